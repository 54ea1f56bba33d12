// strata — the triangular solves with a factor spread over ranks (docs/distributed.md
// §1.7, §2).
//
// Liu (SIAM Review 34, 1992, §6), split at the subtree roots: the right-hand side's
// entries of each rank's subtree pivots go to that rank; each rank runs the forward
// substitution over its fronts; what it leaves for the top part goes to rank 0, which
// runs forward, diagonal and backward substitution on the top part; the top part's
// solution goes back to every rank (one broadcast), which finishes the backward
// substitution on its fronts; the subtree pivots' solution is gathered on rank 0.
//
// Where every part's panels stayed on the GPU that computed them (NumericFactor::held),
// each part is solved there (Executor::solve_held_parts, as the one-process multi-GPU
// solve does: cuda/part_solve.cu), and what goes to rank 0 are the update vectors of the
// subtree roots (their contribution-block rows). Otherwise the panels are fetched to the
// host and the fronts solved there, each rank's updates to the top part's rows summed
// onto rank 0 (one reduction). The ranks agree on the path before any data moves, and a
// GPU without room for the solve's workspaces sends every rank to the host path.
//
// Volume per solve: n·nrhs doubles in the scatter and the gather together, plus (ranks −
// 1)·(top rows)·nrhs in the broadcast, and Σ over the other ranks' subtree roots of their
// contribution-block rows × nrhs on the device path ((ranks − 1)·(top rows)·nrhs in the
// reduction on the host path).
#include <algorithm>
#include <exception>
#include <mutex>
#include <thread>

#include "base/blas.hpp"
#include "base/timer.hpp"
#include "distributed/distributed_internal.hpp"
#include "strata/errors.hpp"

namespace strata::distributed {
namespace {

constexpr int kTagRhs = 8;       // right-hand side pieces
constexpr int kTagX = 9;         // solution pieces
constexpr int kTagUpdates = 11;  // the subtree roots' update vectors (values.cpp: 10)

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

// Step 1 of either solve: the right-hand side of each rank's subtree pivots to that rank
// (x: b on rank 0; on the others zero but at those pivots on return).
void scatter_rhs(detail::CommImpl& comm, const RankLayout& l, double* x, index_t n, index_t nrhs) {
  const int rank = comm.rank(), ranks = l.ranks;
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

// The last step of either solve: the subtree pivots' solution gathered on rank 0.
void gather_solution(detail::CommImpl& comm, const RankLayout& l, double* x, index_t n,
                     index_t nrhs) {
  const int rank = comm.rank(), ranks = l.ranks;
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

// x at the top part's pivot rows from rank 0 to every rank (its solution there).
void broadcast_top(detail::CommImpl& comm, const RankLayout& l, double* x, index_t n,
                   index_t nrhs) {
  const std::size_t nt = l.top_cols.size();
  std::vector<double> top(nt * nrhs);
  if (comm.rank() == 0)
    for (index_t c = 0; c < nrhs; ++c)
      for (std::size_t k = 0; k < nt; ++k) top[k + c * nt] = x[l.top_cols[k] + c * n];
  comm.broadcast(top.data(), sizeof(double) * top.size(), 0);
  if (comm.rank() != 0)
    for (index_t c = 0; c < nrhs; ++c)
      for (std::size_t k = 0; k < nt; ++k) x[l.top_cols[k] + c * n] = top[k + c * nt];
}

// The solve with host panels (after fetch_panels): every front of this rank on the host,
// the updates to the top part's rows summed onto rank 0.
void solve_on_host(detail::CommImpl& comm, const RankLayout& l, const Analysis& an,
                   const numeric::NumericFactor& factor, double* x, index_t nrhs) {
  const int rank = comm.rank();
  const index_t n = an.n;
  std::vector<double> w;
  openblas_set_num_threads(1);
  scatter_rhs(comm, l, x, n, nrhs);
  // forward substitution over this rank's fronts, starting from zero on the top part's
  // rows (rank 0: b there), so that what the other ranks leave there is their update
  for (const index_t f : l.my_fronts) numeric::forward_front(an, factor, f, x, nrhs, w);
  const std::size_t nt = l.top_cols.size();
  std::vector<double> top(nt * nrhs);
  for (index_t c = 0; c < nrhs; ++c)
    for (std::size_t k = 0; k < nt; ++k) top[k + c * nt] = x[l.top_cols[k] + c * n];
  comm.reduce_sum(top.data(), top.size(), 0);
  if (rank == 0) {
    for (index_t c = 0; c < nrhs; ++c)
      for (std::size_t k = 0; k < nt; ++k) x[l.top_cols[k] + c * n] = top[k + c * nt];
    const auto& tf = an.partition.top.fronts;
    for (const index_t f : tf) numeric::forward_front(an, factor, f, x, nrhs, w);
    for (const index_t f : tf) numeric::diagonal_front(an, factor, f, x, nrhs);
    for (auto it = tf.rbegin(); it != tf.rend(); ++it)
      numeric::backward_front(an, factor, *it, x, nrhs, w);
  }
  broadcast_top(comm, l, x, n, nrhs);
  for (const index_t f : l.my_fronts) numeric::diagonal_front(an, factor, f, x, nrhs);
  for (auto it = l.my_fronts.rbegin(); it != l.my_fronts.rend(); ++it)
    numeric::backward_front(an, factor, *it, x, nrhs, w);
  gather_solution(comm, l, x, n, nrhs);
}

// Where this rank's parts are held: per local worker, the subtree parts it holds; on rank
// 0 also the worker holding the top part (-1 when the top part has no fronts). False when
// some part of this rank is not held by one of its executors or that executor cannot
// solve it where it is (then the solve runs on the host). A rank without parts is ready.
bool held_parts(const Analysis& an, const NumericState& ns, const numeric::NumericFactor& factor,
                int rank, std::vector<std::vector<int>>& lists, int& top_worker) {
  const schedule::TreePartition& tp = an.partition;
  const RankLayout& l = ns.layout;
  const int workers = static_cast<int>(ns.executors.size());
  top_worker = -1;
  lists.assign(workers, {});
  if (tp.n_upper_layers() != 0) return false;
  std::vector<int> worker(static_cast<std::size_t>(tp.n_parts()), -1);
  for (const numeric::HeldPanels& h : factor.held) {
    if (h.part < 0 || h.part >= tp.n_parts() || h.worker < 0 || h.worker >= workers) return false;
    worker[h.part] = h.worker;
  }
  for (const int i : l.subtrees_of[rank]) {
    if (tp.subtrees[i].fronts.empty()) continue;
    if (worker[i] < 0) return false;
    lists[worker[i]].push_back(i);
  }
  if (rank == 0 && !tp.top.fronts.empty()) {
    top_worker = worker[tp.top_id()];
    if (top_worker < 0) return false;
    if (!ns.executors[top_worker]->can_solve_held_parts(an, factor, {tp.top_id()})) return false;
  }
  for (int w = 0; w < workers; ++w)
    if (!lists[w].empty() && !ns.executors[w]->can_solve_held_parts(an, factor, lists[w]))
      return false;
  return true;
}

// One sweep over this rank's subtree parts, each worker's on a thread of its own. Returns
// false when a GPU had no room for the solve's workspaces; other errors are agreed on by
// every rank (agree) and thrown.
bool sweep_subtrees(detail::CommImpl& comm, NumericState& ns, const Analysis& an,
                    const numeric::NumericFactor& factor,
                    const std::vector<std::vector<int>>& lists, bool forward, double* x, double* u,
                    index_t nrhs) {
  std::exception_ptr error;
  bool no_room = false;
  std::mutex m;
  std::vector<std::thread> threads;
  for (std::size_t w = 0; w < lists.size(); ++w) {
    if (lists[w].empty()) continue;
    threads.emplace_back([&, w] {
      try {
        ns.executors[w]->solve_held_parts(an, factor, lists[w], forward, x, u, nrhs);
      } catch (const OutOfMemory&) {
        const std::lock_guard<std::mutex> lock(m);
        no_room = true;
      } catch (...) {
        const std::lock_guard<std::mutex> lock(m);
        if (!error) error = std::current_exception();
      }
    });
  }
  for (std::thread& t : threads) t.join();
  agree(comm, error);
  return !comm.any(no_room);
}

// The solve where the parts are held (see the file header). False, with nothing
// exchanged but the agreement, when some rank's parts are not all held where they can be
// solved, or a GPU had no room for the solve: x is then as it was on entry.
bool solve_where_held(detail::CommImpl& comm, NumericState& ns, const Analysis& an,
                      const numeric::NumericFactor& factor, double* x, index_t nrhs) {
  const RankLayout& l = ns.layout;
  const int rank = comm.rank();
  const index_t n = an.n;
  const schedule::TreePartition& tp = an.partition;
  std::vector<std::vector<int>> lists;
  int top_worker = -1;
  const bool ok = ns.solve_where_held && held_parts(an, ns, factor, rank, lists, top_worker);
  if (comm.any(!ok)) return false;
  // b kept for a fall-back to the host (rank 0; the others' x is scratch)
  if (rank == 0) ns.solve_b.assign(x, x + static_cast<std::size_t>(n) * nrhs);
  auto give_up = [&] {
    if (rank == 0) std::copy(ns.solve_b.begin(), ns.solve_b.end(), x);
    return false;
  };
  const std::size_t u_len = static_cast<std::size_t>(an.child_rows.offsets.back());
  if (ns.solve_u.size() < u_len * nrhs) ns.solve_u.resize(u_len * nrhs);
  double* u = ns.solve_u.data();
  scatter_rhs(comm, l, x, n, nrhs);
  if (!sweep_subtrees(comm, ns, an, factor, lists, true, x, u, nrhs)) return give_up();
  // the update vectors of the other ranks' subtree roots to rank 0, in subtree order,
  // each root's rows for every right-hand side
  const auto& off = an.child_rows.offsets;
  auto roots_of = [&](int r) {
    std::vector<index_t> roots;
    for (const int i : l.subtrees_of[r]) {
      const index_t f = tp.subtrees[i].root;
      if (!tp.subtrees[i].fronts.empty() && f >= 0 && an.tree.parent[f] >= 0 && off[f + 1] > off[f])
        roots.push_back(f);
    }
    return roots;
  };
  auto packed_size = [&](const std::vector<index_t>& roots) {
    std::size_t k = 0;
    for (const index_t f : roots) k += static_cast<std::size_t>(off[f + 1] - off[f]);
    return k * nrhs;
  };
  {
    std::vector<std::vector<double>> piece(l.ranks);
    std::vector<detail::Message> sends, recvs;
    if (rank == 0) {
      for (int r = 1; r < l.ranks; ++r) {
        piece[r].resize(packed_size(roots_of(r)));
        if (!piece[r].empty())
          recvs.push_back({r, kTagUpdates, piece[r].data(), sizeof(double) * piece[r].size()});
      }
    } else {
      for (const index_t f : roots_of(rank))
        for (index_t c = 0; c < nrhs; ++c) {
          const double* src = u + off[f] + c * u_len;
          piece[rank].insert(piece[rank].end(), src, src + (off[f + 1] - off[f]));
        }
      if (!piece[rank].empty())
        sends.push_back({0, kTagUpdates, piece[rank].data(), sizeof(double) * piece[rank].size()});
    }
    comm.exchange(sends, recvs);
    if (rank == 0)
      for (int r = 1; r < l.ranks; ++r) {
        std::size_t k = 0;
        for (const index_t f : roots_of(r))
          for (index_t c = 0; c < nrhs; ++c) {
            const std::size_t len = static_cast<std::size_t>(off[f + 1] - off[f]);
            std::copy(piece[r].begin() + k, piece[r].begin() + k + len, u + off[f] + c * u_len);
            k += len;
          }
      }
  }
  // the top part on rank 0, both sweeps
  std::exception_ptr error;
  bool no_room = false;
  if (rank == 0 && top_worker >= 0) {
    try {
      numeric::Executor& e = *ns.executors[top_worker];
      e.solve_held_parts(an, factor, {tp.top_id()}, true, x, u, nrhs);
      e.solve_held_parts(an, factor, {tp.top_id()}, false, x, u, nrhs);
    } catch (const OutOfMemory&) {
      no_room = true;
    } catch (...) {
      error = std::current_exception();
    }
  }
  agree(comm, error);
  if (comm.any(no_room)) return give_up();
  broadcast_top(comm, l, x, n, nrhs);
  if (!sweep_subtrees(comm, ns, an, factor, lists, false, x, u, nrhs)) return give_up();
  gather_solution(comm, l, x, n, nrhs);
  return true;
}

}  // namespace

bool solve_part(detail::CommImpl& comm, NumericState& ns, const Analysis& an,
                numeric::NumericFactor& factor, double* x, index_t nrhs) {
  Timer timer;
  bool on_devices = solve_where_held(comm, ns, an, factor, x, nrhs);
  if (!on_devices) {
    std::vector<numeric::Executor*> execs;
    for (auto& e : ns.executors) execs.push_back(e.get());
    numeric::fetch_panels(an, execs, factor);
    solve_on_host(comm, ns.layout, an, factor, x, nrhs);
  }
  ns.stats.solve_seconds += timer.seconds();
  return on_devices;
}

}  // namespace strata::distributed
