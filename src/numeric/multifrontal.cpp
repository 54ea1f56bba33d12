// strata — the multifrontal driver (Duff & Reid 1983; Liu 1992), level by level.
//
// The fronts are processed in the order of the memory plan: batches of one level of
// the paper's reverse-BFS level schedule (Jung & Bae 2018), deepest level first. All
// fronts of a batch are independent, so an executor may run them concurrently (host
// threads, or one batched GPU launch). An executor may instead take the whole tree in an
// order of its own (Executor::factor_tree: the CPU executor's depth-first traversal). The driver
// owns nothing backend-specific: it sizes the factor storage once (reused by refactorization),
// hands batches to the executor, and merges the per-front pivot statistics in front order so that
// the result does not depend on the thread count. With one executor the whole tree is one part; the
// multi-worker driver (multi_device.cpp) runs the parts of a TreePartition on several.
#include <algorithm>
#include <string>

#include "base/alloc.hpp"
#include "numeric/factor.hpp"

namespace strata::numeric {

PartView PartView::whole(const Analysis& an) {
  PartView v;
  v.id = -1;
  v.schedule = &an.schedule;
  v.batches = &an.plan.batches;
  v.cb_layout = &an.cb_layout;
  return v;
}

PartView PartView::of(const schedule::FactorPart& p, int id) {
  PartView v;
  v.id = id;
  v.schedule = &p.schedule;
  v.batches = &p.plan.batches;
  v.cb_layout = &p.cb_layout;
  return v;
}

void prepare_factor(const Analysis& an, MatrixType type, NumericFactor& factor, bool host_panels) {
  const auto& t = an.tree;
  factor.type = type;
  factor.valid = false;
  // Storage is sized once; refactorization reuses it (resize is a no-op then).
  factor.held.clear();
  if (host_panels) sized_resize(factor.panels, an.factor_layout.total, "factorize: factor panels");
  sized_resize(factor.rows, t.rows.size(), "factorize: factor row indices");
  factor.front_stats.assign(t.n_fronts(), PivotStats{});
  if (type == MatrixType::general) factor.static_pivot_at.resize(an.n);
  if (type == MatrixType::symmetric_indefinite) {
    factor.d_diag.resize(an.n);
    factor.d_off.resize(an.n);
    factor.pivot_size.resize(an.n);
  }
}

void factorize(const Analysis& an, const std::vector<double>& scaled_values, MatrixType type,
               const PivotPolicy& pivots, Executor& exec, NumericFactor& factor,
               std::vector<double>& cb_arena, bool values_on_device) {
  prepare_factor(an, type, factor, false);

  const PartView whole = PartView::whole(an);
  FactorContext ctx;
  ctx.analysis = &an;
  ctx.values = values_on_device ? nullptr : scaled_values.data();
  ctx.values_on_device = values_on_device;
  ctx.type = type;
  ctx.static_pivot = pivots.static_pivot;
  ctx.diagonal_pivot_threshold = pivots.threshold;
  ctx.factor = &factor;
  ctx.cb_arena = &cb_arena;
  exec.begin(ctx);
  ctx.part = &whole;
  exec.begin_part(ctx);
  // The panels go to the host unless the executor keeps them (a resident GPU factor):
  // then the host holds no copy at all — for a large factor that copy cost more than the
  // factorization (pinned staging, a host memcpy, and sizing the vector the first time).
  if (exec.keeps_panels(ctx)) {
    std::vector<double>().swap(factor.panels);
    factor.held.push_back(HeldPanels{whole.id, 0});
  } else {
    sized_resize(factor.panels, an.factor_layout.total, "factorize: factor panels");
  }
  if (!exec.factor_tree(ctx)) {
    if (exec.uses_host_arena() && cb_arena.size() < an.cb_layout.arena_size)
      sized_resize(cb_arena, an.cb_layout.arena_size, "factorize: contribution-block arena");
    for (const BatchInfo& b : an.plan.batches) exec.factor_batch(ctx, b);
  }
  exec.end_part(ctx);
  ctx.part = nullptr;
  exec.end(ctx);
  factor.valid = true;
}

void merge_device_figures(FactorStats& into, const FactorStats& one) {
  into.device_seconds = std::max(into.device_seconds, one.device_seconds);
  into.bytes_to_device += one.bytes_to_device;
  into.bytes_to_host += one.bytes_to_host;
  into.device_batches += one.device_batches;
  into.device_fused_batches += one.device_fused_batches;
  into.tiled_fronts += one.tiled_fronts;
  into.tiled_fronts_prefetched += one.tiled_fronts_prefetched;
  into.lu_large_fronts += one.lu_large_fronts;
  into.lu_large_fronts_pivoted += one.lu_large_fronts_pivoted;
  into.lu_large_fronts_batched += one.lu_large_fronts_batched;
  into.device_budget = std::max(into.device_budget, one.device_budget);
  into.device_pool_bytes = std::max(into.device_pool_bytes, one.device_pool_bytes);
  into.device_working_bytes = std::max(into.device_working_bytes, one.device_working_bytes);
  into.host_pinned_bytes += one.host_pinned_bytes;
  into.contribution_blocks_on_host |= one.contribution_blocks_on_host;
  auto& d = into.device_phases;
  const auto& o = one.device_phases;
  d.assembly += o.assembly;
  d.small_fronts += o.small_fronts;
  d.large_fronts += o.large_fronts;
  d.store += o.store;
  d.tiled_fronts += o.tiled_fronts;
  d.tiled_assembly += o.tiled_assembly;
  d.tiled_slabs += o.tiled_slabs;
  d.tiled_pivot_columns += o.tiled_pivot_columns;
  d.tiled_cb_update += o.tiled_cb_update;
  d.tiled_store += o.tiled_store;
  d.host += o.host;
  d.setup += o.setup;
}

void fetch_panels(const Analysis& an, const std::vector<Executor*>& execs, NumericFactor& fac) {
  if (fac.held.empty()) return;
  // unsized when the panels of every part stayed with the executors
  sized_resize(fac.panels, an.factor_layout.total, "fetch_panels: factor panels");
  for (const HeldPanels& h : fac.held) {
    if (h.worker < 0 || h.worker >= static_cast<int>(execs.size()))
      throw InternalError("fetch_panels: part " + std::to_string(h.part) + " is held by worker " +
                          std::to_string(h.worker) + " of " + std::to_string(execs.size()));
    execs[h.worker]->download_panels(an, h.part, fac);
  }
  fac.held.clear();
}

void fetch_panels(const Analysis& an, Executor& exec, NumericFactor& fac) {
  fetch_panels(an, std::vector<Executor*>{&exec}, fac);
}

void store_ldlt_front(const Analysis& an, index_t f, const index_t* local_perm,
                      const int* local_pivot_size, NumericFactor& fac) {
  const auto& t = an.tree;
  const index_t m = t.n_rows(f), k = t.n_pivots(f), p0 = t.first_pivot[f];
  const index_t* rows = t.rows_of(f);
  index_t* frows = fac.rows.data() + t.row_offsets[f];
  for (index_t i = 0; i < k; ++i) frows[i] = rows[local_perm[i]];
  for (index_t i = k; i < m; ++i) frows[i] = rows[i];
  double* panel = fac.panels.data() + an.factor_layout.panel_offset[f];
  for (index_t i = 0; i < k; ++i) {
    fac.d_diag[p0 + i] = panel[i * m + i];
    panel[i * m + i] = 1.0;
    // local sizes are 2, 2 on both columns of a 2×2 pivot: the first becomes 2, the second 0
    fac.pivot_size[p0 + i] = local_pivot_size[i] == 2 && (i == 0 || fac.pivot_size[p0 + i - 1] != 2)
                                 ? 2
                                 : (local_pivot_size[i] == 2 ? 0 : 1);
    fac.d_off[p0 + i] = 0.0;
    if (fac.pivot_size[p0 + i] == 2) {
      fac.d_off[p0 + i] = panel[i * m + i + 1];
      panel[i * m + i + 1] = 0.0;
    }
  }
}

}  // namespace strata::numeric
