// strata — the scaled values and the contribution blocks between the ranks' GPUs through
// NCCL (build option STRATA_NCCL): each rank's values go from rank 0's host memory over
// rank 0's first GPU to the rank's first GPU; the subtree roots' blocks go from the GPU
// that factored them straight to rank 0's first GPU, where the top part imports them,
// without a copy through host memory on either side (docs/distributed.md §2). NCCL
// (NVIDIA Collective Communications Library) point-to-point ncclSend/ncclRecv inside one
// group per transfer; the NCCL communicator is made once per rank layout from a unique id
// that rank 0 broadcasts over MPI.
#pragma once

#include <exception>
#include <vector>

#include "distributed/distributed_internal.hpp"

namespace strata::distributed {

/// Collective over the ranks, at every factorization: the packed values of ns.values_packed
/// travel from rank 0 (packed[r], r = 1 … R − 1, as send_values packed them) to each rank
/// r (into packed[0], sized by receive_values to what r receives), through rank 0's and
/// r's GPU `device` (this rank's NCCL GPU, its first executor's): host-to-device copy,
/// ncclSend/ncclRecv, device-to-host copy. Page-locked host buffers make the copies
/// direct. `failed`: this rank's error from its packing or preparation (or null), agreed
/// with every rank after the device buffers are allocated and before anything travels,
/// so that every rank throws the same error (agree()) and none waits in a receive. Rank 0
/// returns once its host buffers are copied (the sends finish beside its factorization,
/// in stream order before the next use of the device buffers); the others once their
/// values are in packed[0]. Counts the bytes in comm's counters. Throws DeviceError on a
/// CUDA or NCCL failure.
void transfer_values_nccl(detail::CommImpl& comm, NumericState& ns, int device,
                          std::exception_ptr failed);

/// Collective over the ranks: each rank sends the blocks of its subtrees (tr[i], left in
/// device memory by its exporter, or on the host) to rank 0, whose receives land in
/// device buffers on `device` (rank 0's top-part GPU) and are handed to the importer as
/// device blocks (tr[i].device, device_ordinal). `device` is this rank's NCCL GPU (its first
/// executor's). `symmetric` (LLᵀ, LDLᵀ): each block travels as its packed lower triangle
/// and arrives with both triangles. Counts the bytes in comm's counters. Throws
/// DeviceError on a CUDA or NCCL failure, InternalError for a block that is not square.
void exchange_blocks_nccl(detail::CommImpl& comm, NumericState& ns, const RankLayout& l,
                          std::vector<numeric::CbTransfer>& tr, int device, bool symmetric);

}  // namespace strata::distributed
