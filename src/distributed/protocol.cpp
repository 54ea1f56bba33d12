// strata — the rank layout and the command protocol of the distributed solver.
//
// Rank 0 runs the Solver's phases (validation, scaling, type resolution, statistics,
// iterative refinement); whenever they need the other ranks it broadcasts a command
// (analysis, factor, apply) and the others, waiting in their own call of the same phase,
// follow it. A phase ends with `end` (the others return) or `error` (the others throw
// the same exception). So a program calls the same methods on every rank, as with any
// collective library (the MUMPS and PETSc convention), and the others never need the
// matrix.
#include <algorithm>
#include <cstring>
#include <string>

#include "distributed/distributed_internal.hpp"

namespace strata::distributed {

RankLayout make_layout(const Analysis& an, int ranks, int rank, int workers_per_rank) {
  RankLayout l;
  l.ranks = ranks;
  l.rank = rank;
  l.workers_per_rank = workers_per_rank;
  const auto& p = an.partition;
  const auto& t = an.tree;
  // the ranks hand blocks to rank 0's top part only: upper layers (Options::split_top)
  // are not part of the protocol, and the distributed solver analyzes without them
  if (!p.upper.empty())
    throw InternalError(
        "an analysis with upper layers (Options::split_top) cannot be "
        "factored across ranks");
  const int n_sub = static_cast<int>(p.subtrees.size());
  l.subtree_rank.resize(n_sub);
  l.subtrees_of.assign(ranks, {});
  l.col_begin.resize(n_sub);
  l.col_end.resize(n_sub);
  std::vector<char> in_subtree(t.n, 0);
  for (int i = 0; i < n_sub; ++i) {
    const int r = p.owner[i] / workers_per_rank;
    if (r < 0 || r >= ranks)
      throw InternalError("subtree " + std::to_string(i) + " belongs to worker " +
                          std::to_string(p.owner[i]) + ", beyond " + std::to_string(ranks) +
                          " ranks");
    l.subtree_rank[i] = r;
    l.subtrees_of[r].push_back(i);
    const auto& fronts = p.subtrees[i].fronts;  // a contiguous range of fronts
    l.col_begin[i] = t.first_pivot[fronts.front()];
    l.col_end[i] = t.first_pivot[fronts.back() + 1];
    for (index_t c = l.col_begin[i]; c < l.col_end[i]; ++c) in_subtree[c] = 1;
    if (r == rank) l.my_fronts.insert(l.my_fronts.end(), fronts.begin(), fronts.end());
  }
  std::sort(l.my_fronts.begin(), l.my_fronts.end());
  for (index_t c = 0; c < t.n; ++c)
    if (!in_subtree[c]) l.top_cols.push_back(c);
  return l;
}

void localize_factor_layout(Analysis& an, const RankLayout& l) {
  const auto& t = an.tree;
  const bool lu = !an.symmetric;
  FactorLayout out;
  out.panel_offset.assign(t.n_fronts() + 1, 0);
  std::vector<char> placed(t.n_fronts(), 0);
  std::size_t at = 0;
  auto place = [&](const schedule::FactorPart& part) {
    for (const index_t f : part.schedule.fronts) {
      out.panel_offset[f] = at;
      placed[f] = 1;
      at += panel_size(t, f, lu);
    }
  };
  for (const int i : l.subtrees_of[l.rank]) place(an.partition.subtrees[i]);
  if (l.rank == 0) place(an.partition.top);
  for (index_t f = 0; f < t.n_fronts(); ++f)
    if (!placed[f]) out.panel_offset[f] = at;
  out.panel_offset[t.n_fronts()] = at;
  out.total = at;
  an.factor_layout = std::move(out);
}

void send_command(detail::CommImpl& comm, Header h, const void* payload) {
  comm.broadcast(&h, sizeof h, 0);
  if (h.payload > 0) comm.broadcast(const_cast<void*>(payload), h.payload, 0);
}

Header receive_command(detail::CommImpl& comm, std::vector<char>& payload) {
  Header h;
  comm.broadcast(&h, sizeof h, 0);
  payload.resize(h.payload);
  if (h.payload > 0) comm.broadcast(payload.data(), h.payload, 0);
  return h;
}

namespace {

enum ErrorKind : std::int32_t {
  kError = 0,
  kInvalidInput,
  kNotSupported,
  kOutOfMemory,
  kDeviceError,
  kNotPositiveDefinite,
  kInvalidState,
  kInternal,
  kOther
};

}  // namespace

Header error_header(std::exception_ptr e, std::vector<char>& message) {
  Header h;
  h.command = Command::error;
  std::string what;
  try {
    std::rethrow_exception(e);
  } catch (const NotPositiveDefinite& x) {
    h.a = kNotPositiveDefinite;
    h.b = x.column();
    h.c = x.pivot();
    what = x.what();
  } catch (const OutOfMemory& x) {
    h.a = kOutOfMemory;
    h.b = static_cast<std::int64_t>(x.bytes_requested());
    what = x.what();
  } catch (const InvalidInput& x) {
    h.a = kInvalidInput;
    what = x.what();
  } catch (const NotSupported& x) {
    h.a = kNotSupported;
    what = x.what();
  } catch (const DeviceError& x) {
    h.a = kDeviceError;
    what = x.what();
  } catch (const InvalidState& x) {
    h.a = kInvalidState;
    what = x.what();
  } catch (const InternalError& x) {
    h.a = kInternal;
    what = x.detail();
  } catch (const Error& x) {
    h.a = kError;
    what = x.what();
  } catch (const std::exception& x) {
    h.a = kOther;
    what = x.what();
  } catch (...) {
    h.a = kOther;
    what = "unknown exception";
  }
  message.assign(what.begin(), what.end());
  h.payload = message.size();
  return h;
}

void throw_error(const Header& h, const std::vector<char>& message) {
  std::string what(message.begin(), message.end());
  switch (h.a) {
    case kNotPositiveDefinite:
      throw NotPositiveDefinite(static_cast<index_t>(h.b), h.c);
    case kOutOfMemory: {
      // OutOfMemory builds "out of memory: WHERE asked for N bytes": recover WHERE
      const std::string head = "out of memory: ";
      if (what.rfind(head, 0) == 0) what = what.substr(head.size());
      const std::string tail = h.b > 0 ? " asked for " + std::to_string(h.b) + " bytes"
                                       : " (the size of the failed allocation is not known)";
      if (what.size() >= tail.size() &&
          what.compare(what.size() - tail.size(), tail.size(), tail) == 0)
        what.resize(what.size() - tail.size());
      throw OutOfMemory(static_cast<std::size_t>(h.b), what);
    }
    case kInvalidInput:
      throw InvalidInput(what);
    case kNotSupported:
      throw NotSupported(what);
    case kDeviceError:
      throw DeviceError(what);
    case kInvalidState:
      throw InvalidState(what);
    case kInternal:
      throw InternalError(what);
    default:
      throw Error(what);
  }
}

void agree(detail::CommImpl& comm, std::exception_ptr mine) {
  if (!comm.any(static_cast<bool>(mine))) return;
  // the lowest failing rank's error, prefixed by its rank, from rank 0 to all
  std::vector<char> msg, mine_bytes;
  if (mine) {
    Header h = error_header(mine, msg);
    mine_bytes.resize(sizeof h);
    std::memcpy(mine_bytes.data(), &h, sizeof h);
    mine_bytes.insert(mine_bytes.end(), msg.begin(), msg.end());
  }
  std::vector<std::vector<char>> all;
  comm.gather(mine_bytes, all, 0);
  Header h;
  std::vector<char> text;
  if (comm.rank() == 0) {
    for (int r = 0; r < comm.size(); ++r) {
      if (all[r].empty()) continue;
      std::memcpy(&h, all[r].data(), sizeof h);
      text.assign(all[r].begin() + sizeof h, all[r].end());
      // NotPositiveDefinite and OutOfMemory rebuild their text from their fields
      if (r != 0 && h.a != kNotPositiveDefinite && h.a != kOutOfMemory) {
        const std::string prefix = "rank " + std::to_string(r) + ": ";
        text.insert(text.begin(), prefix.begin(), prefix.end());
      }
      h.payload = text.size();
      break;
    }
  }
  comm.broadcast(&h, sizeof h, 0);
  text.resize(h.payload);
  if (h.payload > 0) comm.broadcast(text.data(), h.payload, 0);
  throw_error(h, text);
}

}  // namespace strata::distributed
