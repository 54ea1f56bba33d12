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

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>

#include "numeric/cuda/device_buffer.hpp"
#include "numeric/cuda/triangle_pack.hpp"
#include "numeric/cuda/value_positions.hpp"

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
  // triangles and staging copies they send from.
  std::vector<DeviceBlock> blocks, packed;
  // The scaled values (values.cpp): `full`, every value in the canonical order (rank 0:
  // uploaded from its host; the others: their share scattered in, zero elsewhere), which
  // the executors copy; `shares` and `positions`, each rank's share and its positions in
  // `full` (rank 0: index r for each rank r; the others: their own at index 0), the
  // positions uploaded once per analysis (positions_generation).
  cuda::DeviceBuffer<double> full;
  std::vector<cuda::DeviceBuffer<double>> shares;
  std::vector<cuda::DeviceBuffer<index_t>> positions;
  std::uint64_t positions_generation = 0;
  ~NcclContext() {
    if (stream) cudaStreamSynchronize(stream);  // a values send may still be in flight
    if (device >= 0) cudaSetDevice(device);
    blocks.clear();
    packed.clear();
    full.clear();
    shares.clear();
    positions.clear();
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

void send_values_nccl(detail::CommImpl& comm, NumericState& ns, const double* values,
                      std::size_t nnz, int device, std::exception_ptr failed) {
  const int ranks = comm.size();
  ns.device_values = nullptr;
  NcclContext* c = nullptr;
  try {
    c = &context(comm, ns, device);
    if (!failed) {
      c->full.resize(std::max<std::size_t>(nnz, 1));
      c->shares.resize(ranks);
      c->positions.resize(ranks);
      const bool upload = c->positions_generation != ns.positions_generation;
      for (int r = 1; r < ranks; ++r) {
        const std::vector<index_t>& pos = ns.value_positions.at(r);
        c->shares[r].resize(std::max<std::size_t>(pos.size(), 1));
        if (upload) c->positions[r].upload(pos.data(), pos.size(), c->stream);
      }
      c->positions_generation = ns.positions_generation;
    }
  } catch (...) {
    if (!failed) failed = std::current_exception();
  }
  // before anything travels: an error on any rank (an allocation here) is thrown on all,
  // so that none is left waiting in an NCCL receive
  agree(comm, failed);
  cudaStream_t s = c->stream;
  if (nnz > 0)  // cudaMemcpyDefault: host memory, or the device where the value pass ran
    cuda_check(cudaMemcpyAsync(c->full.data(), values, sizeof(double) * nnz, cudaMemcpyDefault, s),
               "cudaMemcpyAsync (values)");
  cuda_check(cudaEventRecord(c->copied, s), "cudaEventRecord");
  for (int r = 1; r < ranks; ++r)
    cuda::gather_positions(c->full.data(), c->positions[r].data(),
                           static_cast<std::int64_t>(ns.value_positions[r].size()),
                           c->shares[r].data(), s);
  nccl_check(ncclGroupStart(), "ncclGroupStart");
  for (int r = 1; r < ranks; ++r) {
    const std::size_t count = ns.value_positions[r].size();
    if (count == 0) continue;
    nccl_check(ncclSend(c->shares[r].data(), count, ncclDouble, r, c->comm, s),
               "ncclSend (values)");
    comm.bytes_sent += sizeof(double) * count;
  }
  nccl_check(ncclGroupEnd(), "ncclGroupEnd");
  // the executors copy the values from c->full once they are there; the gathers and
  // sends go on beside rank 0's own subtrees (the next factorization's upload into
  // c->full comes after the executors' copies: they finish within this factorization)
  cuda_check(cudaEventSynchronize(c->copied), "cudaEventSynchronize (values)");
  ns.device_values = c->full.data();
  ns.device_values_device = device;
}

void receive_values_nccl(detail::CommImpl& comm, NumericState& ns, std::size_t nnz, int device,
                         double* host_share, std::exception_ptr failed) {
  const int rank = comm.rank();
  ns.device_values = nullptr;
  const std::vector<index_t>& pos = ns.value_positions.at(rank);
  NcclContext* c = nullptr;
  try {
    c = &context(comm, ns, device);
    if (!failed) {
      c->shares.resize(1);
      c->positions.resize(1);
      c->shares[0].resize(std::max<std::size_t>(pos.size(), 1));
      if (c->positions_generation != ns.positions_generation || c->full.size() < nnz) {
        // entries off this rank's positions are never read: zero, once per analysis
        c->full.resize(std::max<std::size_t>(nnz, 1));
        cuda_check(cudaMemsetAsync(c->full.data(), 0, sizeof(double) * c->full.size(), c->stream),
                   "cudaMemsetAsync (values)");
        c->positions[0].upload(pos.data(), pos.size(), c->stream);
        c->positions_generation = ns.positions_generation;
      }
    }
  } catch (...) {
    if (!failed) failed = std::current_exception();
  }
  agree(comm, failed);
  cudaStream_t s = c->stream;
  if (!pos.empty()) {
    nccl_check(ncclGroupStart(), "ncclGroupStart");
    nccl_check(ncclRecv(c->shares[0].data(), pos.size(), ncclDouble, 0, c->comm, s),
               "ncclRecv (values)");
    nccl_check(ncclGroupEnd(), "ncclGroupEnd");
    comm.bytes_received += sizeof(double) * pos.size();
    cuda::scatter_positions(c->shares[0].data(), c->positions[0].data(),
                            static_cast<std::int64_t>(pos.size()), c->full.data(), s);
    if (host_share)
      cuda_check(cudaMemcpyAsync(host_share, c->shares[0].data(), sizeof(double) * pos.size(),
                                 cudaMemcpyDeviceToHost, s),
                 "cudaMemcpyAsync (values)");
  }
  cuda_check(cudaStreamSynchronize(s), "cudaStreamSynchronize (values)");
  ns.device_values = c->full.data();
  ns.device_values_device = device;
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
      if (!x.on_host && x.device_ready)  // pushed here by its exporter: once the copy is done
        cuda_check(cudaStreamWaitEvent(c.stream, static_cast<cudaEvent_t>(x.device_ready), 0),
                   "cudaStreamWaitEvent (NCCL staging)");
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
