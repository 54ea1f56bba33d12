// strata — Communicator and the one-process communicator (see comm.hpp). With one process
// every collective is the identity: nothing crosses, the counters stay at zero.
#include "distributed/comm.hpp"

namespace strata {
namespace detail {
namespace {

class SelfComm final : public CommImpl {
 public:
  int rank() const override { return 0; }
  int size() const override { return 1; }
  int local_rank() const override { return 0; }
  int local_size() const override { return 1; }
  void broadcast(void*, std::size_t, int) override {}
  void exchange(const std::vector<Message>& sends, const std::vector<Message>& recvs) override {
    if (!sends.empty() || !recvs.empty())
      throw InternalError("a one-process communicator has no peer to exchange with");
  }
  void reduce_sum(double*, std::size_t, int) override {}
  void gather(const std::vector<char>& mine, std::vector<std::vector<char>>& out, int) override {
    out.assign(1, mine);
  }
  bool any(bool flag) override { return flag; }
};

}  // namespace

std::shared_ptr<CommImpl> make_self_comm() { return std::make_shared<SelfComm>(); }

}  // namespace detail

Communicator::Communicator() : impl_(detail::make_self_comm()) {}
Communicator::Communicator(std::shared_ptr<detail::CommImpl> impl) : impl_(std::move(impl)) {
  if (!impl_) throw InvalidInput("Communicator: null implementation");
}
int Communicator::rank() const { return impl_->rank(); }
int Communicator::size() const { return impl_->size(); }
int Communicator::local_rank() const { return impl_->local_rank(); }
std::size_t Communicator::bytes_sent() const { return impl_->bytes_sent; }
std::size_t Communicator::bytes_received() const { return impl_->bytes_received; }
bool Communicator::mpi_available() {
#ifdef STRATA_HAVE_MPI
  return true;
#else
  return false;
#endif
}

}  // namespace strata
