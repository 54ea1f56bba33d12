// strata — the scaled values of each (re)factorization, scattered from rank 0 to the ranks
// that assemble them (docs/distributed.md §1.2 and §2).
//
// What: rank 0 holds the matrix and scales it (the Solver's code). A rank r > 0 assembles
// only the fronts of its own subtrees, and front f reads the scaled values
// entry_src[entry_offsets[f] .. entry_offsets[f + 1]) of the analysis's assembly map; so
// rank 0 sends r exactly those, packed in increasing position order, one point-to-point
// message per rank. Every rank derives the positions from the broadcast analysis and the
// rank layout (value_positions), once per analysis: no index list travels, only values.
// Volume per factorization: Σ over ranks r > 0 of the entries of r's subtrees' fronts
// (each stored entry lands in exactly one front, so the lists are disjoint and their sum is
// at most nnz(A)), where a broadcast of the whole array moved (R − 1)·nnz(A) doubles.
//
// Transport: MPI point-to-point from host memory. Between GPU ranks with NCCL
// (nccl_transport.cpp) the values travel on the GPUs instead: rank 0 uploads them once to
// its first GPU (its executors copy them from there), gathers each rank's share there and
// sends it by NCCL (over NVLink where the GPUs have it, not through a shared-memory copy
// between the processes); a rank scatters its share into an array of the canonical order
// on its first GPU, from which its executors copy. The host array below is then filled only
// for executors that read values on the host (Executor::reads_host_values).
//
// Storage on the receiving ranks (a choice): a values array of the full length nnz(A),
// with only the rank's positions written and the rest zero. The executors read
// ctx.values[entry_src[k]] and the CUDA executor uploads the array whole (page-locked on
// GPU ranks while the array stays, as rank 0's Solver pins its scaled values), so nothing
// downstream changes. Packing and unpacking run over Options::num_threads host threads. The
// consequence: a rank r > 0 still allocates nnz(A) doubles of host memory (and, with a GPU, the
// same on the device) whatever its share; the scatter cuts the traffic and the copying, not that
// footprint. A compact array with a per-rank renumbered entry_src (and an executor that uploads
// only the rank's share) would cut the memory too.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <string>

#include "distributed/distributed_internal.hpp"

#ifdef STRATA_HAVE_NCCL
#include "distributed/nccl_transport.hpp"
#endif

namespace strata::distributed {
namespace {

constexpr int kTagValues = 10;  // the scaled values (solve.cpp uses 8, 9, 11; numeric.cpp 100 + i)

// body(k) for k in [0, count), over `threads` host threads (0: all): packing and unpacking
// millions of values by position is memory-bound gather/scatter work.
template <class Body>
void for_positions(std::size_t count, int threads, Body body) {
  constexpr std::size_t kGrain = 1 << 16;
  if (count < 2 * kGrain || threads == 1) {
    for (std::size_t k = 0; k < count; ++k) body(k);
    return;
  }
  tbb::task_arena arena(threads > 0 ? threads : tbb::task_arena::automatic);
  arena.execute([&] {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, kGrain),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t k = r.begin(); k != r.end(); ++k) body(k);
                      });
  });
}

// ns.values_packed[i] made `count` doubles long, kept from one factorization to the next,
// and page-locked for the NCCL receive's copy to the host (released before the buffer
// moves).
void packed_buffer(NumericState& ns, std::size_t i, std::size_t count) {
  std::vector<std::vector<double>>& packed = ns.values_packed;
  std::vector<std::unique_ptr<numeric::PinnedHostRange>>& pins = ns.values_packed_pins;
  if (packed.size() <= i) packed.resize(i + 1);
  if (pins.size() < packed.size()) pins.resize(packed.size());
  if (packed[i].size() != count) {
    pins[i].reset();
    packed[i].resize(count);
  }
  if (ns.nccl && !pins[i] && count > 0)
    pins[i] = numeric::pin_host_memory(packed[i].data(), sizeof(double) * count);
}

}  // namespace

std::vector<index_t> value_positions(const Analysis& an, const RankLayout& l, int r) {
  const AssemblyMap& am = an.assembly;
  std::vector<index_t> out;
  for (const int i : l.subtrees_of[r])
    for (const index_t f : an.partition.subtrees[i].fronts)
      out.insert(out.end(), am.entry_src.begin() + am.entry_offsets[f],
                 am.entry_src.begin() + am.entry_offsets[f + 1]);
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

void send_values(detail::CommImpl& comm, NumericState& ns, const std::vector<double>& values,
                 const double* device_values) {
  const int ranks = comm.size();
  std::exception_ptr failed;
  try {
    for (int r = 1; r < ranks; ++r) {
      const std::vector<index_t>& pos = ns.value_positions.at(r);
      if (!pos.empty() && static_cast<std::size_t>(pos.back()) >= values.size())
        throw InternalError("rank " + std::to_string(r) + " needs value " +
                            std::to_string(pos.back()) + " of " + std::to_string(values.size()));
    }
    if (device_values && !ns.nccl) throw InternalError("values on a device to send without NCCL");
  } catch (...) {
    failed = std::current_exception();
  }
  ns.device_values = nullptr;
#ifdef STRATA_HAVE_NCCL
  if (ns.nccl) {
    send_values_nccl(comm, ns, device_values ? device_values : values.data(), values.size(),
                     ns.executors.at(0)->device(), failed);
    for (int r = 1; r < ranks; ++r)
      ns.stats.values_bytes += sizeof(double) * ns.value_positions[r].size();
    return;
  }
#endif
  std::vector<std::vector<double>>& packed = ns.values_packed;
  std::vector<detail::Message> sends;
  try {
    packed.resize(ranks);
    for (int r = 1; r < ranks && !failed; ++r) {
      const std::vector<index_t>& pos = ns.value_positions[r];
      if (pos.empty()) continue;
      packed_buffer(ns, r, pos.size());
      double* out = packed[r].data();
      for_positions(pos.size(), ns.threads, [&](std::size_t k) { out[k] = values[pos[k]]; });
      sends.push_back({r, kTagValues, packed[r].data(), sizeof(double) * pos.size()});
      ns.stats.values_bytes += sizeof(double) * pos.size();
    }
  } catch (...) {
    if (!failed) failed = std::current_exception();
  }
  // an error on any rank is thrown on all, so that none waits for a message that will
  // not come
  agree(comm, failed);
  comm.exchange(sends, {});
}

void receive_values(detail::CommImpl& comm, NumericState& ns, std::size_t nnz,
                    std::vector<double>& values) {
  const int rank = comm.rank();
  const std::vector<index_t>& pos = ns.value_positions.at(rank);
  ns.device_values = nullptr;
  // the host array: always with MPI; with NCCL only for executors that read values there
  bool host = !ns.nccl;
  for (const auto& e : ns.executors) host = host || e->reads_host_values();
  std::exception_ptr failed;
  try {
    if (!pos.empty() && static_cast<std::size_t>(pos.back()) >= nnz)
      throw InternalError("rank " + std::to_string(rank) + " needs value " +
                          std::to_string(pos.back()) + " of " + std::to_string(nnz));
    if (host) {
      if (values.size() != nnz) {
        ns.values_pin.reset();
        values.assign(nnz, 0.0);
      }
      if (ns.pin_values && !ns.values_pin)
        ns.values_pin = numeric::pin_host_memory(values.data(), sizeof(double) * nnz);
      packed_buffer(ns, 0, pos.size());
    }
  } catch (...) {
    failed = std::current_exception();
  }
#ifdef STRATA_HAVE_NCCL
  if (ns.nccl) {
    receive_values_nccl(comm, ns, nnz, ns.executors.at(0)->device(),
                        host ? ns.values_packed[0].data() : nullptr, failed);
  } else
#endif
  {
    agree(comm, failed);
    std::vector<detail::Message> recvs;
    if (!pos.empty())
      recvs.push_back({0, kTagValues, ns.values_packed[0].data(), sizeof(double) * pos.size()});
    comm.exchange({}, recvs);
  }
  if (host) {
    const double* packed = ns.values_packed[0].data();
    double* in = values.data();
    for_positions(pos.size(), ns.threads, [&](std::size_t k) { in[pos[k]] = packed[k]; });
  }
  ns.stats.values_bytes += sizeof(double) * pos.size();
}

}  // namespace strata::distributed
