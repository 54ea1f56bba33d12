// strata — the values and the contribution blocks between ranks through NCCL (see
// nccl_transport.hpp).
//
// Why: with GPUs on every rank, a block through MPI from host buffers crosses PCIe twice
// on each side (device → host, host → network → host, host → device); NCCL moves it from
// device memory to device memory over NVLink or GPUDirect RDMA where the machine has them
// (NCCL documentation, "Point-to-point communication"). The blocks of one factorization
// are sent and received inside one ncclGroupStart/End, so that NCCL schedules them
// together and a rank's sends cannot deadlock on each other.
//
// Staging (a rank with several GPUs, or a block in host memory): the block is copied onto
// the NCCL GPU on the NCCL stream itself, so that stream order puts the copy before the
// send. A plain cudaMemcpy is not enough: a device-to-device copy, and a copy from
// pageable host memory, may return before the data has landed (CUDA Runtime API,
// "API synchronization behavior"), and it runs on the legacy default stream, with which
// the NCCL stream (cudaStreamNonBlocking) does not synchronize — so ncclSend could read
// the staging buffer before the copy reached it: the likely cause of the wrong factor of
// the 2 ranks × 2 GPUs run (docs/distributed.md §5; not yet confirmed on a GPU), as only
// a rank's second GPU stages its blocks.
#include "distributed/nccl_transport.hpp"

#include <cuda_runtime.h>
#include <nccl.h>

#include <cmath>
#include <cstdint>
#include <string>
#include <utility>

#include "numeric/cuda/triangle_pack.hpp"

namespace strata::distributed {
namespace {

void cuda_check(cudaError_t e, const char* what) {
  if (e != cudaSuccess) throw DeviceError(std::string(what) + " failed: " + cudaGetErrorString(e));
}
void nccl_check(ncclResult_t r, const char* what) {
  if (r != ncclSuccess) throw DeviceError(std::string(what) + " failed: " + ncclGetErrorString(r));
}

// A device buffer on the current device.
struct DeviceBlock {
  double* p = nullptr;
  int device = -1;
  std::size_t size = 0;  // doubles
  DeviceBlock() = default;
  DeviceBlock(std::size_t n, int dev) : device(dev), size(n) {
    cuda_check(cudaMalloc(&p, sizeof(double) * (n ? n : 1)), "cudaMalloc (NCCL block)");
  }
  DeviceBlock(DeviceBlock&& o) noexcept : p(o.p), device(o.device), size(o.size) { o.p = nullptr; }
  DeviceBlock& operator=(DeviceBlock&& o) noexcept {  // the old buffer goes with o
    std::swap(p, o.p);
    std::swap(device, o.device);
    std::swap(size, o.size);
    return *this;
  }
  ~DeviceBlock() {
    if (p) {
      cudaSetDevice(device);
      cudaFree(p);
    }
  }
};

// Takes a kept buffer of `size` doubles in order from `kept` (reused when the sizes
// agree, as at every refactorization), else allocates one; appends it to `into`.
double* reuse_block(std::vector<DeviceBlock>& kept, std::size_t& next,
                    std::vector<DeviceBlock>& into, std::size_t size, int device) {
  if (next < kept.size() && kept[next].size == size)
    into.push_back(std::move(kept[next++]));
  else
    into.emplace_back(size, device);
  return into.back().p;
}

}  // namespace

struct NcclContext {
  ncclComm_t comm = nullptr;
  int device = -1;
  cudaStream_t stream = nullptr;
  cudaEvent_t copied = nullptr;  // rank 0: its values' host-to-device copies done
  // Kept from one exchange to the next, which reuses them when their sizes are the same (a
  // refactorization): no allocation, and no cudaFree, which waits for the device, in the
  // factorization's path. Rank 0: the received blocks (imported by the top part) and,
  // for symmetric types, the packed triangles they arrive in; the others: the packed
  // triangles and staging copies they send from. `values`: rank 0's packed values for
  // each rank (index r), the others' as received (index 0).
  std::vector<DeviceBlock> blocks, packed, values;
  ~NcclContext() {
    if (stream) cudaStreamSynchronize(stream);  // a values send may still be in flight
    blocks.clear();
    packed.clear();
    values.clear();
    if (copied) cudaEventDestroy(copied);
    if (stream) cudaStreamDestroy(stream);
    if (comm) ncclCommDestroy(comm);
  }
};

namespace {

// This rank's NCCL communicator on `device`, made at the first transfer after an
// analysis (collective: every rank calls it at the same point).
NcclContext& context(detail::CommImpl& comm, NumericState& ns, int device) {
  cuda_check(cudaSetDevice(device), "cudaSetDevice");
  if (!ns.nccl_context || ns.nccl_context->device != device) {
    ns.nccl_context.reset();
    ncclUniqueId id;
    if (comm.rank() == 0) nccl_check(ncclGetUniqueId(&id), "ncclGetUniqueId");
    comm.broadcast(&id, sizeof id, 0);
    auto ctx = std::make_shared<NcclContext>();
    ctx->device = device;
    nccl_check(ncclCommInitRank(&ctx->comm, comm.size(), id, comm.rank()), "ncclCommInitRank");
    cuda_check(cudaStreamCreateWithFlags(&ctx->stream, cudaStreamNonBlocking), "cudaStreamCreate");
    cuda_check(cudaEventCreateWithFlags(&ctx->copied, cudaEventDisableTiming), "cudaEventCreate");
    ns.nccl_context = std::move(ctx);
  }
  return *ns.nccl_context;
}

}  // namespace

void transfer_values_nccl(detail::CommImpl& comm, NumericState& ns, int device,
                          std::exception_ptr failed) {
  const int rank = comm.rank();
  std::vector<std::vector<double>>& packed = ns.values_packed;
  NcclContext* c = nullptr;
  try {
    c = &context(comm, ns, device);
    // the device buffers, before anything travels: an allocation that fails on one rank
    // must not leave another waiting in an NCCL receive
    const std::size_t first = rank == 0 ? 1 : 0, end = rank == 0 ? packed.size() : 1;
    if (c->values.size() < end) c->values.resize(end);
    for (std::size_t r = first; r < end && !failed; ++r)
      if (c->values[r].size != packed[r].size()) {
        c->values[r] = DeviceBlock();
        if (!packed[r].empty()) c->values[r] = DeviceBlock(packed[r].size(), device);
      }
  } catch (...) {
    if (!failed) failed = std::current_exception();
  }
  agree(comm, failed);
  cudaStream_t s = c->stream;
  if (rank == 0) {
    for (std::size_t r = 1; r < packed.size(); ++r)
      if (!packed[r].empty())
        cuda_check(cudaMemcpyAsync(c->values[r].p, packed[r].data(),
                                   sizeof(double) * packed[r].size(), cudaMemcpyHostToDevice, s),
                   "cudaMemcpyAsync (values)");
    cuda_check(cudaEventRecord(c->copied, s), "cudaEventRecord");
  }
  nccl_check(ncclGroupStart(), "ncclGroupStart");
  if (rank == 0) {
    for (std::size_t r = 1; r < packed.size(); ++r)
      if (!packed[r].empty()) {
        nccl_check(
            ncclSend(c->values[r].p, packed[r].size(), ncclDouble, static_cast<int>(r), c->comm, s),
            "ncclSend (values)");
        comm.bytes_sent += sizeof(double) * packed[r].size();
      }
  } else if (!packed[0].empty()) {
    nccl_check(ncclRecv(c->values[0].p, packed[0].size(), ncclDouble, 0, c->comm, s),
               "ncclRecv (values)");
    comm.bytes_received += sizeof(double) * packed[0].size();
  }
  nccl_check(ncclGroupEnd(), "ncclGroupEnd");
  if (rank == 0) {
    // the host buffers may be written again once copied; the sends go on beside rank 0's
    // own subtrees, in stream order before any later use of the device buffers
    cuda_check(cudaEventSynchronize(c->copied), "cudaEventSynchronize (values)");
    return;
  }
  if (!packed[0].empty())
    cuda_check(cudaMemcpyAsync(packed[0].data(), c->values[0].p, sizeof(double) * packed[0].size(),
                               cudaMemcpyDeviceToHost, s),
               "cudaMemcpyAsync (values)");
  cuda_check(cudaStreamSynchronize(s), "cudaStreamSynchronize (values)");
}

void exchange_blocks_nccl(detail::CommImpl& comm, NumericState& ns, const RankLayout& l,
                          std::vector<numeric::CbTransfer>& tr, int device, bool symmetric) {
  const int rank = comm.rank();
  NcclContext& c = context(comm, ns, device);
  std::vector<DeviceBlock> kept_blocks = std::move(c.blocks), kept_packed = std::move(c.packed);
  c.blocks.clear();
  c.packed.clear();
  std::size_t next_block = 0, next_packed = 0;
  // tr is indexed by part id: the subtrees come first (the top part's entry follows)
  const int n_sub = static_cast<int>(l.subtree_rank.size());
  if (tr.size() < l.subtree_rank.size()) throw InternalError("fewer block transfers than subtrees");
  // Stage first (copies may not be inside the NCCL group), on the NCCL stream (see above).
  // A symmetric type's block (its lower triangle is what the importer needs) travels as
  // its packed lower triangle, about half the bytes, unpacked on rank 0 with both
  // triangles as the block was.
  std::vector<const double*> wire(n_sub, nullptr);  // what the send reads / the receive writes
  std::vector<std::size_t> count(n_sub, 0);
  std::vector<double*> full(n_sub, nullptr);  // rank 0: the block the importer gets
  for (int i = 0; i < n_sub; ++i) {
    numeric::CbTransfer& x = tr[i];
    const int owner = l.subtree_rank[i];
    if (x.size == 0 || owner == 0) continue;
    const auto m = static_cast<std::int64_t>(std::llround(std::sqrt(static_cast<double>(x.size))));
    if (static_cast<std::size_t>(m * m) != x.size)
      throw InternalError("a contribution block of " + std::to_string(x.size) +
                          " doubles is not square");
    count[i] = symmetric ? static_cast<std::size_t>(cuda::packed_lower_size(m)) : x.size;
    if (rank == 0) {
      full[i] = reuse_block(kept_blocks, next_block, c.blocks, x.size, device);
      wire[i] =
          symmetric ? reuse_block(kept_packed, next_packed, c.packed, count[i], device) : full[i];
    } else if (owner == rank) {
      const double* block = x.device;
      if (x.on_host || x.device_ordinal != device) {
        double* copy = reuse_block(kept_packed, next_packed, c.packed, x.size, device);
        const std::size_t bytes = sizeof(double) * x.size;
        if (x.on_host)
          cuda_check(cudaMemcpyAsync(copy, x.host, bytes, cudaMemcpyHostToDevice, c.stream),
                     "cudaMemcpyAsync (NCCL staging)");
        else  // another GPU of this rank: explicit devices, no peer access needed
          cuda_check(cudaMemcpyPeerAsync(copy, device, x.device, x.device_ordinal, bytes, c.stream),
                     "cudaMemcpyPeerAsync (NCCL staging)");
        block = copy;
      }
      if (symmetric) {
        double* tri = reuse_block(kept_packed, next_packed, c.packed, count[i], device);
        cuda::pack_lower_triangle(block, m, tri, c.stream);
        block = tri;
      }
      wire[i] = block;
    }
  }
  nccl_check(ncclGroupStart(), "ncclGroupStart");
  for (int i = 0; i < n_sub; ++i) {
    if (!wire[i]) continue;
    if (rank == 0) {
      nccl_check(ncclRecv(const_cast<double*>(wire[i]), count[i], ncclDouble, l.subtree_rank[i],
                          c.comm, c.stream),
                 "ncclRecv");
      comm.bytes_received += sizeof(double) * count[i];
    } else {
      nccl_check(ncclSend(wire[i], count[i], ncclDouble, 0, c.comm, c.stream), "ncclSend");
      comm.bytes_sent += sizeof(double) * count[i];
    }
  }
  nccl_check(ncclGroupEnd(), "ncclGroupEnd");
  if (rank == 0 && symmetric)
    for (int i = 0; i < n_sub; ++i)
      if (wire[i]) {
        const auto m =
            static_cast<std::int64_t>(std::llround(std::sqrt(static_cast<double>(tr[i].size))));
        cuda::unpack_symmetric(wire[i], m, full[i], c.stream);
      }
  cuda_check(cudaStreamSynchronize(c.stream), "cudaStreamSynchronize (NCCL)");
  if (rank == 0)
    for (int i = 0; i < n_sub; ++i) {
      if (!wire[i]) continue;
      numeric::CbTransfer& x = tr[i];
      x.device = full[i];
      x.device_ordinal = device;
      x.on_host = false;
    }
}

}  // namespace strata::distributed
