// strata — the message layer under the distributed solver: what the solver needs from a
// communicator (broadcast, point-to-point exchange, reduction, gather), behind a small
// interface with two implementations: one process without MPI (comm.cpp) and MPI
// (mpi_comm.cpp, built with STRATA_MPI). Every call is collective over the ranks named
// in its description; byte counters record what crossed between processes, for the
// statistics and the cost model (docs/distributed.md).
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "strata/distributed.hpp"

namespace strata::detail {

/// One message of an exchange: `bytes` at `data` to (send) or from (receive) `peer`, with
/// a tag that tells it from the others between the same two ranks.
struct Message {
  int peer = 0;
  int tag = 0;
  void* data = nullptr;
  std::size_t bytes = 0;
};

class CommImpl {
 public:
  virtual ~CommImpl() = default;
  virtual int rank() const = 0;
  virtual int size() const = 0;
  virtual int local_rank() const = 0;
  /// Number of ranks on this rank's machine.
  virtual int local_size() const = 0;
  /// Broadcast of `bytes` at `data` from `root` (all ranks).
  virtual void broadcast(void* data, std::size_t bytes, int root) = 0;
  /// Posts every receive, then every send, and waits for all (the ranks that take part).
  virtual void exchange(const std::vector<Message>& sends, const std::vector<Message>& recvs) = 0;
  /// Elementwise sum of `count` doubles onto `root` (all ranks; data is in and, on root, out).
  virtual void reduce_sum(double* data, std::size_t count, int root) = 0;
  /// Gathers each rank's bytes on `root` (all ranks): out[r] is rank r's buffer there.
  virtual void gather(const std::vector<char>& mine, std::vector<std::vector<char>>& out,
                      int root) = 0;
  /// Logical or of `flag` over all ranks.
  virtual bool any(bool flag) = 0;

  std::size_t bytes_sent = 0;
  std::size_t bytes_received = 0;
};

/// The one-process communicator (no MPI).
std::shared_ptr<CommImpl> make_self_comm();

}  // namespace strata::detail
