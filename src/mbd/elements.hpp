// strata::mbd — the two kinds of model elements and their automatic Jacobians.
//
// A Constraint contributes m rows Φ(q, t) = 0 and, through the multipliers, Φ_qᵀλ to the
// equations of motion. A Force contributes a term g(q, v, a, t) to the residual of the
// equations of motion F = Σ g + Φ_qᵀλ: inertia (M a plus quadratic velocity terms) with
// a positive sign, applied forces Q with a negative sign.
//
// Each concrete element implements ONE templated kernel (see the CRTP adaptors below);
// the adaptors evaluate it with the types of autodiff.hpp to obtain exact Jacobians:
//   Constraint::evaluate  Φ, Φ̇ = Φ_q v + Φ_t, Φ̈ = Φ_q a + (Φ_q v)_q v + 2Φ_qt v + Φ_tt,
//                         and their q-Jacobians, from one Jet2<Dual<NZ>> evaluation;
//                         the v- and a-Jacobians follow from ∂Φ̇/∂v = Φ_q,
//                         ∂Φ̈/∂v = 2 ∂Φ̇/∂q, ∂Φ̈/∂a = Φ_q.
//   Constraint::hessian   Σ λ_i ∂²Φ_i/∂q², from Dual<Dual<NZ>>.
//   Force::evaluate       g and ∂g/∂q, ∂g/∂v (∂g/∂a for inertia) from Dual<2NZ or 3NZ>.
// Kernel sources (the constraint and force formulas) are cited in their files.
#pragma once

#include <array>
#include <cmath>
#include <cstdint>
#include <mutex>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "mbd/autodiff.hpp"
#include "mbd/linalg.hpp"
#include "strata/types.hpp"

namespace strata::mbd {

/// Values and q-Jacobians of one constraint at the three levels (row-major, rows × nz).
struct ConstraintEval {
  std::vector<double> phi, phid, phidd;  ///< Φ, Φ̇, Φ̈ (rows)
  std::vector<double> jq;                ///< Φ_q
  std::vector<double> jvq;               ///< ∂Φ̇/∂q
  std::vector<double> jaq;               ///< ∂Φ̈/∂q
};

/// A set of holonomic (possibly rheonomic) constraint equations on a few bodies.
class Constraint {
 public:
  virtual ~Constraint() = default;
  std::string name;           ///< for messages, e.g. "joints[3] 'J4'"
  std::vector<index_t> dofs;  ///< global coordinate indices of the local vector z
  int rows = 0;               ///< number of equations
  /// Local index of the translational coordinates of the body whose reaction force is
  /// reported (body j of a joint, or body i when j does not move); -1: none.
  int reaction_local = -1;
  int reaction_dim = 0;  ///< 2 (planar) or 3
  /// Depends on time explicitly (a driver): it does work, so the energy is not conserved.
  bool rheonomic = false;
  /// Evaluates at local q, v, a (each dofs.size()) and time t. jacobian=false fills only
  /// phi, phid, phidd.
  virtual void evaluate(const double* q, const double* v, const double* a, double t, bool jacobian,
                        ConstraintEval& out) const = 0;
  /// Φ, Φ̇, Φ̈ and Φ_q only (for residuals: Φ_qᵀλ), cheaper than evaluate(…, true, …).
  virtual void evaluate_gradient(const double* q, const double* v, const double* a, double t,
                                 ConstraintEval& out) const = 0;
  /// H = Σ_i λ_i ∂²Φ_i/∂q² (nz × nz, row-major).
  virtual void hessian(const double* q, double t, const double* lambda, double* h) const = 0;
  /// How many local coordinates hessian() differentiates: those with a nonzero row of H
  /// (known after the first call; dofs.size() before).
  virtual int hessian_coordinates() const = 0;
};

/// Residual contribution g and its Jacobians (row-major nz × nz).
struct ForceEval {
  std::vector<double> g, dq, dv, da;
};

/// A term of the equations of motion: inertia, an applied force, a force element.
class Force {
 public:
  virtual ~Force() = default;
  std::string name;
  std::vector<index_t> dofs;
  bool uses_v = true;   ///< ∂g/∂v may be nonzero (structurally)
  bool uses_a = false;  ///< ∂g/∂a may be nonzero (inertia)
  /// Contact: the force is often exactly zero. Such elements are left out of the values
  /// the linear solver's analysis sees (its matching must not rely on them), and, when
  /// `margin` > 0, they enter the Newton matrix only while proximity() < margin.
  bool intermittent = false;
  double margin = 0;  ///< m; 0: always part of the Newton matrix
  /// Does no net work over a closed path and its potential_energy() accounts for it
  /// (inertia with gravity, undamped springs without actuators): set by the factories.
  bool conservative = false;
  /// Separation (m) of the contact surfaces at local q; negative when penetrating.
  virtual double proximity(const double* q) const { return -1; }
  /// g(q, v, a, t) with local vectors; Jacobians when jacobian=true.
  virtual void evaluate(const double* q, const double* v, const double* a, double t, bool jacobian,
                        ForceEval& out) const = 0;
  /// The structure of ∂g/∂a (uses_a): the positions i·nz + j (nz = dofs.size(), row-major
  /// as ForceEval::da) of the mass block's entries that may be nonzero, ascending; empty
  /// (the default) when any of the nz² may be. Entries outside it are exactly zero at every
  /// state (tests/unit/test_mbd_jacobians.cpp checks), and the initial acceleration
  /// analysis's matrix leaves them out (a hexahedron's M ⊗ I₃ has 192 of 576). The Newton
  /// matrix keeps whole blocks: with them a node's coordinates have the same rows there,
  /// which the nested dissection compresses to one vertex.
  virtual std::span<const std::uint32_t> mass_structure() const { return {}; }
  /// The number of entries of the mass block in the acceleration analysis's matrix:
  /// mass_structure()'s, or dofs.size()² when it is empty; 0 without inertia.
  std::size_t mass_entries() const {
    if (!uses_a) return 0;
    const std::size_t listed = mass_structure().size();
    return listed ? listed : dofs.size() * dofs.size();
  }
  /// Calls put(i, j) (local indices) for each entry of mass_structure() (all nz² when it is
  /// empty, none without inertia), in row-major order.
  template <class Put>
  void for_each_mass_entry(Put&& put) const {
    if (!uses_a) return;
    const std::size_t nz = dofs.size();
    const std::span<const std::uint32_t> listed = mass_structure();
    if (listed.empty()) {
      for (std::size_t i = 0; i < nz; ++i)
        for (std::size_t j = 0; j < nz; ++j) put(i, j);
    } else {
      for (const std::uint32_t s : listed) put(s / nz, s % nz);
    }
  }
  virtual double kinetic_energy(const double* q, const double* v) const { return 0; }
  virtual double potential_energy(const double* q, double t) const { return 0; }
  /// ∂g/∂a at local (q, v, t) with a = 0 into `da` (dofs.size()² entries, row-major as
  /// ForceEval::da), for the initial acceleration analysis's mass matrix. The default
  /// evaluates the element with its Jacobians; an element whose mass matrix is known
  /// without them overrides it.
  virtual void mass_matrix(const double* q, const double* v, double t,
                           std::vector<double>& da) const {
    const std::vector<double> a(dofs.size(), 0.0);
    ForceEval fe;
    evaluate(q, v, a.data(), t, true, fe);
    da = std::move(fe.da);
  }
};

// --------------------------------------------------------------- CRTP adaptors --------

/// Constraint adaptor: D provides `static constexpr int NR` and
/// `template <class T> void phi(const T* z, const T& t, T* out) const`.
template <class D, int NZ>
class ConstraintT : public Constraint {
 public:
  void evaluate(const double* q, const double* v, const double* a, double t, bool jacobian,
                ConstraintEval& out) const override {
    constexpr int NR = D::NR;
    out.phi.resize(NR);
    out.phid.resize(NR);
    out.phidd.resize(NR);
    if (!jacobian) {
      using J = Jet2<double>;
      J z[NZ], o[NR];
      for (int i = 0; i < NZ; ++i) z[i] = J(q[i], v[i], 0.5 * a[i]);
      static_cast<const D*>(this)->phi(z, J(t, 1.0, 0.0), o);
      for (int r = 0; r < NR; ++r) {
        out.phi[r] = o[r].c0;
        out.phid[r] = o[r].c1;
        out.phidd[r] = 2 * o[r].c2;
      }
      return;
    }
    using S = Dual<double, NZ>;
    using J = Jet2<S>;
    J z[NZ], o[NR];
    for (int i = 0; i < NZ; ++i) z[i] = J(S(q[i], i), S(v[i]), S(0.5 * a[i]));
    static_cast<const D*>(this)->phi(z, J(S(t), S(1.0), S(0.0)), o);
    out.jq.resize(NR * NZ);
    out.jvq.resize(NR * NZ);
    out.jaq.resize(NR * NZ);
    for (int r = 0; r < NR; ++r) {
      out.phi[r] = o[r].c0.v;
      out.phid[r] = o[r].c1.v;
      out.phidd[r] = 2 * o[r].c2.v;
      for (int k = 0; k < NZ; ++k) {
        out.jq[r * NZ + k] = o[r].c0.d[k];
        out.jvq[r * NZ + k] = o[r].c1.d[k];
        out.jaq[r * NZ + k] = 2 * o[r].c2.d[k];
      }
    }
  }
  void evaluate_gradient(const double* q, const double* v, const double* a, double t,
                         ConstraintEval& out) const override {
    evaluate(q, v, a, t, false, out);  // values from Jet2<double>
    constexpr int NR = D::NR;
    using S = Dual<double, NZ>;
    S z[NZ], o[NR];
    for (int i = 0; i < NZ; ++i) z[i] = S(q[i], i);
    static_cast<const D*>(this)->phi(z, S(t), o);
    out.jq.resize(NR * NZ);
    for (int r = 0; r < NR; ++r)
      for (int k = 0; k < NZ; ++k) out.jq[r * NZ + k] = o[r].d[k];
  }
  /// Only the coordinates with a nonzero row in the Hessian are differentiated (positions
  /// enter most joints linearly: a spatial revolute joint's 14 coordinates have 8 such, its
  /// Euler parameters), in a nested dual number of that size; the others are constants
  /// (their rows and, by symmetry, columns are zero). Which they are is found at the first
  /// call from the full Hessian at two points near q with random multipliers (a row that
  /// is zero there is zero everywhere for the polynomial and trigonometric kernels, barring
  /// a cancellation of probability zero); a non-finite value there keeps every coordinate.
  void hessian(const double* q, double t, const double* lambda, double* h) const override {
    std::call_once(hessian_once_, [&] { find_hessian_coordinates(q, t); });
    if (hessian_n_ <= 4 && 4 < NZ)
      hessian_over<4>(q, t, lambda, hessian_idx_.data(), hessian_n_, h);
    else if (hessian_n_ <= 8 && 8 < NZ)
      hessian_over<8>(q, t, lambda, hessian_idx_.data(), hessian_n_, h);
    else
      hessian_over<NZ>(q, t, lambda, all_coordinates().data(), NZ, h);
  }
  int hessian_coordinates() const override { return hessian_n_; }
  D& self() { return *static_cast<D*>(this); }

 private:
  static const std::array<int, NZ>& all_coordinates() {
    static const std::array<int, NZ> all = [] {
      std::array<int, NZ> a{};
      for (int i = 0; i < NZ; ++i) a[i] = i;
      return a;
    }();
    return all;
  }
  // H over the nh coordinates idx[0..nh) (K ≥ nh), zero elsewhere.
  template <int K>
  void hessian_over(const double* q, double t, const double* lambda, const int* idx, int nh,
                    double* h) const {
    constexpr int NR = D::NR;
    using S1 = Dual<double, K>;
    using S = Dual<S1, K>;
    S z[NZ], o[NR];
    for (int i = 0; i < NZ; ++i) z[i] = S(q[i]);
    for (int p = 0; p < nh; ++p) {
      z[idx[p]].v = S1(q[idx[p]], p);
      z[idx[p]].d[p] = S1(1.0);
    }
    static_cast<const D*>(this)->phi(z, S(t), o);
    for (int k = 0; k < NZ * NZ; ++k) h[k] = 0;
    for (int r = 0; r < NR; ++r)
      for (int a = 0; a < nh; ++a)
        for (int b = 0; b < nh; ++b) h[idx[a] * NZ + idx[b]] += lambda[r] * o[r].d[a].d[b];
  }
  void find_hessian_coordinates(const double* q, double t) const {
    constexpr int NR = D::NR;
    std::array<char, NZ> used{};
    std::array<double, NZ> qs{};
    std::array<double, NR> lam{};
    std::array<double, NZ * NZ> h{};
    std::uint64_t x = 0x9E3779B97F4A7C15ull;  // fixed: the same set from every thread
    auto uniform = [&x] {                     // in [−1, 1)
      x = x * 6364136223846793005ull + 1442695040888963407ull;
      return static_cast<double>(x >> 11) * 0x1.0p-52 - 1.0;
    };
    bool finite = true;
    for (int sample = 0; sample < 2; ++sample) {
      for (int i = 0; i < NZ; ++i) qs[i] = q[i] + 0.1 * (1 + std::abs(q[i])) * uniform();
      for (int r = 0; r < NR; ++r) lam[r] = 1.5 + 0.5 * uniform();
      hessian_over<NZ>(qs.data(), t, lam.data(), all_coordinates().data(), NZ, h.data());
      for (int k = 0; k < NZ; ++k)
        for (int l = 0; l < NZ; ++l) {
          finite &= std::isfinite(h[k * NZ + l]);
          if (h[k * NZ + l] != 0) used[k] = 1;
        }
    }
    hessian_n_ = 0;
    for (int k = 0; k < NZ; ++k)
      if (used[k] || !finite) hessian_idx_[hessian_n_++] = k;
  }
  mutable std::once_flag hessian_once_;
  mutable int hessian_n_ = NZ;
  mutable std::array<int, NZ> hessian_idx_{};
};

/// Applied-force adaptor: D provides
/// `template <class S> void generalized_force(const Jet1<S>* z, double t, S* Q) const`
/// where z[i] = (q_i, v_i) as a first-order series in time (so positions computed from z
/// carry their velocities), and optionally `bool inactive(const double* q) const` for a
/// cheap exit (e.g. a contact pair far apart). The residual is g = −Q.
template <class D, int NZ>
class ForceT : public Force {
 public:
  void evaluate(const double* q, const double* v, const double* a, double t, bool jacobian,
                ForceEval& out) const override {
    out.g.assign(NZ, 0.0);
    if (jacobian) {
      out.dq.assign(NZ * NZ, 0.0);
      out.dv.assign(NZ * NZ, 0.0);
    }
    if (static_cast<const D*>(this)->inactive(q)) return;
    if (!jacobian) {
      Jet1<double> z[NZ];
      double qf[NZ];
      for (int i = 0; i < NZ; ++i) z[i] = Jet1<double>(q[i], v[i]);
      static_cast<const D*>(this)->generalized_force(z, t, qf);
      for (int i = 0; i < NZ; ++i) out.g[i] = -qf[i];
      return;
    }
    using S = Dual<double, 2 * NZ>;
    Jet1<S> z[NZ];
    S qf[NZ];
    for (int i = 0; i < NZ; ++i) z[i] = Jet1<S>(S(q[i], i), S(v[i], NZ + i));
    static_cast<const D*>(this)->generalized_force(z, t, qf);
    for (int i = 0; i < NZ; ++i) {
      out.g[i] = -qf[i].v;
      for (int k = 0; k < NZ; ++k) {
        out.dq[i * NZ + k] = -qf[i].d[k];
        out.dv[i * NZ + k] = -qf[i].d[NZ + k];
      }
    }
  }
  bool inactive(const double*) const { return false; }
};

/// Inertia adaptor: D provides `template <class S> void inertia(const S* q, const S* v,
/// const S* a, S* g) const` (g = M(q) a + quadratic velocity terms − body forces).
template <class D, int NZ>
class InertiaT : public Force {
 public:
  InertiaT() { uses_a = true; }
  void evaluate(const double* q, const double* v, const double* a, double t, bool jacobian,
                ForceEval& out) const override {
    out.g.assign(NZ, 0.0);
    if (!jacobian) {
      double g[NZ];
      static_cast<const D*>(this)->inertia(q, v, a, g);
      for (int i = 0; i < NZ; ++i) out.g[i] = g[i];
      return;
    }
    using S = Dual<double, 3 * NZ>;
    S qs[NZ], vs[NZ], as[NZ], g[NZ];
    for (int i = 0; i < NZ; ++i) {
      qs[i] = S(q[i], i);
      vs[i] = S(v[i], NZ + i);
      as[i] = S(a[i], 2 * NZ + i);
    }
    static_cast<const D*>(this)->inertia(qs, vs, as, g);
    out.dq.resize(NZ * NZ);
    out.dv.resize(NZ * NZ);
    out.da.resize(NZ * NZ);
    for (int i = 0; i < NZ; ++i) {
      out.g[i] = g[i].v;
      for (int k = 0; k < NZ; ++k) {
        out.dq[i * NZ + k] = g[i].d[k];
        out.dv[i * NZ + k] = g[i].d[NZ + k];
        out.da[i * NZ + k] = g[i].d[2 * NZ + k];
      }
    }
  }
};

// ----------------------------------------------------------- body references --------

/// Where an element finds one body's coordinates in its local vector z, or, for ground
/// and fixed bodies (local < 0), the body's constant pose.
struct BodyRef {
  int local = -1;                ///< first local coordinate; -1: not moving
  Vec3<double> r{};              ///< constant position (planar: x, y)
  Vec4<double> p{{1, 0, 0, 0}};  ///< constant Euler parameters (spatial)
  double phi = 0;                ///< constant angle (planar)
  bool moving() const { return local >= 0; }
};

template <class T>
struct Pose2 {
  Vec2<T> r;
  T phi;
  Mat2<T> A;
  /// Global position of the body-fixed point s'.
  Vec2<T> point(const Vec2<double>& s) const { return r + A * lift<T>(s); }
  /// Global direction of the body-fixed vector u'.
  Vec2<T> vec(const Vec2<double>& u) const { return A * lift<T>(u); }
};
template <class T>
struct Pose3 {
  Vec3<T> r;
  Vec4<T> p;
  Mat3<T> A;
  Vec3<T> point(const Vec3<double>& s) const { return r + A * lift<T>(s); }
  Vec3<T> vec(const Vec3<double>& u) const { return A * lift<T>(u); }
};

template <class T>
Pose2<T> pose2(const BodyRef& b, const T* z) {
  Pose2<T> p;
  if (b.moving()) {
    p.r = {{z[b.local], z[b.local + 1]}};
    p.phi = z[b.local + 2];
  } else {
    p.r = {{T(b.r[0]), T(b.r[1])}};
    p.phi = T(b.phi);
  }
  p.A = rot2(p.phi);
  return p;
}
template <class T>
Pose3<T> pose3(const BodyRef& b, const T* z) {
  Pose3<T> p;
  if (b.moving()) {
    p.r = {{z[b.local], z[b.local + 1], z[b.local + 2]}};
    p.p = {{z[b.local + 3], z[b.local + 4], z[b.local + 5], z[b.local + 6]}};
  } else {
    p.r = lift<T>(b.r);
    p.p = lift<T>(b.p);
  }
  p.A = rot3(p.p);
  return p;
}
/// Position of an FE node (3 coordinates) or of a fixed point.
template <class T>
Vec3<T> node_position(const BodyRef& b, const T* z) {
  if (b.moving()) return {{z[b.local], z[b.local + 1], z[b.local + 2]}};
  return lift<T>(b.r);
}

/// Adds to Q the generalized force of a planar force f (global) acting at the global
/// point x, plus a torque n, on a planar body with pose (r, φ) (Nikravesh 1988, §6.2).
template <class S>
void add_wrench2(const BodyRef& b, const Pose2<S>& pose, const Vec2<S>& x, const Vec2<S>& f,
                 const S& n, S* Q) {
  if (!b.moving()) return;
  const Vec2<S> d = x - pose.r;
  Q[b.local] = Q[b.local] + f[0];
  Q[b.local + 1] = Q[b.local + 1] + f[1];
  Q[b.local + 2] = Q[b.local + 2] + n + (d[0] * f[1] - d[1] * f[0]);
}
/// Adds to Q the generalized force of a spatial force f (global) at the global point x
/// plus a torque n (global) on a body with Euler parameters: Q_r = f,
/// Q_p = 2 Gᵀ Aᵀ ((x − r) × f + n) (Haug 1989, Eq. 11.1.17).
template <class S>
void add_wrench3(const BodyRef& b, const Pose3<S>& pose, const Vec3<S>& x, const Vec3<S>& f,
                 const Vec3<S>& n, S* Q) {
  if (!b.moving()) return;
  const Vec3<S> torque = cross(x - pose.r, f) + n;
  const Vec3<S> tb = tmul(pose.A, torque);
  const Vec4<S> qp = GT_times(pose.p, tb);
  for (int i = 0; i < 3; ++i) Q[b.local + i] = Q[b.local + i] + f[i];
  for (int i = 0; i < 4; ++i) Q[b.local + 3 + i] = Q[b.local + 3 + i] + 2.0 * qp[i];
}
/// Adds a force f on an FE node.
template <class S>
void add_node_force(const BodyRef& b, const Vec3<S>& f, S* Q) {
  if (!b.moving()) return;
  for (int i = 0; i < 3; ++i) Q[b.local + i] = Q[b.local + i] + f[i];
}

/// c0 parts of a pose computed from Jet1 coordinates.
template <class S>
Pose2<S> c0(const Pose2<Jet1<S>>& p) {
  Pose2<S> r;
  for (int i = 0; i < 2; ++i) r.r[i] = p.r[i].c0;
  r.phi = p.phi.c0;
  for (int i = 0; i < 4; ++i) r.A.m[i] = p.A.m[i].c0;
  return r;
}
template <class S>
Pose3<S> c0(const Pose3<Jet1<S>>& p) {
  Pose3<S> r;
  for (int i = 0; i < 3; ++i) r.r[i] = p.r[i].c0;
  for (int i = 0; i < 4; ++i) r.p[i] = p.p[i].c0;
  for (int i = 0; i < 9; ++i) r.A.m[i] = p.A.m[i].c0;
  return r;
}
template <class S, int N>
Vec<S, N> c0(const Vec<Jet1<S>, N>& v) {
  Vec<S, N> r;
  for (int i = 0; i < N; ++i) r[i] = v[i].c0;
  return r;
}
template <class S, int N>
Vec<S, N> c1(const Vec<Jet1<S>, N>& v) {
  Vec<S, N> r;
  for (int i = 0; i < N; ++i) r[i] = v[i].c1;
  return r;
}

}  // namespace strata::mbd
