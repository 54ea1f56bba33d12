// strata — internals of the distributed solver (docs/distributed.md): who owns which part
// of the tree, the command protocol between rank 0 and the other ranks, the numeric
// factorization and the triangular solves across ranks, and the hooks tests use.
#pragma once

#include <cstdint>
#include <exception>
#include <memory>
#include <optional>
#include <vector>

#include "analysis/analysis.hpp"
#include "distributed/comm.hpp"
#include "numeric/factor.hpp"
#include "strata/distributed.hpp"
#include "strata/solver.hpp"

namespace strata::distributed {

/// Which rank holds what, for an analysis split for ranks × workers_per_rank workers:
/// global worker w runs on rank w / workers_per_rank, so subtree i (partition owner
/// o) is factored on rank o / workers_per_rank; the top part on rank 0.
struct RankLayout {
  int ranks = 1;
  int rank = 0;
  int workers_per_rank = 1;
  std::vector<int> subtree_rank;              ///< per subtree
  std::vector<std::vector<int>> subtrees_of;  ///< per rank, increasing subtree index
  std::vector<index_t> my_fronts;             ///< fronts of this rank's subtrees, increasing
  std::vector<index_t> top_cols;              ///< pivot columns of the top part, increasing
  std::vector<index_t> col_begin, col_end;    ///< pivot columns of subtree i: [begin, end)
};

/// The layout of `an` (split for ranks × workers_per_rank workers) seen from `rank`.
RankLayout make_layout(const Analysis& an, int ranks, int rank, int workers_per_rank);

/// Gives `an` a factor layout holding only the panels of the rank's fronts (its subtrees,
/// each in its part's schedule order, then the top part on rank 0); the other fronts'
/// offsets point at the end (they are never read or written on this rank). So each rank
/// stores its share of the factor, not all of it.
void localize_factor_layout(Analysis& an, const RankLayout& layout);

/// Commands rank 0 broadcasts to the others (they follow them in follow()).
enum class Command : std::int32_t { analysis = 1, factor = 2, apply = 3, end = 4, error = 5 };

struct Header {
  Command command = Command::end;
  std::int32_t a = 0;         ///< analysis: workers per rank; factor: MatrixType; error: kind
  std::int64_t b = 0;         ///< factor: nnz (values); apply: nrhs; error: column / bytes
  double c = 0;               ///< factor: static pivot; error: pivot
  std::uint64_t payload = 0;  ///< bytes that follow
};

/// Rank 0: broadcasts a command and its payload.
void send_command(detail::CommImpl& comm, Header h, const void* payload = nullptr);
/// The other ranks: receives the next command; its payload goes to `payload`.
Header receive_command(detail::CommImpl& comm, std::vector<char>& payload);

/// The error `e` as a command (type, message and the fields of NotPositiveDefinite and
/// OutOfMemory), and back: throws the exception it describes.
Header error_header(std::exception_ptr e, std::vector<char>& message);
[[noreturn]] void throw_error(const Header& h, const std::vector<char>& message);

/// Collective: when any rank passes an error, every rank throws the error of the lowest
/// such rank (same type and message, prefixed by the rank). Returns when none failed.
void agree(detail::CommImpl& comm, std::exception_ptr mine);

/// Positions (indices into the canonical input's values, the order of an.pattern_indices)
/// of the scaled values that the fronts of rank r's subtrees assemble: the entry_src of
/// an.assembly over those fronts, increasing and distinct (an entry lands in exactly one
/// front). Rank 0 needs every value (it also factors the top part); this is what a rank
/// r > 0 is sent at each factorization (values.cpp).
std::vector<index_t> value_positions(const Analysis& an, const RankLayout& l, int r);

struct NcclContext;  // nccl_transport.cpp (STRATA_NCCL)

/// What every rank keeps for the numeric phases.
struct NumericState {
  RankLayout layout;
  std::vector<std::unique_ptr<numeric::Executor>> executors;  ///< this rank's workers
  std::vector<std::vector<double>> arenas;
  numeric::BlockBuffers blocks;  ///< host buffers of the blocks sent and received, kept
  std::vector<DeviceStats> devices;
  /// value_positions per rank, made once per analysis: rank 0 holds every rank's list
  /// (its own empty: it has all values); a rank r > 0 only its own, at index r.
  std::vector<std::vector<index_t>> value_positions;
  RankStats stats;  ///< this rank's figures of the current phases
  int threads = 0;  ///< host threads for its loops over values (Options::num_threads)
  /// GPU ranks r > 0: their values array (receive_values) page-locked while it stays, as
  /// the Solver pins rank 0's scaled values, for its upload at every factorization.
  bool pin_values = false;
  std::unique_ptr<numeric::PinnedHostRange> values_pin;
  /// The values packed for each rank (rank 0) or as received (the others), kept from one
  /// factorization to the next: 8 bytes per position of value_positions.
  std::vector<std::vector<double>> values_packed;
  /// With NCCL, values_packed's buffers page-locked (released before the buffers; declared
  /// after them so that they go first).
  std::vector<std::unique_ptr<numeric::PinnedHostRange>> values_packed_pins;
  /// Rank 0: the fronts of each rank's subtrees, increasing (the order in which a rank
  /// sends their pivot statistics), made at the first factorization of an analysis.
  std::vector<std::vector<index_t>> fronts_of_rank;
  bool nccl = false;  ///< values and contribution blocks between GPUs through NCCL
  /// Options::gpu_solve_parts: solve on the GPUs that hold the parts (solve.cpp).
  bool solve_where_held = true;
  /// The device solve's update vectors (the whole tree's arena: an.child_rows.offsets)
  /// and rank 0's copy of b, kept from one solve to the next.
  std::vector<double> solve_u, solve_b;
  std::shared_ptr<NcclContext> nccl_context;
  /// Made anew with value_positions (at each analysis), so that the NCCL transfer uploads
  /// its copy of the positions once per analysis.
  std::uint64_t positions_generation = 0;
  /// With NCCL: the current factorization's scaled values on GPU device_values_device
  /// (FactorContext::device_values; set by send_values / receive_values), else null.
  const double* device_values = nullptr;
  int device_values_device = -1;
};

/// Collective with receive_values: rank 0 sends each rank r > 0 the scaled values at
/// ns.value_positions[r], packed in that order (MPI point-to-point, one message per
/// rank; NCCL between GPU ranks, ns.nccl). `values`: all nnz scaled values, or, with
/// `device_values` (NCCL only), their size alone: the values are then those nnz on rank 0's
/// NCCL GPU, where the value pass ran (DistributedDriver::scale_values_on_device). Adds the
/// bytes sent to ns.stats.values_bytes. An error on any rank (an InternalError for a
/// position past the values or device values without NCCL; DeviceError) is thrown on
/// every rank (agree()).
void send_values(detail::CommImpl& comm, NumericState& ns, const std::vector<double>& values,
                 const double* device_values = nullptr);
/// Ranks r > 0: receives this rank's scaled values into `values`, which is made nnz long
/// (zero-filled) when it is not: only this rank's positions are written, the others are
/// never read by its fronts. With NCCL they arrive on the rank's first GPU
/// (ns.device_values) and `values` is filled only when an executor reads values on the
/// host (Executor::reads_host_values), else left as it is. Adds the bytes received to
/// ns.stats.values_bytes. Throws as send_values.
void receive_values(detail::CommImpl& comm, NumericState& ns, std::size_t nnz,
                    std::vector<double>& values);

/// Collective: this rank's part of the factorization of the scaled values: its subtrees
/// on its executors, the subtree roots' contribution blocks and pivot statistics to rank
/// 0, and there the top part. Throws on every rank what failed on any (agree()); the top
/// part's errors only on rank 0.
void factor_part(detail::CommImpl& comm, NumericState& ns, const Analysis& an,
                 const std::vector<double>& values, MatrixType type,
                 const numeric::PivotPolicy& pivots, bool work_stealing,
                 numeric::NumericFactor& factor);

/// Collective: one solve with the distributed factor. x (tree numbering, n×nrhs) holds b
/// on rank 0 on entry and the solution there on return; on the other ranks it is n×nrhs
/// scratch. On the GPUs that hold the parts' panels when every rank can solve its parts
/// there (returns true), else on the host: the held panels are fetched into `factor`
/// first (returns false). Same result on every rank.
bool solve_part(detail::CommImpl& comm, NumericState& ns, const Analysis& an,
                numeric::NumericFactor& factor, double* x, index_t nrhs);

}  // namespace strata::distributed

namespace strata::detail {

struct DistributedState {
  Communicator comm;
  Options options;
  int host_workers = 0;           ///< DistributedAccess::use_host_workers
  std::optional<Solver> solver;   ///< rank 0 (and the one-rank case)
  std::optional<Analysis> copy;   ///< the other ranks: the broadcast analysis
  Analysis* analysis = nullptr;   ///< rank 0: the Solver's; others: &*copy
  numeric::NumericFactor factor;  ///< the other ranks' share of the factor
  std::vector<double> values;     ///< the other ranks: the scaled values of their subtrees'
                                  ///< fronts (nnz long, receive_values)
  distributed::NumericState numeric;
  Stats stats;  ///< the other ranks: analysis figures only
  DistributedStats dstats;
};

/// Test hooks.
struct DistributedAccess {
  /// Every rank runs `per_rank` CPU executors (one host thread each) as its workers, as
  /// it would run that many GPUs. Call before analyze on every rank.
  static void use_host_workers(DistributedSolver& s, int per_rank);
  /// This rank's view of the analysis (rank 0: its Solver's; the others: the broadcast
  /// copy), or nullptr before analyze.
  static const Analysis* analysis(const DistributedSolver& s);
};

}  // namespace strata::detail
