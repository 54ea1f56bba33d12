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
// Transport: MPI point-to-point from host memory; between GPU ranks with NCCL
// (nccl_transport.cpp), from rank 0's page-locked packed buffer over its GPU to the rank's
// GPU and into its page-locked buffer, which moves them over NVLink where the GPUs have it
// instead of through a shared-memory copy between the processes.
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
// and page-locked for the NCCL transfer's copies (released before the buffer moves).
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

// Rank 0's sends or a rank's receive, after every rank's preparation is agreed (agree():
// an error on any rank is thrown on all, so that none waits for a message that will not
// come): by NCCL on GPU ranks that have it, else by MPI.
void transfer(detail::CommImpl& comm, NumericState& ns, const std::vector<detail::Message>& sends,
              const std::vector<detail::Message>& recvs, std::exception_ptr failed) {
#ifdef STRATA_HAVE_NCCL
  if (ns.nccl) {
    transfer_values_nccl(comm, ns, ns.executors.at(0)->device(), failed);
    return;
  }
#endif
  agree(comm, failed);
  comm.exchange(sends, recvs);
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

void send_values(detail::CommImpl& comm, NumericState& ns, const std::vector<double>& values) {
  const int ranks = comm.size();
  std::vector<std::vector<double>>& packed = ns.values_packed;
  std::vector<detail::Message> sends;
  std::exception_ptr failed;
  try {
    packed.resize(ranks);
    for (int r = 1; r < ranks; ++r) {
      const std::vector<index_t>& pos = ns.value_positions.at(r);
      if (pos.empty()) continue;
      if (static_cast<std::size_t>(pos.back()) >= values.size())
        throw InternalError("rank " + std::to_string(r) + " needs value " +
                            std::to_string(pos.back()) + " of " + std::to_string(values.size()));
      packed_buffer(ns, r, pos.size());
      double* out = packed[r].data();
      for_positions(pos.size(), ns.threads, [&](std::size_t k) { out[k] = values[pos[k]]; });
      sends.push_back({r, kTagValues, packed[r].data(), sizeof(double) * pos.size()});
      ns.stats.values_bytes += sizeof(double) * pos.size();
    }
  } catch (...) {
    failed = std::current_exception();
  }
  transfer(comm, ns, sends, {}, failed);
}

void receive_values(detail::CommImpl& comm, NumericState& ns, std::size_t nnz,
                    std::vector<double>& values) {
  const int rank = comm.rank();
  const std::vector<index_t>& pos = ns.value_positions.at(rank);
  std::vector<detail::Message> recvs;
  std::exception_ptr failed;
  try {
    if (values.size() != nnz) {
      ns.values_pin.reset();
      values.assign(nnz, 0.0);
    }
    if (ns.pin_values && !ns.values_pin)
      ns.values_pin = numeric::pin_host_memory(values.data(), sizeof(double) * nnz);
    if (!pos.empty() && static_cast<std::size_t>(pos.back()) >= nnz)
      throw InternalError("rank " + std::to_string(rank) + " needs value " +
                          std::to_string(pos.back()) + " of " + std::to_string(nnz));
    packed_buffer(ns, 0, pos.size());
    if (!pos.empty())
      recvs.push_back({0, kTagValues, ns.values_packed[0].data(), sizeof(double) * pos.size()});
  } catch (...) {
    failed = std::current_exception();
  }
  transfer(comm, ns, {}, recvs, failed);
  const double* packed = ns.values_packed[0].data();
  double* in = values.data();
  for_positions(pos.size(), ns.threads, [&](std::size_t k) { in[pos[k]] = packed[k]; });
  ns.stats.values_bytes += sizeof(double) * pos.size();
}

}  // namespace strata::distributed
