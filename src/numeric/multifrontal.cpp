// strata — the multifrontal driver (Duff & Reid 1983; Liu 1992), level by level.
//
// The fronts are processed in the order of the memory plan: batches of one level of
// the paper's reverse-BFS level schedule (Jung & Bae 2018), deepest level first. All
// fronts of a batch are independent, so an executor may run them concurrently (host
// threads, or one batched GPU launch). The driver owns nothing backend-specific: it sizes
// the factor storage once (reused by refactorization), hands batches to the executor,
// and merges the per-front pivot statistics in front order so that the result does not
// depend on the thread count. With one executor the whole tree is one part; the
// multi-worker driver (multi_device.cpp) runs the parts of a TreePartition on several.
#include <algorithm>

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

void prepare_factor(const Analysis& an, MatrixType type, NumericFactor& factor) {
  const auto& t = an.tree;
  factor.type = type;
  factor.valid = false;
  // Storage is sized once; refactorization reuses it (resize is a no-op then).
  factor.panels.resize(an.factor_layout.total);
  factor.rows.resize(t.rows.size());
  factor.front_stats.assign(t.n_fronts(), cpu::PivotStats{});
  if (type == MatrixType::symmetric_indefinite) {
    factor.d_diag.resize(an.n);
    factor.d_off.resize(an.n);
    factor.pivot_size.resize(an.n);
  }
}

void factorize(const Analysis& an, const std::vector<double>& scaled_values, MatrixType type,
               double static_pivot, Executor& exec, NumericFactor& factor,
               std::vector<double>& cb_arena) {
  prepare_factor(an, type, factor);
  cb_arena.resize(an.cb_layout.arena_size);

  const PartView whole = PartView::whole(an);
  FactorContext ctx;
  ctx.analysis = &an;
  ctx.values = scaled_values.data();
  ctx.type = type;
  ctx.static_pivot = static_pivot;
  ctx.factor = &factor;
  ctx.cb_arena = &cb_arena;
  exec.begin(ctx);
  ctx.part = &whole;
  exec.begin_part(ctx);
  for (const BatchInfo& b : an.plan.batches) exec.factor_batch(ctx, b);
  exec.end_part(ctx);
  ctx.part = nullptr;
  exec.end(ctx);
  factor.valid = true;
}

}  // namespace strata::numeric
