// strata — the numeric factorization and the triangular solves across ranks
// (docs/distributed.md §2–3).
//
// Factorization: every rank runs the multi-worker driver (numeric/multi_device.cpp) on
// the subtrees its workers own; when they are done, the ranks agree on failure, each
// subtree root's contribution block goes to rank 0 (MPI from host memory), and with it
// the pivot statistics of the rank's fronts (inertia, perturbed pivots, determinant);
// rank 0 then factors the top part with the blocks imported as on one machine. The factor
// stays where it was computed: each rank holds its fronts' panels only
// (localize_factor_layout).
//
// Solve (Liu 1992 §6, split at the subtree roots): the right-hand side's entries of each
// rank's subtree pivots go to that rank; each rank runs the forward substitution over its
// fronts, starting from zero on the top part's rows, so that what it leaves there is its
// update to them; the updates are summed onto rank 0 (one reduction over the top part's
// rows), which runs forward, diagonal and backward substitution on the top part; the top
// part's solution goes back to every rank (one broadcast), which finishes the backward
// substitution on its fronts; the subtree pivots' solution is gathered on rank 0. Volume
// per solve: n·nrhs doubles in the scatter and gather together, plus 2·(ranks − 1)·(top
// rows)·nrhs in the reduction and the broadcast.
#include <algorithm>
#include <cstring>

#include "base/blas.hpp"
#include "base/timer.hpp"
#include "distributed/distributed_internal.hpp"

#ifdef STRATA_HAVE_NCCL
#include "distributed/nccl_blocks.hpp"
#endif

namespace strata::distributed {
namespace {

constexpr int kTagBlock = 100;  // + subtree index: contribution blocks
constexpr int kTagRhs = 8;      // solve: right-hand side pieces
constexpr int kTagX = 9;        // solve: solution pieces

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

// Calls f(column) for the pivot columns of rank r's subtrees, in a fixed order.
template <class F>
void for_columns(const RankLayout& l, int r, F&& f) {
  for (const int i : l.subtrees_of[r])
    for (index_t c = l.col_begin[i]; c < l.col_end[i]; ++c) f(c);
}

std::size_t columns_of(const RankLayout& l, int r) {
  std::size_t k = 0;
  for (const int i : l.subtrees_of[r]) k += static_cast<std::size_t>(l.col_end[i] - l.col_begin[i]);
  return k;
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
  // each GPU keeps its parts' panels during the factorization (no copy and wait after
  // every launch group) and they come to the host in one copy per part at the end:
  // the distributed solve works on host panels
  config.keep_panels_on_devices = true;
  bool exchanged = false;
  config.exchange = [&](std::vector<numeric::CbTransfer>& tr, std::exception_ptr failed) {
    exchanged = true;
    agree(comm, failed);
    // the subtree roots' contribution blocks to rank 0
    std::vector<detail::Message> sends, recvs;
#ifdef STRATA_HAVE_NCCL
    if (ns.nccl) {
      exchange_blocks_nccl(comm, ns, l, tr, execs[0]->device());
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
    // the pivot statistics of every rank's fronts to rank 0
    std::vector<char> mine;
    if (rank != 0) {
      for (const index_t f : l.my_fronts) {
        const char* p = reinterpret_cast<const char*>(&factor.front_stats[f]);
        mine.insert(mine.end(), p, p + sizeof(numeric::PivotStats));
      }
    }
    std::vector<std::vector<char>> all;
    comm.gather(mine, all, 0);
    if (rank == 0)
      for (int r = 1; r < l.ranks; ++r) {
        const std::vector<index_t> fr = fronts_of_rank(an, l, r);
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
    numeric::fetch_panels(an, execs, factor);
  } catch (...) {
    // failed before the exchange (sizing the factor): the other ranks wait in agree()
    if (!exchanged) agree(comm, std::current_exception());
    throw;
  }
  RankStats& st = ns.stats;
  st.workers = l.workers_per_rank;
  st.subtrees = static_cast<index_t>(l.subtrees_of[rank].size());
  st.factor_flops = 0;
  for (const DeviceStats& d : ns.devices) st.factor_flops += d.flops;
  st.factor_seconds += timer.seconds();
  st.factor_bytes_held = sizeof(double) * an.factor_layout.total;
}

void solve_part(detail::CommImpl& comm, NumericState& ns, const Analysis& an,
                const numeric::NumericFactor& factor, double* x, index_t nrhs) {
  Timer timer;
  const RankLayout& l = ns.layout;
  const int rank = comm.rank(), ranks = l.ranks;
  const index_t n = an.n;
  std::vector<double> w;
  openblas_set_num_threads(1);

  // 1. the right-hand side of each rank's subtree pivots to that rank
  {
    std::vector<std::vector<double>> piece(ranks);
    std::vector<detail::Message> sends, recvs;
    if (rank == 0) {
      for (int r = 1; r < ranks; ++r) {
        piece[r].reserve(columns_of(l, r) * nrhs);
        for (index_t c = 0; c < nrhs; ++c)
          for_columns(l, r, [&](index_t j) { piece[r].push_back(x[j + c * n]); });
        if (!piece[r].empty())
          sends.push_back({r, kTagRhs, piece[r].data(), sizeof(double) * piece[r].size()});
      }
    } else {
      std::fill(x, x + static_cast<std::size_t>(n) * nrhs, 0.0);
      piece[rank].resize(columns_of(l, rank) * nrhs);
      if (!piece[rank].empty())
        recvs.push_back({0, kTagRhs, piece[rank].data(), sizeof(double) * piece[rank].size()});
    }
    comm.exchange(sends, recvs);
    if (rank != 0) {
      std::size_t k = 0;
      for (index_t c = 0; c < nrhs; ++c)
        for_columns(l, rank, [&](index_t j) { x[j + c * n] = piece[rank][k++]; });
    }
  }
  // 2. forward substitution over this rank's fronts
  for (const index_t f : l.my_fronts) numeric::forward_front(an, factor, f, x, nrhs, w);
  // 3. the updates to the top part's rows summed onto rank 0
  const std::size_t nt = l.top_cols.size();
  std::vector<double> top(nt * nrhs);
  auto pack_top = [&] {
    for (index_t c = 0; c < nrhs; ++c)
      for (std::size_t k = 0; k < nt; ++k) top[k + c * nt] = x[l.top_cols[k] + c * n];
  };
  auto unpack_top = [&] {
    for (index_t c = 0; c < nrhs; ++c)
      for (std::size_t k = 0; k < nt; ++k) x[l.top_cols[k] + c * n] = top[k + c * nt];
  };
  pack_top();
  comm.reduce_sum(top.data(), top.size(), 0);
  // 4. the top part on rank 0
  if (rank == 0) {
    unpack_top();
    const auto& tf = an.partition.top.fronts;
    for (const index_t f : tf) numeric::forward_front(an, factor, f, x, nrhs, w);
    for (const index_t f : tf) numeric::diagonal_front(an, factor, f, x, nrhs);
    for (auto it = tf.rbegin(); it != tf.rend(); ++it)
      numeric::backward_front(an, factor, *it, x, nrhs, w);
    pack_top();
  }
  // 5. the top part's solution to every rank
  comm.broadcast(top.data(), sizeof(double) * top.size(), 0);
  if (rank != 0) unpack_top();
  // 6. diagonal and backward substitution over this rank's fronts
  for (const index_t f : l.my_fronts) numeric::diagonal_front(an, factor, f, x, nrhs);
  for (auto it = l.my_fronts.rbegin(); it != l.my_fronts.rend(); ++it)
    numeric::backward_front(an, factor, *it, x, nrhs, w);
  // 7. the subtree pivots' solution gathered on rank 0
  {
    std::vector<std::vector<double>> piece(ranks);
    std::vector<detail::Message> sends, recvs;
    if (rank == 0) {
      for (int r = 1; r < ranks; ++r) {
        piece[r].resize(columns_of(l, r) * nrhs);
        if (!piece[r].empty())
          recvs.push_back({r, kTagX, piece[r].data(), sizeof(double) * piece[r].size()});
      }
    } else {
      for (index_t c = 0; c < nrhs; ++c)
        for_columns(l, rank, [&](index_t j) { piece[rank].push_back(x[j + c * n]); });
      if (!piece[rank].empty())
        sends.push_back({0, kTagX, piece[rank].data(), sizeof(double) * piece[rank].size()});
    }
    comm.exchange(sends, recvs);
    if (rank == 0)
      for (int r = 1; r < ranks; ++r) {
        std::size_t k = 0;
        for (index_t c = 0; c < nrhs; ++c)
          for_columns(l, r, [&](index_t j) { x[j + c * n] = piece[r][k++]; });
      }
  }
  ns.stats.solve_seconds += timer.seconds();
}

}  // namespace strata::distributed
