// strata — the MPI communicator (comm.hpp), compiled with STRATA_MPI.
//
// strata works on a duplicate of the caller's communicator so that its messages never
// match the caller's (the usual rule for libraries, MPI 4.0 §6.1). MPI counts are ints:
// anything larger than 2^30 bytes (a contribution block of a front with 11 600 rows or
// more) goes in pieces of 2^30 bytes with one tag — MPI keeps messages between two ranks
// with the same tag in order, so the pieces match up. Errors return (MPI_ERRORS_RETURN)
// and become strata::Error naming the call.
#include <mpi.h>

#include <algorithm>
#include <cstdint>
#include <string>

#include "distributed/comm.hpp"
#include "strata/mpi.hpp"

namespace strata {
namespace detail {
namespace {

constexpr std::size_t kPiece = std::size_t{1} << 30;  // bytes per MPI call at most

void check(int rc, const char* call) {
  if (rc == MPI_SUCCESS) return;
  char text[MPI_MAX_ERROR_STRING];
  int len = 0;
  MPI_Error_string(rc, text, &len);
  throw Error(std::string(call) + " failed: " + std::string(text, static_cast<std::size_t>(len)));
}

class MpiComm final : public CommImpl {
 public:
  explicit MpiComm(MPI_Comm parent) {
    int init = 0;
    MPI_Initialized(&init);
    if (!init) throw InvalidState("mpi_communicator: MPI is not initialized (call MPI_Init first)");
    check(MPI_Comm_dup(parent, &comm_), "MPI_Comm_dup");
    MPI_Comm_set_errhandler(comm_, MPI_ERRORS_RETURN);
    MPI_Comm_rank(comm_, &rank_);
    MPI_Comm_size(comm_, &size_);
    MPI_Comm node;
    check(MPI_Comm_split_type(comm_, MPI_COMM_TYPE_SHARED, rank_, MPI_INFO_NULL, &node),
          "MPI_Comm_split_type");
    MPI_Comm_rank(node, &local_rank_);
    MPI_Comm_size(node, &local_size_);
    MPI_Comm_free(&node);
  }
  ~MpiComm() override {
    int done = 0;
    MPI_Finalized(&done);
    if (!done) MPI_Comm_free(&comm_);
  }
  int rank() const override { return rank_; }
  int size() const override { return size_; }
  int local_rank() const override { return local_rank_; }
  int local_size() const override { return local_size_; }

  void broadcast(void* data, std::size_t bytes, int root) override {
    char* p = static_cast<char*>(data);
    for (std::size_t at = 0; at < bytes; at += kPiece) {
      const int len = static_cast<int>(std::min(kPiece, bytes - at));
      check(MPI_Bcast(p + at, len, MPI_BYTE, root, comm_), "MPI_Bcast");
    }
    if (bytes == 0) return;
    if (rank_ == root)
      bytes_sent += bytes * static_cast<std::size_t>(size_ - 1);
    else
      bytes_received += bytes;
  }

  void exchange(const std::vector<Message>& sends, const std::vector<Message>& recvs) override {
    std::vector<MPI_Request> req;
    auto post = [&](const Message& m, bool send) {
      char* p = static_cast<char*>(m.data);
      for (std::size_t at = 0; at < m.bytes; at += kPiece) {
        const int len = static_cast<int>(std::min(kPiece, m.bytes - at));
        req.emplace_back();
        if (send)
          check(MPI_Isend(p + at, len, MPI_BYTE, m.peer, m.tag, comm_, &req.back()), "MPI_Isend");
        else
          check(MPI_Irecv(p + at, len, MPI_BYTE, m.peer, m.tag, comm_, &req.back()), "MPI_Irecv");
      }
    };
    for (const Message& m : recvs) {
      post(m, false);
      bytes_received += m.bytes;
    }
    for (const Message& m : sends) {
      post(m, true);
      bytes_sent += m.bytes;
    }
    if (!req.empty())
      check(MPI_Waitall(static_cast<int>(req.size()), req.data(), MPI_STATUSES_IGNORE),
            "MPI_Waitall");
  }

  void reduce_sum(double* data, std::size_t count, int root) override {
    const std::size_t piece = kPiece / sizeof(double);
    for (std::size_t at = 0; at < count; at += piece) {
      const int len = static_cast<int>(std::min(piece, count - at));
      if (rank_ == root)
        check(MPI_Reduce(MPI_IN_PLACE, data + at, len, MPI_DOUBLE, MPI_SUM, root, comm_),
              "MPI_Reduce");
      else
        check(MPI_Reduce(data + at, nullptr, len, MPI_DOUBLE, MPI_SUM, root, comm_), "MPI_Reduce");
    }
    if (count == 0) return;
    if (rank_ == root)
      bytes_received += count * sizeof(double) * static_cast<std::size_t>(size_ - 1);
    else
      bytes_sent += count * sizeof(double);
  }

  void gather(const std::vector<char>& mine, std::vector<std::vector<char>>& out,
              int root) override {
    std::uint64_t my_size = mine.size();
    std::vector<std::uint64_t> sizes(rank_ == root ? size_ : 0);
    check(MPI_Gather(&my_size, 1, MPI_UINT64_T, sizes.data(), 1, MPI_UINT64_T, root, comm_),
          "MPI_Gather");
    std::vector<Message> sends, recvs;
    out.clear();
    if (rank_ == root) {
      out.resize(size_);
      for (int r = 0; r < size_; ++r) {
        if (r == root) {
          out[r] = mine;
          continue;
        }
        out[r].resize(sizes[r]);
        if (sizes[r] > 0) recvs.push_back({r, 1, out[r].data(), out[r].size()});
      }
    } else if (!mine.empty()) {
      sends.push_back({root, 1, const_cast<char*>(mine.data()), mine.size()});
    }
    exchange(sends, recvs);
  }

  bool any(bool flag) override {
    int in = flag ? 1 : 0, out = 0;
    check(MPI_Allreduce(&in, &out, 1, MPI_INT, MPI_LOR, comm_), "MPI_Allreduce");
    return out != 0;
  }

 private:
  MPI_Comm comm_ = MPI_COMM_NULL;
  int rank_ = 0, size_ = 1, local_rank_ = 0, local_size_ = 1;
};

}  // namespace
}  // namespace detail

Communicator mpi_communicator(MPI_Comm comm) {
  return Communicator(std::make_shared<detail::MpiComm>(comm));
}

}  // namespace strata
