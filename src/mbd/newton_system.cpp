// strata::mbd — residual and Jacobian assembly of the BDF Newton system (see the header).
#include "mbd/newton_system.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <stdexcept>

#include "base/roundoff.hpp"
#include "base/serial_scope.hpp"
#include "strata/errors.hpp"

namespace strata::mbd {

NewtonSystem::NewtonSystem(const Model& model)
    : model_(model),
      n_(model.n),
      candidate_(model.forces.size(), 1),
      in_pattern_(model.forces.size(), 1) {
  index_t rows = 0;
  for (const auto& c : model.constraints) {
    row0_.push_back(rows);
    rows += c->rows;
  }
  active_.assign(rows, 1);
  m_ = rows;
  model_row_.resize(rows);
  active_index_.resize(rows);
  for (index_t k = 0; k < rows; ++k) model_row_[k] = active_index_[k] = k;
  node_first_.assign(n_, -1);
  for (const Body& b : model.bodies)
    if (b.kind == BodyKind::node && b.offset >= 0)
      for (int c = 0; c < b.n_coords; ++c) node_first_[b.offset + c] = b.offset;
}

// Mass scale of each constraint's coordinates (the regularisation of the stabilized
// formulation is relative to Φ_q M⁻¹ Φ_qᵀ): mean positive diagonal of ∂g/∂a at q0.
// Computed at the first stabilized evaluation, with the assembly's threads.
void NewtonSystem::compute_mass_scale() {
  std::vector<double> diag(n_, 0.0);
  std::vector<index_t> ri, ci;
  std::vector<double> vals;
  const std::vector<double> zero(n_, 0.0);
  mass_triplets(model_.q0.data(), zero.data(), 0.0, ri, ci, vals);
  for (std::size_t k = 0; k < ri.size(); ++k)
    if (ri[k] == ci[k]) diag[ri[k]] += vals[k];
  mass_scale_.clear();
  for (const auto& c : model_.constraints) {
    double s = 0;
    int count = 0;
    for (index_t i : c->dofs)
      if (diag[i] > 0) s += diag[i], ++count;
    mass_scale_.push_back(count ? s / count : 1.0);
  }
}

std::string NewtonSystem::model_row_name(index_t k) const {
  const auto it = std::upper_bound(row0_.begin(), row0_.end(), k) - 1;
  const std::size_t e = it - row0_.begin();
  const auto& c = model_.constraints[e];
  if (c->rows == 1) return c->name;
  return c->name + " equation " + std::to_string(k - *it);
}

void NewtonSystem::set_threads(int threads) {
  threads_ = threads > 0 ? threads : 1;
  arena_ = threads_ > 1 ? std::make_unique<tbb::task_arena>(threads_) : nullptr;
}

template <class F>
void NewtonSystem::for_element_ranges(std::size_t n, F&& f) const {
  if (!arena_) {
    f(std::size_t{0}, n);
    return;
  }
  // ranges of at most 64 elements, and at least four per thread: one element (a joint's
  // derivatives, a contact) costs microseconds, and a model has a few hundred joints, so
  // ranges of 64 would leave them to a few threads
  const std::size_t grain =
      std::clamp<std::size_t>(n / (4 * static_cast<std::size_t>(threads_)), 1, 64);
  arena_->execute([&] {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, grain),
                      [&](const tbb::blocked_range<std::size_t>& r) { f(r.begin(), r.end()); });
  });
}

template <class F>
void NewtonSystem::in_arena(F&& f) const {
  if (arena_) {
    arena_->execute(f);
  } else {
    detail::SerialScope serial(true);
    f();
  }
}

void NewtonSystem::set_formulation(Formulation f) {
  formulation_ = f;
  rebuild_pattern();
}

void NewtonSystem::set_active_rows(const std::vector<char>& active) {
  if (active.size() != active_.size())
    throw std::logic_error("NewtonSystem::set_active_rows: wrong size");
  active_ = active;
  model_row_.clear();
  for (index_t k = 0; k < model_m(); ++k) {
    active_index_[k] = active_[k] ? static_cast<index_t>(model_row_.size()) : -1;
    if (active_[k]) model_row_.push_back(k);
  }
  m_ = static_cast<index_t>(model_row_.size());
  independent_.clear();
  jac_ = SparseMatrix{};
  ++pattern_id_;
  pattern_current_ = false;
}

void NewtonSystem::gather(const std::vector<index_t>& dofs, const double* src,
                          std::vector<double>& dst) const {
  dst.resize(dofs.size());
  for (std::size_t i = 0; i < dofs.size(); ++i) dst[i] = src[dofs[i]];
}

bool NewtonSystem::set_partition(const Partition& p) {
  if (pattern_current_ && p.independent == independent_) return false;
  independent_ = p.independent;
  rebuild_pattern();
  return true;
}

namespace {
// A saved per-force set (checkpoint) must have one entry per force element of the model.
void expect_force_set(const std::vector<char>& set, std::size_t forces, const char* what) {
  if (set.size() != forces)
    throw InvalidInput(std::string("the saved ") + what + " has " + std::to_string(set.size()) +
                       " entries, the model " + std::to_string(forces) + " force elements");
}
}  // namespace

void NewtonSystem::set_candidates(const std::vector<char>& c) {
  expect_force_set(c, candidate_.size(), "contact candidate set");
  candidate_ = c;
  for (std::size_t e = 0; e < c.size(); ++e) {
    pattern_current_ &= in_pattern_[e] || !c[e];
    in_pattern_[e] |= c[e];
  }
}

void NewtonSystem::set_pattern_forces(const std::vector<char>& p) {
  expect_force_set(p, in_pattern_.size(), "pattern's force set");
  pattern_current_ &= in_pattern_ == p;
  in_pattern_ = p;
}

int NewtonSystem::update_candidates(const double* q) {
  bool changed = false, grew = false;
  std::vector<double> lq;
  for (std::size_t e = 0; e < model_.forces.size(); ++e) {
    const Force& f = *model_.forces[e];
    if (f.margin <= 0) continue;
    gather(f.dofs, q, lq);
    const char c = f.proximity(lq.data()) < f.margin;
    changed |= c != candidate_[e];
    grew |= c && !in_pattern_[e];
    candidate_[e] = c;
    in_pattern_[e] |= c;
  }
  if (grew && jac_.n_rows > 0) rebuild_pattern();
  return grew ? 2 : changed ? 1 : 0;
}

bool NewtonSystem::prune_pattern() {
  if (in_pattern_ == candidate_) return false;
  in_pattern_ = candidate_;
  if (jac_.n_rows > 0) rebuild_pattern();
  return true;
}

int NewtonSystem::check_candidates(const double* q) const {
  // the largest status over the elements, on the assembly's threads (the same for any
  // number of them)
  std::atomic<int> status{0};
  for_element_ranges(model_.forces.size(), [&](std::size_t begin, std::size_t end) {
    std::vector<double> lq;
    int local = 0;
    for (std::size_t e = begin; e < end && local < 2; ++e) {
      const Force& f = *model_.forces[e];
      if (f.margin <= 0 || candidate_[e]) continue;
      gather(f.dofs, q, lq);
      const double p = f.proximity(lq.data());
      local = std::max(local, p < 0 ? 2 : p < 0.5 * f.margin ? 1 : 0);
    }
    for (int s = status.load(); s < local && !status.compare_exchange_weak(s, local);) {
    }
  });
  return status.load();
}

index_t NewtonSystem::active_forces() const {
  index_t k = 0;
  for (char c : candidate_) k += c;
  return k;
}

void NewtonSystem::rebuild_pattern() {
  const index_t n = n_, m = m_, N = size();
  const bool stab = formulation_ == Formulation::stabilized;
  const index_t A = 0, V = n, Q = 2 * n, L = 3 * n, NU = 3 * n + m;  // column blocks
  // row blocks; the stabilized formulation has no acceleration constraints
  const index_t RA = n, RV = stab ? n : n + m, RP = RV + m, RU = RP + m;
  // BDF rows: the independent coordinates (partitioned) or all (stabilized)
  std::vector<index_t> bdf_coords = independent_;
  if (stab) {
    bdf_coords.resize(n);
    for (index_t i = 0; i < n; ++i) bdf_coords[i] = i;
  }
  const index_t nb = static_cast<index_t>(bdf_coords.size());
  // The pairs of each element (forces, then constraints, then the BDF rows of each
  // coordinate k < nb) in a fixed order: put(r, c, pos) for a pair whose position goes to
  // the element's list `pos` (null for the BDF rows, whose positions go to upos_[4k …]).
  auto force_pairs = [&](std::size_t e, auto&& put) {
    if (!in_pattern_[e]) return;
    const Force& f = *model_.forces[e];
    ForcePos& fp = fpos_[e];
    for (index_t i : f.dofs)
      for (index_t j : f.dofs) {
        put(i, Q + j, &fp.q);
        if (f.uses_v) put(i, V + j, &fp.v);
        if (f.uses_a) put(i, A + j, &fp.a);
      }
  };
  auto constraint_pairs = [&](std::size_t e, auto&& put) {
    const Constraint& c = *model_.constraints[e];
    ConstraintPos& cp = cpos_[e];
    const index_t r0 = row0_[e];
    for (index_t i : c.dofs)
      for (index_t j : c.dofs) {
        put(i, Q + j, &cp.hq);
        if (stab) put(RU + n + i, Q + j, &cp.nuq);
      }
    for (index_t i : c.dofs)
      for (int r = 0; r < c.rows; ++r) {
        const index_t k = active_index_[r0 + r];
        if (k < 0) continue;
        put(i, L + k, &cp.fl);
        if (stab) put(RU + n + i, NU + k, &cp.nu);
      }
    for (int r = 0; r < c.rows; ++r) {
      const index_t k = active_index_[r0 + r];
      if (k < 0) continue;
      for (index_t j : c.dofs) {
        if (!stab) {
          put(RA + k, A + j, &cp.aa);
          put(RA + k, V + j, &cp.av);
          put(RA + k, Q + j, &cp.aq);
        }
        put(RV + k, V + j, &cp.vv);
        put(RV + k, Q + j, &cp.vq);
        put(RP + k, Q + j, &cp.pq);
      }
      if (stab) {
        put(RV + k, L + k, &cp.reg);
        put(RP + k, NU + k, &cp.reg);
      }
    }
  };
  // A flexible-body node's BDF rows also hold its other two coordinates' columns, as
  // explicit zeros that nothing writes: a node's three coordinates then have rows of the
  // same pattern in every block, which the nested dissection's compression merges into one
  // vertex of its graph (their BDF rows alone differed), for a third of the BDF vertices
  // and the same fill. Rigid bodies' rows are left as they are (their coordinates couple
  // differently; the blocks added fill there).
  std::vector<index_t> structural_zero;  // the position list of those pairs: none is kept
  auto bdf_pairs = [&](index_t k, auto&& put) {
    const index_t j = bdf_coords[k];
    std::vector<index_t>* none = nullptr;
    put(RU + k, A + j, none);
    put(RU + k, V + j, none);
    put(RU + nb + k, V + j, none);
    put(RU + nb + k, Q + j, none);
    if (const index_t first = node_first_[j]; first >= 0)
      for (index_t o = first; o < n && node_first_[o] == first; ++o)
        if (o != j) {
          put(RU + k, A + o, &structural_zero);
          put(RU + k, V + o, &structural_zero);
          put(RU + nb + k, V + o, &structural_zero);
          put(RU + nb + k, Q + o, &structural_zero);
        }
  };
  const std::size_t nf = model_.forces.size(), nc = model_.constraints.size();
  const std::size_t elements = nf + nc + static_cast<std::size_t>(nb);
  auto pairs = [&](std::size_t e, auto&& put) {
    if (e < nf)
      force_pairs(e, put);
    else if (e < nf + nc)
      constraint_pairs(e - nf, put);
    else
      bdf_pairs(static_cast<index_t>(e - nf - nc), put);
  };
  fpos_.assign(nf, {});
  cpos_.assign(nc, {});
  upos_.assign(4 * static_cast<std::size_t>(nb), 0);
  // every element's pairs counted, then written to their own range of the builder's
  // pairs; the pattern sorted; each element's positions looked up (all on the assembly's
  // threads, the same result on any number of them)
  std::vector<std::size_t> first(elements + 1, 0);
  for_element_ranges(elements, [&](std::size_t begin, std::size_t end) {
    for (std::size_t e = begin; e < end; ++e) {
      std::size_t count = 0;
      if (e < nf) {  // a force's blocks are whole (see force_pairs)
        const Force& f = *model_.forces[e];
        count = in_pattern_[e] ? f.dofs.size() * f.dofs.size() * (1 + f.uses_v + f.uses_a) : 0;
      } else {
        pairs(e, [&](index_t, index_t, std::vector<index_t>*) { ++count; });
      }
      first[e + 1] = count;
    }
  });
  for (std::size_t e = 0; e < elements; ++e) first[e + 1] += first[e];
  PatternBuilder pb(N, N);
  pb.grow(first[elements]);
  for_element_ranges(elements, [&](std::size_t begin, std::size_t end) {
    for (std::size_t e = begin; e < end; ++e) {
      std::size_t at = first[e];
      pairs(e, [&](index_t r, index_t c, std::vector<index_t>*) { pb.set(at++, r, c); });
    }
  });
  in_arena([&] { jac_ = pb.finish(); });
  ++pattern_id_;
  for_element_ranges(elements, [&](std::size_t begin, std::size_t end) {
    for (std::size_t e = begin; e < end; ++e) {
      if (e < nf && in_pattern_[e]) {  // a force's lists are whole blocks: sized at once
        const std::size_t nz = model_.forces[e]->dofs.size();
        fpos_[e].q.reserve(nz * nz);
        if (model_.forces[e]->uses_v) fpos_[e].v.reserve(nz * nz);
        if (model_.forces[e]->uses_a) fpos_[e].a.reserve(nz * nz);
      }
      std::size_t at = 4 * (e - std::min(e, nf + nc));  // a BDF row's first position
      pairs(e, [&](index_t r, index_t c, std::vector<index_t>* pos) {
        if (pos == &structural_zero) return;
        if (pos)
          pos->push_back(entry_position(jac_, r, c));
        else
          upos_[at++] = entry_position(jac_, r, c);
      });
    }
  });
  build_slot_sums();
  pattern_current_ = true;
}

std::vector<RowElimination> NewtonSystem::bdf_eliminations() const {
  const index_t n = n_, m = m_;
  const bool stab = formulation_ == Formulation::stabilized;
  const index_t A = 0, V = n, Q = 2 * n;          // column blocks (rebuild_pattern)
  const index_t RU = (stab ? n : n + m) + 2 * m;  // the BDF rows' first row
  const index_t nb = stab ? n : static_cast<index_t>(independent_.size());
  auto coord = [&](index_t k) { return stab ? k : independent_[k]; };
  std::vector<RowElimination> out;
  out.reserve(stab ? nb : 2 * nb);
  if (!stab)
    for (index_t k = 0; k < nb; ++k) out.push_back({RU + nb + k, Q + coord(k), V + coord(k)});
  for (index_t k = 0; k < nb; ++k) out.push_back({RU + k, V + coord(k), A + coord(k)});
  return out;
}

void NewtonSystem::build_slot_sums() {
  const std::size_t nf = model_.forces.size(), nc = model_.constraints.size();
  const bool stab = formulation_ == Formulation::stabilized;
  // h's layout (evaluate): F (n), [Φ̈ (m)], Φ̇ (m), Φ (m), BDF rows; stabilized: the BDF
  // relation of q, which Φ_qᵀν enters, starts n after the BDF rows
  const index_t hu = stab ? n_ + 2 * m_ : n_ + 3 * m_;
  force_rslot_.assign(nf + 1, 0);
  force_jslot_.assign(nf + 1, 0);
  for (std::size_t e = 0; e < nf; ++e) {
    const ForcePos& fp = fpos_[e];
    force_rslot_[e + 1] = force_rslot_[e] + model_.forces[e]->dofs.size();
    force_jslot_[e + 1] = force_jslot_[e] + fp.q.size() + fp.v.size() + fp.a.size();
  }
  constraint_rslot_.assign(nc + 1, force_rslot_[nf]);
  constraint_jslot_.assign(nc + 1, force_jslot_[nf]);
  for (std::size_t e = 0; e < nc; ++e) {
    const ConstraintPos& cp = cpos_[e];
    constraint_rslot_[e + 1] =
        constraint_rslot_[e] + (stab ? 2 : 1) * model_.constraints[e]->dofs.size();
    constraint_jslot_[e + 1] = constraint_jslot_[e] + cp.hq.size() + cp.nuq.size();
  }
  // the slots zeroed, and every slot's target in slot order (each element's slots at its
  // own offset), in pieces on the assembly's threads; then the slots grouped by target
  // keeping that order
  auto zeroed = [&](FillLater<double>& v, std::size_t n) {
    v.resize(n);
    constexpr std::size_t kPiece = std::size_t{1} << 16;
    for_element_ranges((n + kPiece - 1) / kPiece, [&](std::size_t begin, std::size_t end) {
      std::fill(v.begin() + begin * kPiece, v.begin() + std::min(n, end * kPiece), 0.0);
    });
  };
  zeroed(rslots_, constraint_rslot_[nc]);
  zeroed(jslots_, constraint_jslot_[nc]);
  FillLater<index_t> target_of(rslots_.size());
  for_element_ranges(nf, [&](std::size_t begin, std::size_t end) {
    for (std::size_t e = begin; e < end; ++e) {
      const auto& dofs = model_.forces[e]->dofs;
      std::copy(dofs.begin(), dofs.end(), target_of.begin() + force_rslot_[e]);
    }
  });
  for_element_ranges(nc, [&](std::size_t begin, std::size_t end) {
    for (std::size_t e = begin; e < end; ++e) {
      const auto& dofs = model_.constraints[e]->dofs;
      auto at = std::copy(dofs.begin(), dofs.end(), target_of.begin() + constraint_rslot_[e]);
      if (stab)
        for (index_t d : dofs) *at++ = hu + n_ + d;
    }
  });
  in_arena([&] { rsums_ = group_by_target(target_of, size()); });
  target_of.resize(jslots_.size());
  for_element_ranges(nf, [&](std::size_t begin, std::size_t end) {
    for (std::size_t e = begin; e < end; ++e) {
      auto at = target_of.begin() + force_jslot_[e];
      for (const auto* pos : {&fpos_[e].q, &fpos_[e].v, &fpos_[e].a})
        at = std::copy(pos->begin(), pos->end(), at);
    }
  });
  for_element_ranges(nc, [&](std::size_t begin, std::size_t end) {
    for (std::size_t e = begin; e < end; ++e) {
      auto at = target_of.begin() + constraint_jslot_[e];
      for (const auto* pos : {&cpos_[e].hq, &cpos_[e].nuq})
        at = std::copy(pos->begin(), pos->end(), at);
    }
  });
  in_arena([&] { jsums_ = group_by_target(target_of, static_cast<index_t>(jac_.values.size())); });
}

void NewtonSystem::add_slot_sums(const SlotSums& sums, const double* slots, double* out) const {
  for_element_ranges(sums.target.size(), [&](std::size_t begin, std::size_t end) {
    for (std::size_t t = begin; t < end; ++t) {
      double s = 0;
      for (std::size_t k = sums.first[t]; k < sums.first[t + 1]; ++k) s += slots[sums.slot[k]];
      out[sums.target[t]] += s;
    }
  });
}

void NewtonSystem::evaluate(const double* x, double t, const BdfTerms& bdf, bool jacobian,
                            double* h, bool skip_intermittent) {
  const index_t n = n_, m = m_;
  const bool stab = formulation_ == Formulation::stabilized;
  const double *a = x, *v = x + n, *q = x + 2 * n, *lam = x + 3 * n;
  const double* nu = stab ? x + 3 * n + m : nullptr;
  if (!pattern_current_)
    throw std::logic_error("NewtonSystem::evaluate: the pattern is not built for this state");
  double* ha = stab ? nullptr : h + n;  // the stabilized formulation has no Φ̈ rows
  double* hv = stab ? h + n : h + n + m;
  double *hp = hv + m, *hu = hp + m;
  if (stab && mass_scale_.size() != model_.constraints.size()) compute_mass_scale();
  std::fill(h, h + size(), 0.0);
  double* J = jac_.values.data();
  if (jacobian) std::fill(jac_.values.begin(), jac_.values.end(), 0.0);
  const std::size_t nf = model_.forces.size(), nc = model_.constraints.size();
  double* rs = rslots_.data();  // contributions to shared entries (see the file comment)
  double* js = jslots_.data();
  auto forces = [&](std::size_t begin, std::size_t end) {
    std::vector<double> lq, lv, la;
    ForceEval fe;
    for (std::size_t e = begin; e < end; ++e) {
      const Force& f = *model_.forces[e];
      const std::size_t nz = f.dofs.size();
      double* r = rs + force_rslot_[e];
      double* j = js + force_jslot_[e];
      double* const j_end = js + force_jslot_[e + 1];
      if (!candidate_[e] || (skip_intermittent && f.intermittent)) {
        std::fill(r, r + nz, 0.0);
        if (jacobian) std::fill(j, j_end, 0.0);
        continue;
      }
      if (jacobian && static_cast<std::size_t>(j_end - j) != nz * nz * (1 + f.uses_v + f.uses_a))
        throw std::logic_error("NewtonSystem::evaluate: a force element outside the pattern");
      gather(f.dofs, q, lq);
      gather(f.dofs, v, lv);
      gather(f.dofs, a, la);
      f.evaluate(lq.data(), lv.data(), la.data(), t, jacobian, fe);
      std::copy_n(fe.g.begin(), nz, r);
      if (!jacobian) continue;
      j = std::copy_n(fe.dq.begin(), nz * nz, j);
      if (f.uses_v) j = std::copy_n(fe.dv.begin(), nz * nz, j);
      if (f.uses_a) std::copy_n(fe.da.begin(), nz * nz, j);
    }
  };
  auto constraints = [&](std::size_t begin, std::size_t end) {
    std::vector<double> lq, lv, la, llam, lnu, eps_p, eps_a;
    std::vector<index_t> act;
    ConstraintEval ce;
    for (std::size_t e = begin; e < end; ++e) {
      const Constraint& c = *model_.constraints[e];
      const index_t r0 = row0_[e];
      const int nr = c.rows;
      act.resize(nr);
      bool any = false;
      for (int r = 0; r < nr; ++r) any |= (act[r] = active_index_[r0 + r]) >= 0;
      const std::size_t nz = c.dofs.size();
      double* rslot = rs + constraint_rslot_[e];
      double* jslot = js + constraint_jslot_[e];
      if (!any) {
        std::fill(rslot, rs + constraint_rslot_[e + 1], 0.0);
        if (jacobian) std::fill(jslot, js + constraint_jslot_[e + 1], 0.0);
        continue;
      }
      gather(c.dofs, q, lq);
      gather(c.dofs, v, lv);
      gather(c.dofs, a, la);
      // Φ_q is needed for Φ_qᵀλ even in a residual-only evaluation
      if (jacobian)
        c.evaluate(lq.data(), lv.data(), la.data(), t, true, ce);
      else
        c.evaluate_gradient(lq.data(), lv.data(), la.data(), t, ce);
      llam.assign(nr, 0.0);
      lnu.assign(nr, 0.0);
      for (int r = 0; r < nr; ++r) {
        const index_t k = act[r];
        if (k < 0) continue;
        llam[r] = lam[k];
        if (stab) lnu[r] = nu[k];
        if (!stab) ha[k] = ce.phidd[r];
        hv[k] = ce.phid[r];
        hp[k] = ce.phi[r];
      }
      for (std::size_t i = 0; i < nz; ++i) {
        double s = 0, snu = 0;
        for (int r = 0; r < nr; ++r) {
          if (act[r] < 0) continue;
          s += ce.jq[r * nz + i] * lam[act[r]];
          if (stab) snu += ce.jq[r * nz + i] * nu[act[r]];
        }
        rslot[i] = s;
        if (stab) rslot[nz + i] = bdf.beta * snu;
      }
      // regularisation of the stabilized formulation (rows owned by this element)
      eps_p.assign(nr, 0.0);
      eps_a.assign(nr, 0.0);
      if (stab)
        for (int r = 0; r < nr; ++r) {
          const index_t k = act[r];
          if (k < 0) continue;
          double w = 0;
          for (std::size_t i = 0; i < nz; ++i) w += ce.jq[r * nz + i] * ce.jq[r * nz + i];
          eps_p[r] = bdf.regularization * bdf.beta * w;
          eps_a[r] = bdf.regularization * bdf.beta * w / mass_scale_[e];
          const double lam_prev = bdf.lambda_prev ? bdf.lambda_prev[k] : 0.0;
          hv[k] -= eps_a[r] * (lam[k] - lam_prev);
          hp[k] -= eps_p[r] * nu[k];
        }
      if (!jacobian) continue;
      c.hessian(lq.data(), t, llam.data(), jslot);
      if (stab) {  // β(Φ_qᵀν)_q: ν is small except near singular configurations
        double* nuq = jslot + nz * nz;
        c.hessian(lq.data(), t, lnu.data(), nuq);
        for (std::size_t k = 0; k < nz * nz; ++k) nuq[k] *= bdf.beta;
      }
      write_constraint_jacobian(cpos_[e], nz, act, ce, eps_a, eps_p, bdf.beta, J);
    }
  };
  // Elements are evaluated in parallel (oneTBB, as strata's CPU executor) into their
  // slots, then each shared entry sums its slots in element order (the file comment).
  for_element_ranges(nf, forces);
  for_element_ranges(nc, constraints);
  add_slot_sums(rsums_, rs, h);
  if (jacobian) add_slot_sums(jsums_, js, J);
  add_bdf_rows(a, v, q, bdf, jacobian, hu);
}

// A constraint element's own rows and multiplier columns of the Jacobian (no other element
// writes there): Φ_qᵀ in the equations of motion's λ columns (and β Φ_qᵀ in the ν columns,
// stabilized), the rows of Φ̈ (partitioned), Φ̇ and Φ with respect to a, v and q, and the
// stabilized formulation's regularisation on the diagonal.
void NewtonSystem::write_constraint_jacobian(const ConstraintPos& cp, std::size_t nz,
                                             const std::vector<index_t>& act,
                                             const ConstraintEval& ce,
                                             const std::vector<double>& eps_a,
                                             const std::vector<double>& eps_p, double beta,
                                             double* J) const {
  const bool stab = formulation_ == Formulation::stabilized;
  const int nr = static_cast<int>(act.size());
  std::size_t p = 0;
  for (std::size_t i = 0; i < nz; ++i)
    for (int r = 0; r < nr; ++r) {
      if (act[r] < 0) continue;
      J[cp.fl[p]] += ce.jq[r * nz + i];
      if (stab) J[cp.nu[p]] += beta * ce.jq[r * nz + i];
      ++p;
    }
  p = 0;
  std::size_t preg = 0;
  for (int r = 0; r < nr; ++r) {
    if (act[r] < 0) continue;
    for (std::size_t i = 0; i < nz; ++i, ++p) {
      const std::size_t k = r * nz + i;
      if (!stab) {
        J[cp.aa[p]] += ce.jq[k];
        J[cp.av[p]] += 2 * ce.jvq[k];
        J[cp.aq[p]] += ce.jaq[k];
      }
      J[cp.vv[p]] += ce.jq[k];
      J[cp.vq[p]] += ce.jvq[k];
      J[cp.pq[p]] += ce.jq[k];
    }
    if (stab) {
      J[cp.reg[preg++]] -= eps_a[r];
      J[cp.reg[preg++]] -= eps_p[r];
    }
  }
}

namespace {
// x − y − z, or exactly 0 where it is within the rounding error of its own evaluation,
// γ₃(|x| + |y| + |z|) with γ₃ ≈ 3u (Higham, Accuracy and Stability of Numerical
// Algorithms, §3.1), taken as 4u: the data cannot tell such a value from 0. A Newton
// update satisfies the (linear) BDF relations exactly but for the rounding of x += δx, so
// from the second iteration on their rows read 0, and the condensed system's right-hand
// side (condensed_solver.hpp) skips the columns of the rows that do.
double relation_residual(double x, double y, double z) {
  constexpr double kFloor = 4 * kUnitRoundoff;
  const double r = x - y - z;
  return std::abs(r) <= kFloor * (std::abs(x) + std::abs(y) + std::abs(z)) ? 0.0 : r;
}
}  // namespace

// The BDF relations β a − v − ζ₁ and β v − q − ζ₂ of the independent coordinates
// (partitioned) or of every coordinate (stabilized), added to hu and the Jacobian
// (each 0 where within its rounding error: relation_residual).
void NewtonSystem::add_bdf_rows(const double* a, const double* v, const double* q,
                                const BdfTerms& bdf, bool jacobian, double* hu) {
  const bool stab = formulation_ == Formulation::stabilized;
  const index_t nb = stab ? n_ : static_cast<index_t>(independent_.size());
  double* J = jac_.values.data();
  for (index_t k = 0; k < nb; ++k) {
    const index_t j = stab ? k : independent_[k];
    hu[k] += relation_residual(bdf.beta * a[j], v[j], bdf.zeta1[j]);
    hu[nb + k] += relation_residual(bdf.beta * v[j], q[j], bdf.zeta2[j]);
    if (!jacobian) continue;
    J[upos_[4 * k]] += bdf.beta;
    J[upos_[4 * k + 1]] += -1.0;
    J[upos_[4 * k + 2]] += bdf.beta;
    J[upos_[4 * k + 3]] += -1.0;
  }
}

namespace {
// Rows of Φ_q of the constraint elements; `keep(k)` for model row k.
template <class Keep, class Gather>
SparseRows jacobian_rows(const Model& model, index_t n, const double* q, double t, Keep keep,
                         const std::vector<index_t>& row0, Gather gather) {
  SparseRows rows;
  rows.n_cols = n;
  std::vector<double> lq, zero;
  ConstraintEval ce;
  for (std::size_t e = 0; e < model.constraints.size(); ++e) {
    const auto& c = model.constraints[e];
    gather(c->dofs, q, lq);
    zero.assign(c->dofs.size(), 0.0);
    c->evaluate_gradient(lq.data(), zero.data(), zero.data(), t, ce);
    const std::size_t nz = c->dofs.size();
    for (int r = 0; r < c->rows; ++r) {
      if (!keep(row0[e] + r)) continue;
      for (std::size_t i = 0; i < nz; ++i)
        if (ce.jq[r * nz + i] != 0.0) {
          rows.cols.push_back(c->dofs[i]);
          rows.vals.push_back(ce.jq[r * nz + i]);
        }
      rows.ptr.push_back(static_cast<index_t>(rows.cols.size()));
    }
  }
  return rows;
}
}  // namespace

SparseRows NewtonSystem::constraint_jacobian(const double* q, double t) const {
  return jacobian_rows(
      model_, n_, q, t, [&](index_t k) { return active_[k] != 0; }, row0_,
      [&](const std::vector<index_t>& d, const double* s, std::vector<double>& o) {
        gather(d, s, o);
      });
}

void NewtonSystem::constraint_jacobian_full(const double* q, double t, SparseRows& rows) const {
  // the pattern: every coordinate of each active row, element by element
  const std::size_t nc = model_.constraints.size();
  std::vector<std::size_t> first(nc + 1, 0);  // first entry of each element
  rows.n_cols = n_;
  rows.ptr.assign(1, 0);
  rows.cols.clear();
  for (std::size_t e = 0; e < nc; ++e) {
    const auto& c = model_.constraints[e];
    for (int r = 0; r < c->rows; ++r) {
      if (!active_[row0_[e] + r]) continue;
      rows.cols.insert(rows.cols.end(), c->dofs.begin(), c->dofs.end());
      rows.ptr.push_back(static_cast<index_t>(rows.cols.size()));
    }
    first[e + 1] = rows.cols.size();
  }
  rows.vals.resize(rows.cols.size());
  for_element_ranges(nc, [&](std::size_t begin, std::size_t end) {
    std::vector<double> lq, zero;
    ConstraintEval ce;
    for (std::size_t e = begin; e < end; ++e) {
      if (first[e + 1] == first[e]) continue;
      const auto& c = model_.constraints[e];
      gather(c->dofs, q, lq);
      zero.assign(c->dofs.size(), 0.0);
      c->evaluate_gradient(lq.data(), zero.data(), zero.data(), t, ce);
      const std::size_t nz = c->dofs.size();
      double* out = rows.vals.data() + first[e];
      for (int r = 0; r < c->rows; ++r) {
        if (!active_[row0_[e] + r]) continue;
        std::copy(ce.jq.begin() + r * nz, ce.jq.begin() + (r + 1) * nz, out);
        out += nz;
      }
    }
  });
}

SparseRows NewtonSystem::model_constraint_jacobian(const double* q, double t) const {
  return jacobian_rows(
      model_, n_, q, t, [](index_t) { return true; }, row0_,
      [&](const std::vector<index_t>& d, const double* s, std::vector<double>& o) {
        gather(d, s, o);
      });
}

template <class Put>
void NewtonSystem::each_constraint_value(const double* q, const double* v, const double* a,
                                         double t, Put&& put) const {
  for_element_ranges(model_.constraints.size(), [&](std::size_t begin, std::size_t end) {
    std::vector<double> lq, lv, la;
    ConstraintEval ce;
    for (std::size_t e = begin; e < end; ++e) {
      const auto& c = model_.constraints[e];
      gather(c->dofs, q, lq);
      if (v)
        gather(c->dofs, v, lv);
      else
        lv.assign(c->dofs.size(), 0.0);
      if (a)
        gather(c->dofs, a, la);
      else
        la.assign(c->dofs.size(), 0.0);
      c->evaluate(lq.data(), lv.data(), la.data(), t, false, ce);
      put(e, ce);
    }
  });
}

void NewtonSystem::constraint_values(const double* q, const double* v, const double* a, double t,
                                     double* phi, double* phid, double* phidd) const {
  each_constraint_value(q, v, a, t, [&](std::size_t e, const ConstraintEval& ce) {
    const int rows = model_.constraints[e]->rows;
    for (int r = 0; r < rows; ++r) {
      const index_t k = active_index_[row0_[e] + r];
      if (k < 0) continue;
      if (phi) phi[k] = ce.phi[r];
      if (phid) phid[k] = ce.phid[r];
      if (phidd) phidd[k] = ce.phidd[r];
    }
  });
}

void NewtonSystem::model_constraint_values(const double* q, const double* v, double t, double* phi,
                                           double* phid) const {
  each_constraint_value(q, v, nullptr, t, [&](std::size_t e, const ConstraintEval& ce) {
    const int rows = model_.constraints[e]->rows;
    for (int r = 0; r < rows; ++r) {
      if (phi) phi[row0_[e] + r] = ce.phi[r];
      if (phid) phid[row0_[e] + r] = ce.phid[r];
    }
  });
}

void NewtonSystem::force_values(const double* q, const double* v, const double* a, double t,
                                double* g) const {
  std::fill(g, g + n_, 0.0);
  std::vector<double> lq, lv, la;
  ForceEval fe;
  for (const auto& f : model_.forces) {
    gather(f->dofs, q, lq);
    gather(f->dofs, v, lv);
    gather(f->dofs, a, la);
    f->evaluate(lq.data(), lv.data(), la.data(), t, false, fe);
    for (std::size_t i = 0; i < f->dofs.size(); ++i) g[f->dofs[i]] += fe.g[i];
  }
}

void NewtonSystem::mass_triplets(const double* q, const double* v, double t,
                                 std::vector<index_t>& rows, std::vector<index_t>& cols,
                                 std::vector<double>& vals) const {
  // each element's mass block (Force::mass_structure) at its own offset, so elements are
  // evaluated in parallel
  const std::size_t nf = model_.forces.size(), base = rows.size();
  std::vector<std::size_t> offset(nf + 1, base);
  for (std::size_t e = 0; e < nf; ++e) {
    const Force& f = *model_.forces[e];
    offset[e + 1] = offset[e] + f.mass_entries();
  }
  rows.resize(offset[nf]);
  cols.resize(offset[nf]);
  vals.resize(offset[nf]);
  auto blocks = [&](std::size_t begin, std::size_t end) {
    std::vector<double> lq, lv, da;
    for (std::size_t e = begin; e < end; ++e) {
      const Force& f = *model_.forces[e];
      if (!f.uses_a) continue;
      gather(f.dofs, q, lq);
      gather(f.dofs, v, lv);
      f.mass_matrix(lq.data(), lv.data(), t, da);
      const std::size_t nz = f.dofs.size();
      std::size_t k = offset[e];
      f.for_each_mass_entry([&](std::size_t i, std::size_t j) {
        rows[k] = f.dofs[i];
        cols[k] = f.dofs[j];
        vals[k++] = da[i * nz + j];
      });
    }
  };
  for_element_ranges(nf, blocks);
}

void NewtonSystem::energy(const double* q, const double* v, double t, double* kinetic,
                          double* potential) const {
  // each element's energies on the assembly's threads, then summed in the elements' order:
  // the sums one thread's loop makes, for any number of threads
  const std::size_t nf = model_.forces.size();
  std::vector<double> ek(nf), ep(nf);
  for_element_ranges(nf, [&](std::size_t begin, std::size_t end) {
    std::vector<double> lq, lv;
    for (std::size_t e = begin; e < end; ++e) {
      const auto& f = model_.forces[e];
      gather(f->dofs, q, lq);
      gather(f->dofs, v, lv);
      ek[e] = f->kinetic_energy(lq.data(), lv.data());
      ep[e] = f->potential_energy(lq.data(), t);
    }
  });
  double k = 0, p = 0;
  for (std::size_t e = 0; e < nf; ++e) {
    k += ek[e];
    p += ep[e];
  }
  *kinetic = k;
  *potential = p;
}

}  // namespace strata::mbd
