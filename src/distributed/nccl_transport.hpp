// strata — the scaled values and the contribution blocks between the ranks' GPUs through
// NCCL (build option STRATA_NCCL): each rank's share of the values goes from rank 0's
// first GPU, where they are uploaded once, to the rank's first GPU, where its executors
// copy them from; the subtree roots' blocks go from the GPU
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

/// Rank 0's side of a collective with receive_values_nccl, at every factorization: its
/// `nnz` scaled values — in host memory (page-locked by the Solver for a direct copy) or
/// already on its NCCL GPU `device` (its first executor's, where the value pass ran) —
/// copied once into a buffer there, each rank r's share (ns.value_positions[r]) gathered
/// there and sent by NCCL. Sets ns.device_values to the uploaded array, from which
/// rank 0's executors copy the values device to device. `failed`: this rank's error from
/// its checks (or null), agreed with every rank after the device buffers are allocated
/// and before anything travels, so that every rank throws the same error (agree()) and
/// none waits in a receive. Returns once the upload is done (the sends finish beside the
/// factorization). Counts the bytes in comm's counters. Throws OutOfMemory (device
/// buffers) or DeviceError (CUDA, NCCL) on every rank.
void send_values_nccl(detail::CommImpl& comm, NumericState& ns, const double* values,
                      std::size_t nnz, int device, std::exception_ptr failed);

/// A rank r > 0's side: its share received on its NCCL GPU `device` and scattered into an
/// nnz-long array of the canonical order there (zero off its positions), to which
/// ns.device_values is set; with `host_share` (page-locked, ns.value_positions[r].size()
/// doubles) also copied there, for executors that read values on the host. Returns once
/// both are in place. Throws as send_values_nccl.
void receive_values_nccl(detail::CommImpl& comm, NumericState& ns, std::size_t nnz, int device,
                         double* host_share, std::exception_ptr failed);

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
