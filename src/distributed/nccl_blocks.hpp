// strata — contribution blocks between the ranks' GPUs through NCCL (build option
// STRATA_NCCL): the subtree roots' blocks go from the GPU that factored them straight to
// rank 0's first GPU, where the top part imports them, without a copy through host memory
// on either side (docs/distributed.md §2). NCCL (NVIDIA Collective Communications
// Library) point-to-point ncclSend/ncclRecv inside one group; the NCCL communicator is made
// once per rank layout from a unique id that rank 0 broadcasts over MPI.
#pragma once

#include <vector>

#include "distributed/distributed_internal.hpp"

namespace strata::distributed {

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
