// strata — the numeric factorization across ranks (docs/distributed.md §2–3).
//
// Every rank runs the multi-worker driver (numeric/multi_device.cpp) on the subtrees its
// workers own; when they are done, the ranks agree on failure, each subtree root's
// contribution block goes to rank 0 (MPI from host memory), and with it the pivot
// statistics of the rank's fronts (inertia, perturbed pivots, determinant); rank 0 then
// factors the top part with the blocks imported as on one machine. The factor stays where
// it was computed: each rank holds its fronts' panels only (localize_factor_layout), and a
// GPU keeps the panels of the parts it factored (NumericFactor::held) — they come to the
// host only if a solve has to run there (solve.cpp).
#include <algorithm>
#include <cstring>

#include "base/timer.hpp"
#include "distributed/distributed_internal.hpp"

#ifdef STRATA_HAVE_NCCL
#include "distributed/nccl_transport.hpp"
#endif

namespace strata::distributed {
namespace {

constexpr int kTagBlock = 100;  // + subtree index: contribution blocks

// Fronts of rank r's subtrees, increasing.
std::vector<index_t> fronts_of_rank(const Analysis& an, const RankLayout& l, int r) {
  std::vector<index_t> out;
  for (const int i : l.subtrees_of[r]) {
    const auto& f = an.partition.subtrees[i].fronts;
    out.insert(out.end(), f.begin(), f.end());
  }
  std::sort(out.begin(), out.end());
  return out;
}

}  // namespace

void factor_part(detail::CommImpl& comm, NumericState& ns, const Analysis& an,
                 const std::vector<double>& values, MatrixType type,
                 const numeric::PivotPolicy& pivots, bool work_stealing,
                 numeric::NumericFactor& factor) {
  Timer timer;
  const RankLayout& l = ns.layout;
  const int rank = comm.rank();
  const int n_sub = static_cast<int>(an.partition.subtrees.size());
  std::vector<numeric::Executor*> execs;
  for (auto& e : ns.executors) execs.push_back(e.get());

  numeric::MultiWorkerConfig config;
  config.work_stealing = work_stealing;
  config.first_worker = rank * l.workers_per_rank;
  config.factor_top = rank == 0;
  config.remote_blocks_on_device = ns.nccl;
  config.block_buffers = &ns.blocks;
  config.device_values = ns.device_values;  // with NCCL: where the values arrived
  config.device_values_device = ns.device_values_device;
  // each GPU keeps its parts' panels (no copy and wait after every launch group): the
  // solve runs there, or fetches them to the host first (solve_part)
  config.keep_panels_on_devices = true;
  bool exchanged = false, blocks_done = false;
  config.exchange = [&](std::vector<numeric::CbTransfer>& tr, std::exception_ptr failed) {
    exchanged = true;
    Timer exchange;
    agree(comm, failed);
    // the subtree roots' contribution blocks to rank 0
    Timer blocks;
    std::vector<detail::Message> sends, recvs;
#ifdef STRATA_HAVE_NCCL
    if (ns.nccl) {
      exchange_blocks_nccl(comm, ns, l, tr, execs[0]->device(), type != MatrixType::general);
    } else
#endif
    {
      for (int i = 0; i < n_sub; ++i) {
        numeric::CbTransfer& x = tr[i];
        const int owner = l.subtree_rank[i];
        if (x.size == 0 || owner == 0) continue;  // no block, or made on rank 0
        const std::size_t bytes = sizeof(double) * x.size;
        if (rank == 0) {
          recvs.push_back({owner, kTagBlock + i, x.host_buffer(), bytes});
          x.on_host = true;
        } else if (owner == rank) {
          if (!x.on_host)
            throw InternalError("the block of subtree " + std::to_string(i) +
                                " was not exported to host memory for MPI");
          sends.push_back({0, kTagBlock + i, x.host, bytes});
        }
      }
      comm.exchange(sends, recvs);
    }
    ns.stats.blocks_seconds += blocks.seconds();
    blocks_done = true;
    ns.stats.exchange_seconds += exchange.seconds();
  };
  if (rank == 0 && static_cast<int>(ns.fronts_of_rank.size()) != l.ranks) {
    ns.fronts_of_rank.assign(l.ranks, {});
    for (int r = 1; r < l.ranks; ++r) ns.fronts_of_rank[r] = fronts_of_rank(an, l, r);
  }
  // The pivot statistics of every rank's fronts to rank 0, once the blocks are there:
  // rank 0 needs them only for the whole factorization's figures, so they travel after
  // its top part, not on the way to it.
  auto gather_pivot_stats = [&] {
    std::vector<char> mine;
    if (rank != 0) {
      mine.resize(l.my_fronts.size() * sizeof(numeric::PivotStats));
      for (std::size_t k = 0; k < l.my_fronts.size(); ++k)
        std::memcpy(mine.data() + k * sizeof(numeric::PivotStats),
                    &factor.front_stats[l.my_fronts[k]], sizeof(numeric::PivotStats));
    }
    std::vector<std::vector<char>> all;
    comm.gather(mine, all, 0);
    if (rank == 0)
      for (int r = 1; r < l.ranks; ++r) {
        const std::vector<index_t>& fr = ns.fronts_of_rank.at(r);
        if (all[r].size() != fr.size() * sizeof(numeric::PivotStats))
          throw InternalError("rank " + std::to_string(r) +
                              " sent pivot statistics of the wrong size");
        for (std::size_t k = 0; k < fr.size(); ++k)
          std::memcpy(&factor.front_stats[fr[k]], all[r].data() + k * sizeof(numeric::PivotStats),
                      sizeof(numeric::PivotStats));
      }
  };
  try {
    numeric::factorize_multi(an, values, type, pivots, execs, factor, ns.arenas, config,
                             &ns.devices);
  } catch (...) {
    // failed before the exchange (sizing the factor): the other ranks wait in agree()
    if (!exchanged) agree(comm, std::current_exception());
    // rank 0's top part failed after the blocks came: the others wait in the gather
    if (blocks_done) gather_pivot_stats();
    throw;
  }
  gather_pivot_stats();
  RankStats& st = ns.stats;
  st.workers = l.workers_per_rank;
  st.subtrees = static_cast<index_t>(l.subtrees_of[rank].size());
  st.factor_flops = 0;
  for (const DeviceStats& d : ns.devices) st.factor_flops += d.flops;
  st.factor_seconds += timer.seconds();
  st.factor_bytes_held = sizeof(double) * an.factor_layout.total;
}

}  // namespace strata::distributed
