// strata::mbd — residual and Jacobian assembly of the BDF Newton system (see the header).
#include "mbd/newton_system.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <stdexcept>

#include "strata/errors.hpp"

namespace strata::mbd {

SparseMatrix PatternBuilder::finish() {
  std::sort(keys_.begin(), keys_.end());
  keys_.erase(std::unique(keys_.begin(), keys_.end()), keys_.end());
  a_ = SparseMatrix{};
  a_.n_rows = rows_;
  a_.n_cols = cols_;
  a_.offsets.assign(cols_ + 1, 0);
  a_.indices.resize(keys_.size());
  for (std::size_t k = 0; k < keys_.size(); ++k) {
    const index_t c = static_cast<index_t>(keys_[k] / rows_);
    a_.indices[k] = static_cast<index_t>(keys_[k] % rows_);
    ++a_.offsets[c + 1];
  }
  for (index_t c = 0; c < cols_; ++c) a_.offsets[c + 1] += a_.offsets[c];
  a_.values.assign(keys_.size(), 0.0);
  keys_.clear();
  keys_.shrink_to_fit();
  return a_;
}

index_t PatternBuilder::find(index_t r, index_t c) const {
  const auto b = a_.indices.begin() + a_.offsets[c], e = a_.indices.begin() + a_.offsets[c + 1];
  const auto it = std::lower_bound(b, e, r);
  if (it == e || *it != r) throw std::logic_error("PatternBuilder::find: entry not in pattern");
  return it - a_.indices.begin();
}

SparseMatrix from_triplets(index_t n_rows, index_t n_cols, const std::vector<index_t>& rows,
                           const std::vector<index_t>& cols, const std::vector<double>& vals) {
  PatternBuilder pb(n_rows, n_cols);
  for (std::size_t k = 0; k < rows.size(); ++k) pb.add(rows[k], cols[k]);
  SparseMatrix a = pb.finish();
  for (std::size_t k = 0; k < rows.size(); ++k) a.values[pb.find(rows[k], cols[k])] += vals[k];
  return a;
}

NewtonSystem::NewtonSystem(const Model& model)
    : model_(model), n_(model.n), candidate_(model.forces.size(), 1) {
  for (const auto& c : model.constraints) {
    row0_.push_back(m_);
    m_ += c->rows;
  }
}

std::string NewtonSystem::row_name(index_t r) const {
  const auto it = std::upper_bound(row0_.begin(), row0_.end(), r) - 1;
  const std::size_t e = it - row0_.begin();
  const auto& c = model_.constraints[e];
  if (c->rows == 1) return c->name;
  return c->name + " equation " + std::to_string(r - *it);
}

void NewtonSystem::gather(const std::vector<index_t>& dofs, const double* src,
                          std::vector<double>& dst) const {
  dst.resize(dofs.size());
  for (std::size_t i = 0; i < dofs.size(); ++i) dst[i] = src[dofs[i]];
}

void NewtonSystem::set_partition(const Partition& p) {
  independent_ = p.independent;
  rebuild_pattern();
}

void NewtonSystem::set_candidates(const std::vector<char>& c) {
  if (c.size() != candidate_.size())
    throw InvalidInput("the saved contact candidate set has " + std::to_string(c.size()) +
                       " entries, the model " + std::to_string(candidate_.size()) +
                       " force elements");
  candidate_ = c;
}

bool NewtonSystem::update_candidates(const double* q) {
  bool changed = false;
  std::vector<double> lq;
  for (std::size_t e = 0; e < model_.forces.size(); ++e) {
    const Force& f = *model_.forces[e];
    if (f.margin <= 0) continue;
    gather(f.dofs, q, lq);
    const char c = f.proximity(lq.data()) < f.margin;
    changed |= c != candidate_[e];
    candidate_[e] = c;
  }
  if (changed && jac_.n_rows > 0) rebuild_pattern();
  return changed;
}

int NewtonSystem::check_candidates(const double* q) const {
  int status = 0;
  std::vector<double> lq;
  for (std::size_t e = 0; e < model_.forces.size(); ++e) {
    const Force& f = *model_.forces[e];
    if (f.margin <= 0 || candidate_[e]) continue;
    gather(f.dofs, q, lq);
    const double p = f.proximity(lq.data());
    if (p < 0) return 2;
    if (p < 0.5 * f.margin) status = 1;
  }
  return status;
}

index_t NewtonSystem::active_forces() const {
  index_t k = 0;
  for (char c : candidate_) k += c;
  return k;
}

void NewtonSystem::rebuild_pattern() {
  const index_t n = n_, m = m_, N = size();
  const index_t A = 0, V = n, Q = 2 * n, L = 3 * n;                  // column blocks
  const index_t RA = n, RV = n + m, RP = n + 2 * m, RU = n + 3 * m;  // row blocks
  const index_t ni = static_cast<index_t>(independent_.size());
  PatternBuilder pb(N, N);
  // Enumerates every block: mode 0 collects, mode 1 records positions.
  auto visit = [&](int mode) {
    auto put = [&](index_t r, index_t c, std::vector<index_t>* pos) {
      if (mode == 0)
        pb.add(r, c);
      else
        pos->push_back(pb.find(r, c));
    };
    for (std::size_t e = 0; e < model_.forces.size(); ++e) {
      if (!candidate_[e]) continue;
      const Force& f = *model_.forces[e];
      ForcePos& fp = fpos_[e];
      for (index_t i : f.dofs)
        for (index_t j : f.dofs) {
          put(i, Q + j, &fp.q);
          if (f.uses_v) put(i, V + j, &fp.v);
          if (f.uses_a) put(i, A + j, &fp.a);
        }
    }
    for (std::size_t e = 0; e < model_.constraints.size(); ++e) {
      const Constraint& c = *model_.constraints[e];
      ConstraintPos& cp = cpos_[e];
      const index_t r0 = row0_[e];
      for (index_t i : c.dofs)
        for (index_t j : c.dofs) put(i, Q + j, &cp.hq);
      for (index_t i : c.dofs)
        for (int r = 0; r < c.rows; ++r) put(i, L + r0 + r, &cp.fl);
      for (int r = 0; r < c.rows; ++r)
        for (index_t j : c.dofs) {
          put(RA + r0 + r, A + j, &cp.aa);
          put(RA + r0 + r, V + j, &cp.av);
          put(RA + r0 + r, Q + j, &cp.aq);
          put(RV + r0 + r, V + j, &cp.vv);
          put(RV + r0 + r, Q + j, &cp.vq);
          put(RP + r0 + r, Q + j, &cp.pq);
        }
    }
    for (index_t k = 0; k < ni; ++k) {
      const index_t j = independent_[k];
      put(RU + k, A + j, &upos_);
      put(RU + k, V + j, &upos_);
      put(RU + ni + k, V + j, &upos_);
      put(RU + ni + k, Q + j, &upos_);
    }
  };
  fpos_.assign(model_.forces.size(), {});
  cpos_.assign(model_.constraints.size(), {});
  upos_.clear();
  visit(0);
  jac_ = pb.finish();
  visit(1);
}

void NewtonSystem::evaluate(const double* x, double t, const BdfTerms& bdf, bool jacobian,
                            double* h, bool skip_intermittent) {
  const index_t n = n_, m = m_;
  const double *a = x, *v = x + n, *q = x + 2 * n, *lam = x + 3 * n;
  double *hf = h, *ha = h + n, *hv = h + n + m, *hp = h + n + 2 * m, *hu = h + n + 3 * m;
  std::fill(h, h + size(), 0.0);
  double* J = jac_.values.data();
  if (jacobian) std::fill(jac_.values.begin(), jac_.values.end(), 0.0);
  const std::size_t nf = model_.forces.size(), nc = model_.constraints.size();
  auto add = [](double& target, double value) {
    std::atomic_ref<double>(target).fetch_add(value, std::memory_order_relaxed);
  };
  auto forces = [&](std::size_t begin, std::size_t end) {
    std::vector<double> lq, lv, la;
    ForceEval fe;
    for (std::size_t e = begin; e < end; ++e) {
      const Force& f = *model_.forces[e];
      if (!candidate_[e] || (skip_intermittent && f.intermittent)) continue;
      gather(f.dofs, q, lq);
      gather(f.dofs, v, lv);
      gather(f.dofs, a, la);
      f.evaluate(lq.data(), lv.data(), la.data(), t, jacobian, fe);
      const std::size_t nz = f.dofs.size();
      for (std::size_t i = 0; i < nz; ++i) add(hf[f.dofs[i]], fe.g[i]);
      if (!jacobian) continue;
      const ForcePos& fp = fpos_[e];
      for (std::size_t k = 0; k < nz * nz; ++k) add(J[fp.q[k]], fe.dq[k]);
      if (f.uses_v)
        for (std::size_t k = 0; k < nz * nz; ++k) add(J[fp.v[k]], fe.dv[k]);
      if (f.uses_a)
        for (std::size_t k = 0; k < nz * nz; ++k) add(J[fp.a[k]], fe.da[k]);
    }
  };
  auto constraints = [&](std::size_t begin, std::size_t end) {
    std::vector<double> lq, lv, la, hess;
    ConstraintEval ce;
    for (std::size_t e = begin; e < end; ++e) {
      const Constraint& c = *model_.constraints[e];
      const index_t r0 = row0_[e];
      gather(c.dofs, q, lq);
      gather(c.dofs, v, lv);
      gather(c.dofs, a, la);
      // Φ_q is needed for Φ_qᵀλ even in a residual-only evaluation
      if (jacobian)
        c.evaluate(lq.data(), lv.data(), la.data(), t, true, ce);
      else
        c.evaluate_gradient(lq.data(), lv.data(), la.data(), t, ce);
      const std::size_t nz = c.dofs.size();
      const int nr = c.rows;
      for (int r = 0; r < nr; ++r) {
        ha[r0 + r] = ce.phidd[r];
        hv[r0 + r] = ce.phid[r];
        hp[r0 + r] = ce.phi[r];
      }
      for (std::size_t i = 0; i < nz; ++i) {
        double s = 0;
        for (int r = 0; r < nr; ++r) s += ce.jq[r * nz + i] * lam[r0 + r];
        add(hf[c.dofs[i]], s);
      }
      if (!jacobian) continue;
      const ConstraintPos& cp = cpos_[e];
      hess.resize(nz * nz);
      c.hessian(lq.data(), t, lam + r0, hess.data());
      for (std::size_t k = 0; k < nz * nz; ++k) add(J[cp.hq[k]], hess[k]);
      // the constraint's own rows and multiplier column: no other element writes there
      for (std::size_t i = 0; i < nz; ++i)
        for (int r = 0; r < nr; ++r) J[cp.fl[i * nr + r]] += ce.jq[r * nz + i];
      for (std::size_t k = 0; k < nr * nz; ++k) {
        J[cp.aa[k]] += ce.jq[k];
        J[cp.av[k]] += 2 * ce.jvq[k];
        J[cp.aq[k]] += ce.jaq[k];
        J[cp.vv[k]] += ce.jq[k];
        J[cp.vq[k]] += ce.jvq[k];
        J[cp.pq[k]] += ce.jq[k];
      }
    }
  };
  // Elements are evaluated in parallel (oneTBB, as strata's CPU executor); entries shared
  // by several elements (rows of the equations of motion) are added atomically.
  if (threads_ <= 1) {
    forces(0, nf);
    constraints(0, nc);
  } else {
    tbb::task_arena arena(threads_);
    arena.execute([&] {
      tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nf, 64),
                        [&](const auto& r) { forces(r.begin(), r.end()); });
      tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nc, 64),
                        [&](const auto& r) { constraints(r.begin(), r.end()); });
    });
  }
  const index_t ni = static_cast<index_t>(independent_.size());
  for (index_t k = 0; k < ni; ++k) {
    const index_t j = independent_[k];
    hu[k] = bdf.beta * a[j] - v[j] - bdf.zeta1[j];
    hu[ni + k] = bdf.beta * v[j] - q[j] - bdf.zeta2[j];
    if (!jacobian) continue;
    J[upos_[4 * k]] += bdf.beta;
    J[upos_[4 * k + 1]] += -1.0;
    J[upos_[4 * k + 2]] += bdf.beta;
    J[upos_[4 * k + 3]] += -1.0;
  }
}

SparseRows NewtonSystem::constraint_jacobian(const double* q, double t) const {
  SparseRows rows;
  rows.n_cols = n_;
  std::vector<double> lq, zero;
  ConstraintEval ce;
  for (const auto& c : model_.constraints) {
    gather(c->dofs, q, lq);
    zero.assign(c->dofs.size(), 0.0);
    c->evaluate_gradient(lq.data(), zero.data(), zero.data(), t, ce);
    const std::size_t nz = c->dofs.size();
    for (int r = 0; r < c->rows; ++r) {
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

void NewtonSystem::constraint_values(const double* q, const double* v, const double* a, double t,
                                     double* phi, double* phid, double* phidd) const {
  std::vector<double> lq, lv, la;
  ConstraintEval ce;
  for (std::size_t e = 0; e < model_.constraints.size(); ++e) {
    const auto& c = model_.constraints[e];
    gather(c->dofs, q, lq);
    gather(c->dofs, v, lv);
    gather(c->dofs, a, la);
    c->evaluate(lq.data(), lv.data(), la.data(), t, false, ce);
    for (int r = 0; r < c->rows; ++r) {
      if (phi) phi[row0_[e] + r] = ce.phi[r];
      if (phid) phid[row0_[e] + r] = ce.phid[r];
      if (phidd) phidd[row0_[e] + r] = ce.phidd[r];
    }
  }
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
  std::vector<double> lq, lv, la;
  ForceEval fe;
  for (const auto& f : model_.forces) {
    if (!f->uses_a) continue;
    gather(f->dofs, q, lq);
    gather(f->dofs, v, lv);
    la.assign(f->dofs.size(), 0.0);
    f->evaluate(lq.data(), lv.data(), la.data(), t, true, fe);
    const std::size_t nz = f->dofs.size();
    for (std::size_t i = 0; i < nz; ++i)
      for (std::size_t j = 0; j < nz; ++j) {
        rows.push_back(f->dofs[i]);
        cols.push_back(f->dofs[j]);
        vals.push_back(fe.da[i * nz + j]);
      }
  }
}

void NewtonSystem::energy(const double* q, const double* v, double t, double* kinetic,
                          double* potential) const {
  std::vector<double> lq, lv;
  double k = 0, p = 0;
  for (const auto& f : model_.forces) {
    gather(f->dofs, q, lq);
    gather(f->dofs, v, lv);
    k += f->kinetic_energy(lq.data(), lv.data());
    p += f->potential_energy(lq.data(), t);
  }
  *kinetic = k;
  *potential = p;
}

}  // namespace strata::mbd
