// strata — the statistics as JSON, in one place: the document `strata solve --json`
// prints, that Python's Solver.stats returns (as a dict), that the C API's
// strata_get_stats_json writes, and the figures the benchmark drivers record, so that all
// of them use one vocabulary field for field. Header only (nlohmann-json); nlohmann-json
// finds these by argument-dependent lookup: `json j = stats.factor;`.
//
// stats_document(st, factorized, solved): the analysis' fields at the top level, then
// "factor" (after a factorization) and "solve" (after a solve). Times are seconds, sizes
// bytes; the inertia and determinant are null when static pivoting perturbed pivots (they
// would describe the nearby matrix that was factored, not A).
#pragma once

#include <nlohmann/json.hpp>

#include "strata/distributed.hpp"
#include "strata/options.hpp"
#include "strata/stats.hpp"

namespace strata {

/// GPU seconds per phase of a factorization (FactorStats::device_phases).
inline void to_json(nlohmann::json& j, const FactorStats::DevicePhases& d) {
  j = {{"assembly", d.assembly},
       {"small_fronts", d.small_fronts},
       {"large_fronts", d.large_fronts},
       {"store", d.store},
       {"tiled_fronts", d.tiled_fronts},
       {"host", d.host},
       {"setup", d.setup},
       {"tiled_assembly", d.tiled_assembly},
       {"tiled_slabs", d.tiled_slabs},
       {"tiled_pivot_columns", d.tiled_pivot_columns},
       {"tiled_cb_update", d.tiled_cb_update},
       {"tiled_store", d.tiled_store}};
}

/// One part a worker ran (DeviceStats::parts).
inline void to_json(nlohmann::json& j, const PartRun& r) {
  const char* kind = r.kind == PartRun::Kind::subtree ? "subtree"
                     : r.kind == PartRun::Kind::upper ? "upper"
                                                      : "top";
  j = {{"kind", kind},
       {"index", r.index},
       {"stolen", r.stolen},
       {"start_seconds", r.start_seconds},
       {"end_seconds", r.end_seconds},
       {"flops", r.flops}};
}

/// One worker (GPU) of a multi-worker factorization (FactorStats::devices).
inline void to_json(nlohmann::json& j, const DeviceStats& d) {
  j = {{"worker", d.worker},
       {"device", d.device},
       {"busy_seconds", d.busy_seconds},
       {"idle_seconds", d.idle_seconds},
       {"subtrees_run", d.subtrees_run},
       {"subtrees_stolen", d.subtrees_stolen},
       {"upper_parts_run", d.upper_parts_run},
       {"bytes_transferred", d.bytes_transferred},
       {"flops", d.flops},
       {"fronts_split", d.fronts_split},
       {"fronts_distributed", d.fronts_distributed},
       {"strips_helped", d.strips_helped},
       {"parts", d.parts}};
}

/// One MPI rank of a distributed run (DistributedStats::per_rank).
inline void to_json(nlohmann::json& j, const RankStats& r) {
  j = {{"rank", r.rank},
       {"workers", r.workers},
       {"subtrees", r.subtrees},
       {"factor_flops", r.factor_flops},
       {"factor_seconds", r.factor_seconds},
       {"values_seconds", r.values_seconds},
       {"exchange_seconds", r.exchange_seconds},
       {"blocks_seconds", r.blocks_seconds},
       {"factor_bytes_sent", r.factor_bytes_sent},
       {"factor_bytes_received", r.factor_bytes_received},
       {"values_bytes", r.values_bytes},
       {"factor_bytes_held", r.factor_bytes_held},
       {"solve_seconds", r.solve_seconds},
       {"solve_bytes_sent", r.solve_bytes_sent},
       {"solve_bytes_received", r.solve_bytes_received}};
}

/// The analysis (Stats::analysis): sizes, the tree, the memory plan, times.
inline void to_json(nlohmann::json& j, const AnalysisStats& s) {
  nlohmann::json batches = nlohmann::json::array();
  for (const auto& b : s.batches)
    batches.push_back(
        {{"level", b.level}, {"fronts", b.end - b.begin}, {"bytes", b.bytes}, {"tiled", b.tiled}});
  j = {{"n", s.n},
       {"nnz_a", s.nnz_a},
       {"nnz_l", s.nnz_l},
       {"nnz_l_fronts", s.nnz_l_fronts},
       {"factor_flops", s.factor_flops},
       {"fronts", s.n_fronts},
       {"largest_front_rows", s.largest_front_rows},
       {"largest_front_pivots", s.largest_front_pivots},
       {"max_block_size", s.max_block_size},
       {"tree_height", s.tree_height},
       {"fronts_per_level", s.fronts_per_level},
       {"peak_working_bytes", s.peak_working_bytes},
       {"factor_bytes", s.factor_bytes},
       {"cpu_factorization_bytes", s.cpu_factorization_bytes},
       {"analysis_bytes", s.analysis_bytes},
       {"memory_budget", s.memory_budget},
       {"batches", batches},
       {"type", to_string(s.type)},
       {"backend", to_string(s.backend)},
       {"pairs", s.pairs},
       {"odd_cycles", s.odd_cycles},
       {"ordering", to_string(s.ordering)},
       {"order_kept", s.order_kept},
       {"matching_kept", s.matching_kept},
       {"order_from_pivots", s.order_from_pivots},
       {"workers", s.workers},
       {"subtrees", s.subtrees},
       {"subtree_balance", s.subtree_balance},
       {"top_flops_fraction", s.top_flops_fraction},
       {"upper_layers", s.upper_layers},
       {"upper_parts", s.upper_parts},
       {"upper_flops_fraction", s.upper_flops_fraction},
       {"estimated_speedup", s.estimated_speedup},
       {"nd_rebisections", s.nd_rebisections},
       {"device_setup_error", s.device_setup_error},
       {"seconds",
        {{"ordering", s.ordering_seconds},
         {"matching", s.matching_seconds},
         {"nd_balance", s.nd_balance_seconds},
         {"symbolic", s.symbolic_seconds},
         {"plan", s.plan_seconds},
         {"device_setup", s.device_setup_seconds},
         {"total", s.total_seconds}}}};
}

/// The last factorization (Stats::factor): type, backend, pivots, inertia and
/// determinant (null when pivots were perturbed), rates, the GPU figures, the workers.
inline void to_json(nlohmann::json& j, const FactorStats& f) {
  j = {{"type", to_string(f.type)},
       {"backend", to_string(f.backend)},
       {"seconds", f.seconds},
       {"input_seconds", f.input_seconds},
       {"values_scaled_on_device", f.values_scaled_on_device},
       {"gflops", f.gflops},
       {"perturbed_pivots", f.perturbed_pivots},
       {"delayed_pivoting", f.delayed_pivoting},
       {"delayed_pivots", f.delayed_pivots},
       {"fronts_delaying", f.fronts_delaying},
       {"fixed_order_perturbed_pivots", f.fixed_order_perturbed_pivots},
       {"corrected_pivots", f.corrected_pivots},
       {"correction_backward_error", f.correction_backward_error},
       {"rescaling_sweeps", f.rescaling_sweeps},
       {"two_by_two_pivots", f.two_by_two_pivots},
       {"inertia_valid", f.inertia_valid},
       {"matrix_norm", f.matrix_norm},
       {"device_seconds", f.device_seconds},
       {"bytes_to_device", f.bytes_to_device},
       {"bytes_to_host", f.bytes_to_host},
       {"device_batches", f.device_batches},
       {"device_fused_batches", f.device_fused_batches},
       {"tiled_fronts", f.tiled_fronts},
       {"tiled_fronts_prefetched", f.tiled_fronts_prefetched},
       {"lu_large_fronts", f.lu_large_fronts},
       {"lu_large_fronts_pivoted", f.lu_large_fronts_pivoted},
       {"lu_large_fronts_batched", f.lu_large_fronts_batched},
       {"device_budget", f.device_budget},
       {"device_pool_bytes", f.device_pool_bytes},
       {"device_working_bytes", f.device_working_bytes},
       {"host_pinned_bytes", f.host_pinned_bytes},
       {"contribution_blocks_on_host", f.contribution_blocks_on_host},
       {"factor_resident", f.factor_resident},
       {"device_phases", f.device_phases},
       {"devices", f.devices}};
  j["inertia"] = f.inertia_valid
                     ? nlohmann::json{f.inertia_positive, f.inertia_negative, f.inertia_zero}
                     : nlohmann::json();
  j["log_abs_determinant"] =
      f.inertia_valid ? nlohmann::json(f.log_abs_determinant) : nlohmann::json();
  j["determinant_sign"] = f.inertia_valid ? nlohmann::json(f.determinant_sign) : nlohmann::json();
}

/// The last solve (Stats::solve): times, refinement, backward error and its floor.
inline void to_json(nlohmann::json& j, const SolveStats& s) {
  j = {{"seconds", s.seconds},
       {"first_solve_seconds", s.first_solve_seconds},
       {"refinement_steps", s.refinement_steps},
       {"gmres_iterations", s.gmres_iterations},
       {"backward_error", s.backward_error},
       {"backward_error_floor", s.backward_error_floor},
       {"condition_lower_bound", s.condition_lower_bound},
       {"converged", s.refinement_converged},
       {"relative_residual", s.relative_residual},
       {"singular_consistent", s.singular_consistent},
       {"on_device", s.on_device},
       {"host_threads", s.host_threads}};
}

/// A DistributedSolver's ranks (DistributedStats).
inline void to_json(nlohmann::json& j, const DistributedStats& d) {
  j = {{"ranks", d.ranks},
       {"workers_per_rank", d.workers_per_rank},
       {"analysis_bytes", d.analysis_bytes},
       {"analysis_broadcast_seconds", d.analysis_broadcast_seconds},
       {"per_rank", d.per_rank}};
}

/// The statistics document (see the file header): `factor` and `solve` only when the
/// solver has factorized (solved) since its analysis.
inline nlohmann::json stats_document(const Stats& st, bool factorized, bool solved) {
  nlohmann::json j = st.analysis;
  if (factorized) j["factor"] = st.factor;
  if (solved) j["solve"] = st.solve;
  return j;
}

}  // namespace strata
