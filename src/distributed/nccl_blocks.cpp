// strata — contribution blocks through NCCL (see nccl_blocks.hpp).
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
#include "distributed/nccl_blocks.hpp"

#include <cuda_runtime.h>
#include <nccl.h>

#include <string>

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
  DeviceBlock& operator=(DeviceBlock&&) = delete;
  ~DeviceBlock() {
    if (p) {
      cudaSetDevice(device);
      cudaFree(p);
    }
  }
};

}  // namespace

struct NcclContext {
  ncclComm_t comm = nullptr;
  int device = -1;
  cudaStream_t stream = nullptr;
  // rank 0: the received blocks, kept until the next exchange, which reuses them when
  // their sizes are the same (a refactorization): no allocation, and no cudaFree, which
  // waits for the device, in the factorization's path
  std::vector<DeviceBlock> blocks;
  ~NcclContext() {
    blocks.clear();
    if (stream) cudaStreamDestroy(stream);
    if (comm) ncclCommDestroy(comm);
  }
};

void exchange_blocks_nccl(detail::CommImpl& comm, NumericState& ns, const RankLayout& l,
                          std::vector<numeric::CbTransfer>& tr, int device) {
  const int rank = comm.rank();
  cuda_check(cudaSetDevice(device), "cudaSetDevice");
  if (!ns.nccl_context || ns.nccl_context->device != device) {
    ncclUniqueId id;
    if (rank == 0) nccl_check(ncclGetUniqueId(&id), "ncclGetUniqueId");
    comm.broadcast(&id, sizeof id, 0);
    auto ctx = std::make_shared<NcclContext>();
    ctx->device = device;
    nccl_check(ncclCommInitRank(&ctx->comm, comm.size(), id, rank), "ncclCommInitRank");
    cuda_check(cudaStreamCreateWithFlags(&ctx->stream, cudaStreamNonBlocking), "cudaStreamCreate");
    ns.nccl_context = std::move(ctx);
  }
  NcclContext& c = *ns.nccl_context;
  std::vector<DeviceBlock> kept = std::move(c.blocks);
  c.blocks.clear();
  std::size_t next_kept = 0;
  std::vector<DeviceBlock> staging;  // senders: blocks not on the NCCL device
  // tr is indexed by part id: the subtrees come first (the top part's entry follows)
  const int n_sub = static_cast<int>(l.subtree_rank.size());
  if (tr.size() < l.subtree_rank.size()) throw InternalError("fewer block transfers than subtrees");
  // stage first (copies may not be inside the NCCL group), on the NCCL stream (see above)
  std::vector<const double*> src(n_sub, nullptr);
  for (int i = 0; i < n_sub; ++i) {
    numeric::CbTransfer& x = tr[i];
    const int owner = l.subtree_rank[i];
    if (x.size == 0 || owner == 0) continue;
    if (rank == 0) {
      if (next_kept < kept.size() && kept[next_kept].size == x.size)
        c.blocks.push_back(std::move(kept[next_kept++]));
      else
        c.blocks.emplace_back(x.size, device);
      src[i] = c.blocks.back().p;
    } else if (owner == rank) {
      if (!x.on_host && x.device_ordinal == device) {
        src[i] = x.device;
      } else {
        staging.emplace_back(x.size, device);
        const std::size_t bytes = sizeof(double) * x.size;
        if (x.on_host)
          cuda_check(
              cudaMemcpyAsync(staging.back().p, x.host, bytes, cudaMemcpyHostToDevice, c.stream),
              "cudaMemcpyAsync (NCCL staging)");
        else  // another GPU of this rank: explicit devices, no peer access needed
          cuda_check(cudaMemcpyPeerAsync(staging.back().p, device, x.device, x.device_ordinal,
                                         bytes, c.stream),
                     "cudaMemcpyPeerAsync (NCCL staging)");
        src[i] = staging.back().p;
      }
    }
  }
  nccl_check(ncclGroupStart(), "ncclGroupStart");
  for (int i = 0; i < n_sub; ++i) {
    if (!src[i]) continue;
    numeric::CbTransfer& x = tr[i];
    if (rank == 0) {
      nccl_check(ncclRecv(const_cast<double*>(src[i]), x.size, ncclDouble, l.subtree_rank[i],
                          c.comm, c.stream),
                 "ncclRecv");
      comm.bytes_received += sizeof(double) * x.size;
    } else {
      nccl_check(ncclSend(src[i], x.size, ncclDouble, 0, c.comm, c.stream), "ncclSend");
      comm.bytes_sent += sizeof(double) * x.size;
    }
  }
  nccl_check(ncclGroupEnd(), "ncclGroupEnd");
  cuda_check(cudaStreamSynchronize(c.stream), "cudaStreamSynchronize (NCCL)");
  if (rank == 0)
    for (int i = 0; i < n_sub; ++i) {
      if (!src[i]) continue;
      numeric::CbTransfer& x = tr[i];
      x.device = src[i];
      x.device_ordinal = device;
      x.on_host = false;
    }
}

}  // namespace strata::distributed
