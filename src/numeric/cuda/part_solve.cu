// strata — the triangular solves of a multi-GPU factor where its parts live.
//
// What: after a multi-GPU factorization each part of the split tree (subtrees, upper
// parts, the top part; schedule/tree_partition.hpp) keeps its panels on the GPU that
// factored it (NumericFactor::held). A solve then runs part by part on those GPUs, as
// SPRAL SSIDS's numeric subtrees each solve with their own storage: the forward sweep of
// the parts layer by layer from the subtrees up to the top part, each part exporting the
// update vectors of its fronts whose parent lies in another part (its contribution to the
// right-hand side above it) and importing those of its children in other parts; then the
// backward sweep from the top part down, each part reading the solution at the pivot rows
// of the fronts above it. The driver (numeric/driver.cpp) runs the layers in order and the
// GPUs of one layer side by side; the data between them goes through host memory: the
// parts' pivot rows of x and the exported update vectors, O(n) doubles per right-hand
// side, instead of every panel of the factor for a host solve.
//
// How: a part's sweeps are the device solve of cuda_solve.cu with a plan over the part's
// fronts only (plan_sweeps with the part's front set and the whole tree's subtree limit),
// its panels read from the part's own buffer. The x, update-vector and scratch arrays on
// the device are the whole tree's, so the kernels index them as in the whole-tree solve
// and a part's imports and exports are copies of ranges of the update-vector arena.
//
// Source: the multifrontal solve of Liu (SIAM Review 34, 1992, §6); the split by subtrees
// of Geist & Ng (1989); SPRAL SSIDS's subtree objects (Hogg, Ovtchinnikov, Scott, ACM
// TOMS 42, 2016).
#include <algorithm>
#include <string>

#include "numeric/cuda/cuda_executor.hpp"
#include "numeric/cuda/multiprocessors.hpp"

namespace strata::cuda {
namespace {

using Ranges = SolveRanges;

// Copies rows `ranges` of the nrhs columns (leading dimension ld) between host and
// device, enqueued on s (pageable host memory: the driver stages the copy).
void copy_ranges(double* dev, double* host, const Ranges& ranges, std::int64_t ld, index_t nrhs,
                 bool to_device, cudaStream_t s) {
  for (index_t r = 0; r < nrhs; ++r)
    for (const auto& [b, e] : ranges) {
      const std::int64_t at = b + r * ld;
      if (to_device)
        STRATA_CUDA(cudaMemcpyAsync(dev + at, host + at, sizeof(double) * (e - b),
                                    cudaMemcpyHostToDevice, s));
      else
        STRATA_CUDA(cudaMemcpyAsync(host + at, dev + at, sizeof(double) * (e - b),
                                    cudaMemcpyDeviceToHost, s));
    }
}

}  // namespace

void CudaExecutor::prepare_part_limit(const Analysis& an) {
  if (dsolve_.parts_analysis == an.id) return;
  const int n_sm = multiprocessor_count(device_);
  dsolve_.parts.clear();
  // the subtree limit the whole-tree solve would choose: every part's bottom is cut into
  // the subtrees of the whole tree's plan (a part's own model sees fewer fronts per
  // level and can take level launches where the whole tree's takes subtrees)
  SolvePlan whole;
  plan_sweeps(an.tree, an.schedule, n_sm, SolvePath::model, nullptr, whole);
  dsolve_.parts_limit = whole.subtree_limit;
  dsolve_.parts_analysis = an.id;
}

void CudaExecutor::prepare_part_solve(const Analysis& an) {
  // an LDLᵀ factor's panels go to the host (its solve is the host's)
  const bool cholesky = an.type == MatrixType::spd || an.type == MatrixType::automatic;
  if (!cholesky && an.type != MatrixType::general) return;
  const MatrixType rows_type = cholesky ? MatrixType::spd : MatrixType::general;
  try {
    prepare_solve_inverse(an);
    prepare_part_limit(an);
    if (!(dsolve_.rows_analysis == an.id && dsolve_.rows_type == rows_type))
      upload_solve_rows(an, an.tree.rows.data(), rows_type, nullptr);
    dsolve_.x.resize(std::max<std::size_t>(static_cast<std::size_t>(an.n), 1));
    dsolve_.u.resize(
        std::max<std::size_t>(static_cast<std::size_t>(dsolve_.u_offset_host.back()), 1));
    dsolve_.scratch.resize(std::max<std::size_t>(an.tree.rows.size(), 1));
  } catch (const OutOfMemory&) {
    // the factorization's memory comes first; the first solve tries again or leaves the
    // solve to the host
    for (auto* b : {&dsolve_.x, &dsolve_.u, &dsolve_.scratch}) b->clear();
    dsolve_.inv_offsets.clear();
    dsolve_.inv_src.clear();
    dsolve_.inverse_analysis = 0;
    dsolve_.rows_analysis = 0;
  }
}

CudaExecutor::SweepPlanDevice& CudaExecutor::part_sweep_plan(const Analysis& an, int id) {
  const auto& t = an.tree;
  const int n_sm = multiprocessor_count(device_);
  prepare_part_limit(an);
  auto it = dsolve_.parts.find(id);
  if (it != dsolve_.parts.end()) return it->second;
  const index_t nf = t.n_fronts();
  const schedule::FactorPart& part = an.partition.part(id);  // fronts increasing
  const PartDevice& pd = parts_.at(id);
  SweepPlanDevice sp;
  std::vector<char> in(static_cast<std::size_t>(nf), 0);
  for (const index_t f : part.fronts) in[f] = 1;
  plan_sweeps(t, an.schedule, n_sm, SolvePath::model, &in, sp.plan, &dsolve_.parts_limit);
  sp.plan.analysis = an.id;
  sp.panel_offset_host.assign(static_cast<std::size_t>(nf), 0);
  for (std::size_t q = 0; q < pd.fronts_host.size(); ++q)
    sp.panel_offset_host[pd.fronts_host[q]] = pd.panel_off_host[q];
  sp.exchange = part_exchange(t, part.fronts, dsolve_.u_offset_host);
  upload_sweep_plan(sp);
  return dsolve_.parts.emplace(id, std::move(sp)).first->second;
}

bool CudaExecutor::can_solve_held_parts(const Analysis& an, const numeric::NumericFactor& fac,
                                        const std::vector<int>& parts) const {
  if (an.id != analysis_id_ || planned_ != 2 || !fac.valid ||
      fac.type == MatrixType::symmetric_indefinite || fac.type == MatrixType::automatic)
    return false;
  for (const int id : parts)
    if (std::find(held_parts_.begin(), held_parts_.end(), id) == held_parts_.end() ||
        part_panels_.find(id) == part_panels_.end() || parts_.find(id) == parts_.end())
      return false;
  return true;
}

void CudaExecutor::solve_held_parts(const Analysis& an, const numeric::NumericFactor& fac,
                                    const std::vector<int>& parts, bool forward, double* x,
                                    double* u, index_t nrhs) {
  STRATA_CUDA(cudaSetDevice(device_));
  if (!can_solve_held_parts(an, fac, parts))
    throw InternalError("solve_held_parts: this GPU holds no panels of some of these parts");
  if (an.n == 0 || nrhs == 0 || parts.empty()) return;
  prepare_solve_inverse(an);
  // the row arrays of the last factorization (an LU's pivot rows move), once per
  // factorization
  if (!dsolve_.part_rows_current) {
    if (!(fac.type == MatrixType::spd && dsolve_.rows_analysis == an.id &&
          dsolve_.rows_type == MatrixType::spd))
      upload_solve_rows(an, fac.rows.data(), fac.type, &fac);
    dsolve_.part_rows_current = true;
  }
  std::vector<SweepPlanDevice*> plans;
  std::int64_t part_total = 0;
  for (const int id : parts) {
    plans.push_back(&part_sweep_plan(an, id));
    part_total = std::max(part_total, plans.back()->plan.part_total);
  }
  const std::int64_t u_total = dsolve_.u_offset_host.back();
  dsolve_.x.resize(static_cast<std::size_t>(an.n) * nrhs);
  dsolve_.u.resize(std::max<std::size_t>(static_cast<std::size_t>(u_total) * nrhs, 1));
  dsolve_.scratch.resize(std::max<std::size_t>(an.tree.rows.size() * nrhs, 1));
  dsolve_.part.resize(std::max<std::size_t>(static_cast<std::size_t>(part_total) * nrhs, 1));
  double* X = dsolve_.x.data();
  double* U = dsolve_.u.data();
  for (const SweepPlanDevice* sp : plans) {
    const PartExchange& e = sp->exchange;
    copy_ranges(X, x, e.own_rows, an.n, nrhs, true, stream_);
    if (forward)
      copy_ranges(U, u, e.imports, u_total, nrhs, true, stream_);
    else
      copy_ranges(X, x, e.above_rows, an.n, nrhs, true, stream_);
  }
  // the forward sweep in the given order, the backward one in the reverse (the caller
  // lists a layer's parts, which do not depend on each other)
  for (std::size_t q = 0; q < plans.size(); ++q) {
    const std::size_t i = forward ? q : plans.size() - 1 - q;
    enqueue_solve_sweeps(an, fac, *plans[i], part_panels_.at(parts[i]).data(), nrhs, forward,
                         !forward);
  }
  for (const SweepPlanDevice* sp : plans) {
    copy_ranges(X, x, sp->exchange.own_rows, an.n, nrhs, false, stream_);
    if (forward) copy_ranges(U, u, sp->exchange.exports, u_total, nrhs, false, stream_);
  }
  STRATA_CUDA(cudaStreamSynchronize(stream_));
}

}  // namespace strata::cuda
