// strata — DistributedSolver: the Solver over the ranks of a Communicator
// (docs/distributed.md).
//
// Rank 0 holds an ordinary Solver whose numeric driver (SolverAccess::set_driver,
// numeric/driver.hpp) runs the collective phases of numeric.cpp and solve.cpp, so that
// validation, type resolution (Cholesky first, LDLᵀ on failure), scaling, static pivoting,
// statistics and iterative refinement are exactly the Solver's. The other ranks wait in
// the same public call and follow rank 0's commands (protocol.cpp): the analysis, computed
// once on rank 0 and broadcast; at every (re)factorization the scaled values, each rank
// sent only those its subtrees assemble (values.cpp); one command per solve with the
// factor (refinement and GMRES make several). Each phase ends with `end`
// and a gather of every rank's figures onto rank 0, or with `error`, which every rank
// throws. With one rank the Solver runs alone.
#include <cstring>

#include "base/timer.hpp"
#include "core/solver_internal.hpp"
#include "distributed/distributed_internal.hpp"
#include "distributed/serialize.hpp"

namespace strata {

using detail::DistributedState;
using namespace distributed;

namespace {

bool wants_gpu(const DistributedState& s) {
  return s.host_workers == 0 && numeric::uses_cuda(s.options.backend);
}

// Rank 0: the workers each rank runs (the GPUs of a rank, or one CPU executor).
int workers_per_rank(const DistributedState& s) {
  if (s.host_workers > 0) return s.host_workers;
  if (!wants_gpu(s)) return 1;
  if (s.options.num_gpus < 0)
    throw InvalidInput("Options::num_gpus must be at least 0 (got " +
                       std::to_string(s.options.num_gpus) + ")");
  if (s.options.num_gpus > 0) return s.options.num_gpus;
  const int visible = numeric::cuda_device_count();
  return std::max(1, visible / std::max(1, s.comm.impl()->local_size()));
}

// Bytes this rank moved between two points, added to a pair of counters.
class ByteCount {
 public:
  explicit ByteCount(const detail::CommImpl& c)
      : c_(c), sent_(c.bytes_sent), received_(c.bytes_received) {}
  void add_to(std::size_t& sent, std::size_t& received) const {
    sent += c_.bytes_sent - sent_;
    received += c_.bytes_received - received_;
  }

 private:
  const detail::CommImpl& c_;
  std::size_t sent_, received_;
};

// Every rank, after the analysis is known: who owns what, this rank's share of the
// factor, and its executors (their creation can fail on one rank: agreed).
void setup_numeric(DistributedState& s, Analysis& an, int per_rank) {
  detail::CommImpl& comm = *s.comm.impl();
  NumericState& ns = s.numeric;
  std::exception_ptr failed;
  try {
    ns.layout = make_layout(an, comm.size(), comm.rank(), per_rank);
    // the positions of the values each rank is sent, before the layout is localized (it
    // does not depend on it): rank 0 every rank's, the others their own
    ns.value_positions.assign(comm.size(), {});
    for (int r = 1; r < comm.size(); ++r)
      if (comm.rank() == 0 || comm.rank() == r)
        ns.value_positions[r] = value_positions(an, ns.layout, r);
    localize_factor_layout(an, ns.layout);
    ns.threads = s.options.num_threads;
    ++ns.positions_generation;
    ns.device_values = nullptr;
    ns.values_packed_pins.clear();  // before the buffers they lock
    ns.values_packed.clear();
    ns.fronts_of_rank.clear();
    ns.pin_values = wants_gpu(s);
    ns.executors.clear();
    ns.arenas.clear();
    ns.blocks = numeric::BlockBuffers{};
    const bool gpu = wants_gpu(s);
    ns.solve_where_held = s.options.gpu_solve_parts;
    const int visible = gpu ? numeric::cuda_device_count() : 0;
    for (int g = 0; g < per_rank; ++g) {
      if (!gpu) {
        ns.executors.push_back(numeric::make_cpu_executor(
            s.host_workers > 0 ? 1 : s.options.num_threads, s.options.reproducible));
      } else {
        const int device = visible > 0 ? (comm.local_rank() * per_rank + g) % visible : g;
        ns.executors.push_back(numeric::make_cuda_executor(s.options, device));
      }
    }
    // the GPUs' set-up for this analysis (part plans, the part solve's arrays), here as
    // the one-process solver makes it at analysis, not in the first factorization and
    // solve; a failure is not reported here: the factorization meets it again and reports
    // it with its context
    for (auto& e : ns.executors) {
      if (!gpu) break;
      try {
        e->prepare(an, comm.size() * per_rank);
      } catch (const InternalError&) {
        throw;
      } catch (const Error&) {
      }
    }
#ifdef STRATA_HAVE_NCCL
    // NCCL with any number of GPUs per rank: a rank's blocks from its other GPUs are
    // staged onto its NCCL GPU on the NCCL stream (nccl_transport.cpp; an unordered staging
    // copy there once gave a wrong 2 × 2 factor, docs/distributed.md §5)
    ns.nccl = gpu && comm.size() > 1;
    // the value pass on rank 0's first GPU for the whole tree (DistributedDriver::
    // scale_values_on_device); a failure here leaves the host's pass
    if (ns.nccl && comm.rank() == 0 && !ns.executors.empty()) {
      try {
        ns.executors[0]->prepare_shared_value_pass(an);
      } catch (const InternalError&) {
        throw;
      } catch (const Error&) {
      }
    }
#endif
  } catch (...) {
    failed = std::current_exception();
  }
  agree(comm, failed);
}

// Every rank: this rank's factorization; an error is thrown on every rank by agree()
// inside, except the top part's (rank 0 only). The static pivot comes from rank 0, LU's
// threshold from the options every rank was given.
void run_factor(DistributedState& s, const Analysis& an, const std::vector<double>& values,
                MatrixType type, double pivot, numeric::NumericFactor& factor) {
  factor_part(*s.comm.impl(), s.numeric, an, values, type,
              numeric::PivotPolicy(pivot, s.options.diagonal_pivot_threshold),
              s.options.work_stealing, factor);
}

// Rank 0's replacement of the Solver's numeric phases.
// Rank 0's numeric driver: its Solver's factorization and solves as collective commands
// to every rank (numeric.cpp, solve.cpp), so that validation, type resolution, scaling,
// statistics and refinement stay the Solver's.
class DistributedDriver final : public numeric::NumericDriver {
 public:
  DistributedDriver(DistributedState& s, int per_rank) : s_(s), per_rank_(per_rank) {}
  int workers() const override { return s_.comm.size() * per_rank_; }
  bool in_one_process() const override { return false; }
  // GPU ranks: rank 0's executors upload its scaled values (the Solver pins them), or,
  // with NCCL, the value pass runs on rank 0's first GPU (scale_values_on_device)
  bool uploads_values() const override { return wants_gpu(s_); }
  // The value pass (checks, norms, scaling) on rank 0's first GPU, from which the values go
  // to the other ranks by NCCL (send_values) and to rank 0's other GPUs device to device, as
  // one process with several GPUs makes it (MultiWorkerDriver), instead of a pass over
  // every entry on rank 0's host while the other ranks wait for their values. Refused
  // without NCCL (MPI sends host values) and where an executor of rank 0 reads values on
  // the host; the Solver then makes the host's pass.
  bool scale_values_on_device(const Analysis& an, const double* values,
                              const numeric::StageValues& stage, int max_sweeps, bool copy_input,
                              numeric::DeviceValueNorms& out) override {
    const NumericState& ns = s_.numeric;
    if (!ns.nccl || ns.executors.empty()) return false;
    for (const auto& e : ns.executors)
      if (e->reads_host_values()) return false;
    return ns.executors[0]->scale_values_on_device(an, values, stage, max_sweeps, copy_input, out);
  }
  bool download_scaled_values(const Analysis& an, double* host) override {
    return s_.numeric.nccl && !s_.numeric.executors.empty() &&
           s_.numeric.executors[0]->download_scaled_values(an, host);
  }
  bool keep_device_input(const Analysis& an) override {
    return s_.numeric.nccl && !s_.numeric.executors.empty() &&
           s_.numeric.executors[0]->keep_device_input(an);
  }
  bool download_device_input(const Analysis& an, double* host) override {
    return s_.numeric.nccl && !s_.numeric.executors.empty() &&
           s_.numeric.executors[0]->download_device_input(an, host);
  }
  void factorize(const Analysis& an, const std::vector<double>& values, bool values_on_device,
                 MatrixType type, const numeric::PivotPolicy& pivots,
                 numeric::NumericFactor& factor) override {
    const double pivot = pivots.static_pivot;
    const double* device_values = nullptr;
    if (values_on_device) {  // scale_values_on_device's result on rank 0's first GPU
      device_values = s_.numeric.executors.empty()
                          ? nullptr
                          : s_.numeric.executors[0]->device_scaled_values(an);
      if (!device_values)
        throw InternalError("values on the device from no value pass of this analysis");
    }
    detail::CommImpl& comm = *s_.comm.impl();
    ByteCount bytes(comm);
    Header h;
    h.command = Command::factor;
    h.a = static_cast<std::int32_t>(type);
    h.b = static_cast<std::int64_t>(values.size());
    h.c = pivot;
    try {
      send_command(comm, h);
      Timer sending;
      send_values(comm, s_.numeric, values, device_values);
      s_.numeric.stats.values_seconds += sending.seconds();
      run_factor(s_, an, values, type, pivot, factor);
    } catch (...) {
      bytes.add_to(s_.numeric.stats.factor_bytes_sent, s_.numeric.stats.factor_bytes_received);
      throw;
    }
    bytes.add_to(s_.numeric.stats.factor_bytes_sent, s_.numeric.stats.factor_bytes_received);
  }
  bool solve(const Analysis& an, numeric::NumericFactor& factor, double* x, index_t nrhs) override {
    detail::CommImpl& comm = *s_.comm.impl();
    ByteCount bytes(comm);
    Header h;
    h.command = Command::apply;
    h.b = nrhs;
    send_command(comm, h);
    const bool on_devices = solve_part(comm, s_.numeric, an, factor, x, nrhs);
    bytes.add_to(s_.numeric.stats.solve_bytes_sent, s_.numeric.stats.solve_bytes_received);
    return on_devices;
  }
  Backend backend() const override { return wants_gpu(s_) ? Backend::cuda : Backend::cpu; }
  void report(FactorStats& fs) const override {
    fs.devices = s_.numeric.devices;
    for (const auto& e : s_.numeric.executors) {
      FactorStats one;
      e->report(one);
      numeric::merge_device_figures(fs, one);
    }
  }

 private:
  DistributedState& s_;
  int per_rank_;
};

// Every rank at the end of a phase: every rank's figures onto rank 0.
void gather_stats(DistributedState& s) {
  detail::CommImpl& comm = *s.comm.impl();
  RankStats mine = s.numeric.stats;
  mine.rank = comm.rank();
  std::vector<char> bytes(sizeof mine);
  std::memcpy(bytes.data(), &mine, sizeof mine);
  std::vector<std::vector<char>> all;
  comm.gather(bytes, all, 0);
  s.dstats.ranks = comm.size();
  s.dstats.per_rank.clear();
  if (comm.rank() != 0) {
    s.dstats.per_rank.push_back(mine);
    return;
  }
  for (const auto& b : all) {
    RankStats r;
    if (b.size() != sizeof r) throw InternalError("rank statistics of the wrong size");
    std::memcpy(&r, b.data(), sizeof r);
    s.dstats.per_rank.push_back(r);
  }
}

// Rank 0: the analysis broadcast and the numeric setup, after Solver::analyze.
void lead_analysis(DistributedState& s, const SparseMatrix& a) {
  detail::CommImpl& comm = *s.comm.impl();
  s.analysis = nullptr;
  const int per_rank = workers_per_rank(s);
  detail::SolverAccess::set_driver(*s.solver, std::make_unique<DistributedDriver>(s, per_rank));
  s.solver->analyze(a);
  Analysis& an = *detail::SolverAccess::analysis(*s.solver);
  Timer timer;
  const std::vector<char> bytes = serialize(an);
  Header h;
  h.command = Command::analysis;
  h.a = per_rank;
  h.payload = bytes.size();
  send_command(comm, h, bytes.data());
  s.dstats.analysis_bytes = bytes.size();
  s.dstats.analysis_broadcast_seconds = timer.seconds();
  s.dstats.workers_per_rank = per_rank;
  s.numeric.stats = RankStats{};
  try {
    setup_numeric(s, an, per_rank);
    s.dstats.blocks_transport = comm.size() == 1 ? "" : s.numeric.nccl ? "nccl" : "mpi";
  } catch (...) {  // no usable analysis: a later factorize analyzes again
    detail::SolverAccess::set_driver(*s.solver, std::make_unique<DistributedDriver>(s, per_rank));
    throw;
  }
  s.analysis = &an;
}

// Rank 0: runs one public phase; ends it with `end` and the figures, or `error`.
template <class F>
void lead(DistributedState& s, F&& f) {
  detail::CommImpl& comm = *s.comm.impl();
  try {
    f();
  } catch (...) {
    std::vector<char> message;
    const Header h = error_header(std::current_exception(), message);
    send_command(comm, h, message.data());
    throw;
  }
  Header h;
  h.command = Command::end;
  send_command(comm, h);
  gather_stats(s);
}

// The other ranks: follows rank 0's commands until the phase ends.
void follow(DistributedState& s) {
  detail::CommImpl& comm = *s.comm.impl();
  std::vector<char> payload;
  RankStats& st = s.numeric.stats;
  for (;;) {
    ByteCount bytes(comm);
    const Header h = receive_command(comm, payload);
    switch (h.command) {
      case Command::analysis: {
        s.analysis = nullptr;
        s.factor = numeric::NumericFactor{};
        s.values.clear();  // the next factorization makes it nnz long, zero off its positions
        s.copy = deserialize(payload);
        s.analysis = &*s.copy;
        s.stats = Stats{};
        s.stats.analysis = s.copy->stats;
        s.dstats.analysis_bytes = payload.size();
        s.dstats.workers_per_rank = h.a;
        st = RankStats{};
        setup_numeric(s, *s.copy, h.a);
        break;
      }
      case Command::factor: {
        if (!s.analysis) throw InternalError("factor command before the analysis");
        const std::size_t nnz = s.analysis->pattern_indices.size();
        if (h.b != static_cast<std::int64_t>(nnz))
          throw InternalError(std::to_string(h.b) + " values for a pattern of " +
                              std::to_string(nnz) + " entries");
        try {
          Timer receiving;
          receive_values(comm, s.numeric, nnz, s.values);
          st.values_seconds += receiving.seconds();
          run_factor(s, *s.analysis, s.values, static_cast<MatrixType>(h.a), h.c, s.factor);
        } catch (...) {
          // agreed with every rank inside receive_values or factor_part: rank 0 decides
          // what follows (the LDLᵀ retry of an automatic type, or an `error` command)
        }
        bytes.add_to(st.factor_bytes_sent, st.factor_bytes_received);
        break;
      }
      case Command::apply: {
        if (!s.analysis || !s.factor.valid) throw InternalError("solve command without a factor");
        std::vector<double> x(static_cast<std::size_t>(s.analysis->n) * h.b);
        solve_part(comm, s.numeric, *s.analysis, s.factor, x.data(), h.b);
        bytes.add_to(st.solve_bytes_sent, st.solve_bytes_received);
        break;
      }
      case Command::end:
        gather_stats(s);
        return;
      case Command::error:
        throw_error(h, payload);
    }
  }
}

void reset_factor_stats(RankStats& st) {
  st.factor_seconds = 0;
  st.values_seconds = 0;
  st.exchange_seconds = 0;
  st.blocks_seconds = 0;
  st.factor_bytes_sent = st.factor_bytes_received = 0;
  st.values_bytes = 0;
}
void reset_solve_stats(RankStats& st) {
  st.solve_seconds = 0;
  st.solve_bytes_sent = st.solve_bytes_received = 0;
}

}  // namespace

DistributedSolver::DistributedSolver(Communicator comm, Options options)
    : state_(std::make_unique<DistributedState>()) {
  state_->comm = std::move(comm);
  state_->options = std::move(options);
  // upper layers (Options::split_top) are not part of the distributed protocol: with
  // several ranks the top part above the subtrees is factored whole on rank 0
  // (docs/distributed.md §1)
  if (state_->comm.size() > 1) state_->options.split_top = false;
  if (state_->comm.rank() == 0) state_->solver.emplace(state_->options);
  state_->dstats.ranks = state_->comm.size();
}
DistributedSolver::~DistributedSolver() = default;
DistributedSolver::DistributedSolver(DistributedSolver&&) noexcept = default;
DistributedSolver& DistributedSolver::operator=(DistributedSolver&&) noexcept = default;

void DistributedSolver::analyze(const SparseMatrix& a) {
  DistributedState& s = *state_;
  if (s.comm.size() == 1) return s.solver->analyze(a);
  if (s.comm.rank() != 0) return follow(s);
  lead(s, [&] { lead_analysis(s, a); });
}

void DistributedSolver::factorize(const SparseMatrix& a) {
  DistributedState& s = *state_;
  if (s.comm.size() == 1) return s.solver->factorize(a);
  reset_factor_stats(s.numeric.stats);
  if (s.comm.rank() != 0) return follow(s);
  lead(s, [&] {
    if (!s.analysis) lead_analysis(s, a);
    s.solver->factorize(a);
  });
}

void DistributedSolver::refactorize(const SparseMatrix& a) {
  DistributedState& s = *state_;
  if (s.comm.size() == 1) return s.solver->refactorize(a);
  reset_factor_stats(s.numeric.stats);
  if (s.comm.rank() != 0) return follow(s);
  lead(s, [&] { s.solver->refactorize(a); });
}

void DistributedSolver::solve(const double* b, double* x, index_t nrhs) {
  DistributedState& s = *state_;
  if (s.comm.size() == 1) return s.solver->solve(b, x, nrhs);
  reset_solve_stats(s.numeric.stats);
  if (s.comm.rank() != 0) return follow(s);
  lead(s, [&] { s.solver->solve(b, x, nrhs); });
}

std::vector<double> DistributedSolver::solve(const std::vector<double>& b) {
  DistributedState& s = *state_;
  if (s.comm.size() == 1) return s.solver->solve(b);
  reset_solve_stats(s.numeric.stats);
  if (s.comm.rank() != 0) {
    follow(s);
    return {};
  }
  std::vector<double> x;
  lead(s, [&] { x = s.solver->solve(b); });
  return x;
}

index_t DistributedSolver::size() const {
  const DistributedState& s = *state_;
  if (s.solver) return s.solver->size();
  return s.analysis ? s.analysis->n : 0;
}

const Stats& DistributedSolver::stats() const {
  return state_->solver ? state_->solver->stats() : state_->stats;
}
const DistributedStats& DistributedSolver::distributed_stats() const { return state_->dstats; }
const Communicator& DistributedSolver::communicator() const { return state_->comm; }

const Analysis* detail::DistributedAccess::analysis(const DistributedSolver& solver) {
  return solver.state_->analysis;
}

void detail::DistributedAccess::use_host_workers(DistributedSolver& solver, int per_rank) {
  if (per_rank < 0) throw InvalidInput("use_host_workers: per_rank must be at least 0");
  DistributedState& s = *solver.state_;
  s.host_workers = per_rank;
  if (s.comm.size() == 1 && s.solver)
    detail::SolverAccess::use_host_workers(*s.solver, per_rank, 1);
}

}  // namespace strata
