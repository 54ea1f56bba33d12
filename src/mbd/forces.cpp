// strata::mbd — force kernels (sources in forces.hpp). Each kernel computes physical
// forces and torques from positions whose first-order Taylor coefficients are the
// velocities (Jet1), then maps them to generalized forces with add_wrench2/3.
#include "mbd/forces.hpp"

#include <array>
#include <cmath>
#include <cstdint>
#include <span>

namespace strata::mbd {
namespace {

template <class S>
Mat3<S> c1(const Mat3<Jet1<S>>& a) {
  Mat3<S> r;
  for (int i = 0; i < 9; ++i) r.m[i] = a.m[i].c1;
  return r;
}
template <class S>
Mat2<S> c1(const Mat2<Jet1<S>>& a) {
  Mat2<S> r;
  for (int i = 0; i < 4; ++i) r.m[i] = a.m[i].c1;
  return r;
}
template <class T, int N>
Vec<T, N> zero() {
  Vec<T, N> r;
  for (int i = 0; i < N; ++i) r[i] = T(0.0);
  return r;
}

// ------------------------------------------------------------------- inertia --------
template <class K, int NZ>
class InertiaOf : public InertiaT<InertiaOf<K, NZ>, NZ> {
 public:
  explicit InertiaOf(K k) : k_(std::move(k)) {}
  template <class S>
  void inertia(const S* q, const S* v, const S* a, S* g) const {
    k_.inertia(q, v, a, g);
  }
  double kinetic_energy(const double* q, const double* v) const override {
    return k_.kinetic(q, v);
  }
  double potential_energy(const double* q, double) const override { return k_.potential(q); }
  std::span<const std::uint32_t> mass_structure() const override { return K::kMassStructure; }
  K k_;
};

struct PlanarBody {
  // the mass matrix diag(m, m, J): the body's reference point is its centre of mass
  static constexpr std::array<std::uint32_t, 3> kMassStructure{0, 4, 8};
  double m, J;
  Vec3<double> g;
  template <class S>
  void inertia(const S* q, const S* v, const S* a, S* r) const {
    r[0] = a[0] * m - m * g[0];
    r[1] = a[1] * m - m * g[1];
    r[2] = a[2] * J;
  }
  double kinetic(const double*, const double* v) const {
    return 0.5 * m * (v[0] * v[0] + v[1] * v[1]) + 0.5 * J * v[2] * v[2];
  }
  double potential(const double* q) const { return -m * (g[0] * q[0] + g[1] * q[1]); }
};

struct SpatialBody {
  // m I₃ for the centre of mass's position, 4 Gᵀ J G for the Euler parameters, no coupling
  static constexpr std::array<std::uint32_t, 19> kMassStructure{
      0, 8, 16, 24, 25, 26, 27, 31, 32, 33, 34, 38, 39, 40, 41, 45, 46, 47, 48};
  double m;
  Mat3<double> J;
  Vec3<double> g;
  template <class S>
  void inertia(const S* q, const S* v, const S* a, S* r) const {
    for (int i = 0; i < 3; ++i) r[i] = a[i] * m - m * g[i];
    const Vec4<S> p{{q[3], q[4], q[5], q[6]}};
    const Vec4<S> pd{{v[3], v[4], v[5], v[6]}};
    const Vec4<S> pdd{{a[3], a[4], a[5], a[6]}};
    const Vec3<S> w = G_times(p, pd) * 2.0;
    const Vec3<S> wd = G_times(p, pdd) * 2.0;
    const Vec3<S> t = J * wd + cross(w, J * w);
    const Vec4<S> gp = GT_times(p, t);
    for (int i = 0; i < 4; ++i) r[3 + i] = gp[i] * 2.0;
  }
  double kinetic(const double* q, const double* v) const {
    const Vec4<double> p{{q[3], q[4], q[5], q[6]}}, pd{{v[3], v[4], v[5], v[6]}};
    const Vec3<double> w = G_times(p, pd) * 2.0;
    return 0.5 * m * (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]) + 0.5 * dot(w, J * w);
  }
  double potential(const double* q) const { return -m * (g[0] * q[0] + g[1] * q[1] + g[2] * q[2]); }
};

// ------------------------------------------------------------ spring-dampers --------
struct Spring {
  bool planar;
  BodyRef bi, bj;
  Vec3<double> si, sj;
  double k, c, l0;
  TimeFunction act;
  template <class S>
  void generalized_force(const Jet1<S>* z, double t, S* Q) const {
    using std::sqrt;
    using J = Jet1<S>;
    if (planar) {
      const Pose2<J> pi = pose2(bi, z), pj = pose2(bj, z);
      const Vec2<J> xi = pi.point({{si[0], si[1]}}), xj = pj.point({{sj[0], sj[1]}});
      const Vec2<J> d = xj - xi;
      const J l = sqrt(dot(d, d));
      const S f = (l.c0 - l0) * k + l.c1 * c + act(t);
      const Vec2<S> u = c0(d) * (1.0 / l.c0);
      add_wrench2(bj, c0(pj), c0(xj), u * (-f), S(0.0), Q);
      add_wrench2(bi, c0(pi), c0(xi), u * f, S(0.0), Q);
      return;
    }
    const Pose3<J> pi = pose3(bi, z), pj = pose3(bj, z);
    const Vec3<J> xi = pi.point(si), xj = pj.point(sj);
    const Vec3<J> d = xj - xi;
    const J l = sqrt(dot(d, d));
    const S f = (l.c0 - l0) * k + l.c1 * c + act(t);
    const Vec3<S> u = c0(d) * (1.0 / l.c0);
    add_wrench3(bj, c0(pj), c0(xj), u * (-f), zero<S, 3>(), Q);
    add_wrench3(bi, c0(pi), c0(xi), u * f, zero<S, 3>(), Q);
  }
  double potential(const double* q, double) const {
    Vec3<double> d;
    if (planar) {
      const auto a = pose2(bj, q).point({{sj[0], sj[1]}}) - pose2(bi, q).point({{si[0], si[1]}});
      d = {{a[0], a[1], 0}};
    } else {
      d = pose3(bj, q).point(sj) - pose3(bi, q).point(si);
    }
    const double e = norm(d) - l0;
    return 0.5 * k * e * e;
  }
};

struct RotationalSpring {
  bool planar;
  BodyRef bi, bj;
  Frame3 fi, fj;
  double k, c, theta0;
  TimeFunction act;
  template <class T>
  T angle(const T* z) const {
    using std::atan2;
    if (planar) return pose2(bj, z).phi - pose2(bi, z).phi - theta0;
    const Pose3<T> pi = pose3(bi, z), pj = pose3(bj, z);
    const Vec3<T> xj = pj.vec(fj.x);
    return atan2(dot(xj, pi.vec(fi.y)), dot(xj, pi.vec(fi.x))) - theta0;
  }
  template <class S>
  void generalized_force(const Jet1<S>* z, double t, S* Q) const {
    using J = Jet1<S>;
    const J th = angle(z);
    const S tau = -(th.c0 * k + th.c1 * c) + act(t);
    if (planar) {
      const Pose2<S> pi = c0(pose2(bi, z)), pj = c0(pose2(bj, z));
      add_wrench2(bj, pj, pj.r, zero<S, 2>(), tau, Q);
      add_wrench2(bi, pi, pi.r, zero<S, 2>(), -tau, Q);
      return;
    }
    const Pose3<S> pi = c0(pose3(bi, z)), pj = c0(pose3(bj, z));
    const Vec3<S> n = pi.vec(fi.z) * tau;
    add_wrench3(bj, pj, pj.r, zero<S, 3>(), n, Q);
    add_wrench3(bi, pi, pi.r, zero<S, 3>(), -n, Q);
  }
  double potential(const double* q, double) const {
    const double th = angle(q);
    return 0.5 * k * th * th;
  }
};

struct Bushing {
  BodyRef bi, bj;
  Frame3 fi, fj;
  std::array<double, 6> k, c;
  // Deformation δ (frame-i coordinates of frame j's origin) and rotation vector θ.
  template <class T>
  void deformation(const T* z, Vec3<T>& delta, Vec3<T>& theta, Vec3<T> axes[3], Vec3<T>& xj) const {
    const Pose3<T> pi = pose3(bi, z), pj = pose3(bj, z);
    axes[0] = pi.vec(fi.x);
    axes[1] = pi.vec(fi.y);
    axes[2] = pi.vec(fi.z);
    const Vec3<T> bx = pj.vec(fj.x), by = pj.vec(fj.y), bz = pj.vec(fj.z);
    xj = pj.point(fj.s);
    const Vec3<T> d = xj - pi.point(fi.s);
    for (int a = 0; a < 3; ++a) delta[a] = dot(axes[a], d);
    theta[0] = (dot(axes[2], by) - dot(axes[1], bz)) * 0.5;
    theta[1] = (dot(axes[0], bz) - dot(axes[2], bx)) * 0.5;
    theta[2] = (dot(axes[1], bx) - dot(axes[0], by)) * 0.5;
  }
  template <class S>
  void generalized_force(const Jet1<S>* z, double, S* Q) const {
    using J = Jet1<S>;
    Vec3<J> delta, theta, axes[3], xj;
    deformation(z, delta, theta, axes, xj);
    Vec3<S> f = zero<S, 3>(), n = zero<S, 3>();
    for (int a = 0; a < 3; ++a) {
      const S fa = -(delta[a].c0 * k[a] + delta[a].c1 * c[a]);
      const S ma = -(theta[a].c0 * k[3 + a] + theta[a].c1 * c[3 + a]);
      f = f + c0(axes[a]) * fa;
      n = n + c0(axes[a]) * ma;
    }
    const Vec3<S> x = c0(xj);
    add_wrench3(bj, c0(pose3(bj, z)), x, f, n, Q);
    add_wrench3(bi, c0(pose3(bi, z)), x, -f, -n, Q);
  }
  double potential(const double* q, double) const {
    Vec3<double> delta, theta, axes[3], xj;
    deformation(q, delta, theta, axes, xj);
    double e = 0;
    for (int a = 0; a < 3; ++a)
      e += 0.5 * (k[a] * delta[a] * delta[a] + k[3 + a] * theta[a] * theta[a]);
    return e;
  }
};

struct Load {
  bool planar;
  BodyRef b;
  Vec3<double> s, f, n;
  bool body_frame;
  TimeFunction scale;
  template <class S>
  void generalized_force(const Jet1<S>* z, double t, S* Q) const {
    const double sc = scale(t);
    if (planar) {
      const Pose2<S> p = c0(pose2(b, z));
      Vec2<S> fg = lift<S>(Vec2<double>{{f[0] * sc, f[1] * sc}});
      if (body_frame) fg = p.A * fg;
      add_wrench2(b, p, p.point({{s[0], s[1]}}), fg, S(n[2] * sc), Q);
      return;
    }
    const Pose3<S> p = c0(pose3(b, z));
    Vec3<S> fg = lift<S>(f * sc), ng = lift<S>(n * sc);
    if (body_frame) {
      fg = p.A * fg;
      ng = p.A * ng;
    }
    add_wrench3(b, p, p.point(s), fg, ng, Q);
  }
};

/// Normal force and regularised friction for penetration (c0 = δ, c1 = δ̇), unit normal
/// n and slip velocity vt (already tangential). Returns false when not in contact.
constexpr double kDampingDepth = 1e-3;  // m
constexpr double kOnsetDepth = 1e-4;    // m
template <class S, int N>
bool contact_force(const Jet1<S>& pen, const Vec<S, N>& n, const Vec<S, N>& vt, double k, double c,
                   double mu, double vs, Vec<S, N>& f) {
  using std::sqrt;
  if (value(pen.c0) <= 0) return false;
  // the damping grows over the first kDampingDepth of penetration, so that the normal
  // force is continuous at first contact (a jump there stalls Newton's method)
  const S ramp = value(pen.c0) < kDampingDepth ? pen.c0 * (1.0 / kDampingDepth) : S(1.0);
  // elastic part with a quadratic onset over kOnsetDepth: C¹ at first contact
  const S el = value(pen.c0) < kOnsetDepth ? pen.c0 * pen.c0 * (0.5 * k / kOnsetDepth)
                                           : (pen.c0 - 0.5 * kOnsetDepth) * k;
  const S fn = el + pen.c1 * ramp * c;
  if (value(fn) <= 0) return false;
  const S ft = fn * mu / sqrt(dot(vt, vt) + vs * vs);
  f = n * fn - vt * ft;
  return true;
}

struct GroundContact {
  bool planar;
  BodyRef b;
  Vec3<double> s, n;
  double r, h, k, c, mu, vs;
  double gap(const double* q) const {
    if (planar) {
      const auto x = pose2(b, q).point({{s[0], s[1]}});
      return x[0] * n[0] + x[1] * n[1] - h - r;
    }
    return dot(pose3(b, q).point(s), n) - h - r;
  }
  bool inactive(const double* q) const { return gap(q) >= 0; }
  double proximity(const double* q) const { return gap(q); }
  template <class S>
  void generalized_force(const Jet1<S>* z, double, S* Q) const {
    using J = Jet1<S>;
    if (planar) {
      const Vec2<double> n2{{n[0], n[1]}};
      const Pose2<J> p = pose2(b, z);
      const Vec2<J> x = p.point({{s[0], s[1]}});
      const J pen = -(dot(x, lift<J>(n2)) - h - r);
      const Pose2<S> p0 = c0(p);
      const Vec2<S> xc = c0(x) - lift<S>(n2) * r;
      const Vec2<S> vel = c1(p.r) + c1(p.A) * tmul(p0.A, xc - p0.r);
      const Vec2<S> ns = lift<S>(n2);
      const Vec2<S> vt = vel - ns * dot(ns, vel);
      Vec2<S> f;
      if (contact_force(pen, ns, vt, k, c, mu, vs, f)) add_wrench2(b, p0, xc, f, S(0.0), Q);
      return;
    }
    const Pose3<J> p = pose3(b, z);
    const Vec3<J> x = p.point(s);
    const J pen = -(dot(x, lift<J>(n)) - h - r);
    const Pose3<S> p0 = c0(p);
    const Vec3<S> ns = lift<S>(n);
    const Vec3<S> xc = c0(x) - ns * r;
    const Vec3<S> vel = c1(p.r) + c1(p.A) * tmul(p0.A, xc - p0.r);
    const Vec3<S> vt = vel - ns * dot(ns, vel);
    Vec3<S> f;
    if (contact_force(pen, ns, vt, k, c, mu, vs, f)) add_wrench3(b, p0, xc, f, zero<S, 3>(), Q);
  }
  double potential(const double* q, double) const {
    const double g = gap(q);
    return g < 0 ? 0.5 * k * g * g : 0.0;
  }
};

struct WheelContact {
  BodyRef bw, bb;
  Vec3<double> centre, axis, s;
  double R, hw, r, k, c, mu, vs;
  // Axial coordinate and distance from the wheel axis of the sphere centre.
  template <class T>
  void geometry(const T* z, Vec3<T>& C, Vec3<T>& a, T& zax, Vec3<T>& rho) const {
    const Pose3<T> pw = pose3(bw, z), pb = pose3(bb, z);
    C = pw.point(centre);
    a = pw.vec(axis);
    const Vec3<T> X = pb.point(s) - C;
    zax = dot(a, X);
    rho = X - a * zax;
  }
  bool inactive(const double* q) const {
    Vec3<double> C, a, rho;
    double zax;
    geometry(q, C, a, zax, rho);
    return std::abs(zax) > hw || norm(rho) >= R + r;
  }
  double proximity(const double* q) const {
    Vec3<double> C, a, rho;
    double zax;
    geometry(q, C, a, zax, rho);
    return std::max(norm(rho) - (R + r), std::abs(zax) - hw);
  }
  template <class S>
  void generalized_force(const Jet1<S>* z, double, S* Q) const {
    using std::sqrt;
    using J = Jet1<S>;
    Vec3<J> C, a, rho;
    J zax;
    geometry(z, C, a, zax, rho);
    const J dist = sqrt(dot(rho, rho));
    const J pen = (R + r) - dist;
    const Vec3<S> n = c0(rho) * (1.0 / dist.c0);
    const Vec3<S> xc = c0(C) + c0(a) * zax.c0 + n * R;
    const Pose3<J> pw = pose3(bw, z), pb = pose3(bb, z);
    const Pose3<S> w0 = c0(pw), b0 = c0(pb);
    const Vec3<S> vb = c1(pb.r) + c1(pb.A) * tmul(b0.A, xc - b0.r);
    const Vec3<S> vw = c1(pw.r) + c1(pw.A) * tmul(w0.A, xc - w0.r);
    const Vec3<S> vrel = vb - vw;
    const Vec3<S> vt = vrel - n * dot(n, vrel);
    Vec3<S> f;
    if (!contact_force(pen, n, vt, k, c, mu, vs, f)) return;
    add_wrench3(bb, b0, xc, f, zero<S, 3>(), Q);
    add_wrench3(bw, w0, xc, -f, zero<S, 3>(), Q);
  }
  double potential(const double* q, double) const {
    Vec3<double> C, a, rho;
    double zax;
    geometry(q, C, a, zax, rho);
    const double pen = R + r - norm(rho);
    return (pen > 0 && std::abs(zax) <= hw) ? 0.5 * k * pen * pen : 0.0;
  }
};

}  // namespace

std::unique_ptr<Force> make_body_inertia(const Model& m, int k) {
  const Body& b = m.bodies[k];
  std::vector<index_t> dofs;
  bind_bodies(m, {k}, dofs);
  std::unique_ptr<Force> f;
  if (b.kind == BodyKind::planar)
    f = std::make_unique<InertiaOf<PlanarBody, 3>>(PlanarBody{b.mass, b.inertia2, m.gravity});
  else
    f = std::make_unique<InertiaOf<SpatialBody, 7>>(SpatialBody{b.mass, b.inertia3, m.gravity});
  f->dofs = std::move(dofs);
  f->name = "bodies '" + b.name + "' (inertia)";
  f->conservative = true;
  return f;
}

std::unique_ptr<Force> make_spring_damper(const Model& m, const SpringSpec& s) {
  std::vector<index_t> dofs;
  auto refs = bind_bodies(m, {s.body_i, s.body_j}, dofs);
  Spring k{m.planar,    refs[0],   refs[1],       s.si,      s.sj,
           s.stiffness, s.damping, s.free_length, s.actuator};
  auto f = m.planar ? wrap_force<3, 6>(k, std::move(dofs), s.name)
                    : wrap_force<7, 14>(k, std::move(dofs), s.name);
  f->conservative = s.damping == 0 && s.actuator.is_zero();
  return f;
}

std::unique_ptr<Force> make_rotational_spring_damper(const Model& m,
                                                     const RotationalSpringSpec& s) {
  std::vector<index_t> dofs;
  auto refs = bind_bodies(m, {s.body_i, s.body_j}, dofs);
  RotationalSpring k{m.planar,    refs[0],   refs[1],     s.fi,      s.fj,
                     s.stiffness, s.damping, s.reference, s.actuator};
  auto f = m.planar ? wrap_force<3, 6>(k, std::move(dofs), s.name)
                    : wrap_force<7, 14>(k, std::move(dofs), s.name);
  f->conservative = s.damping == 0 && s.actuator.is_zero();
  return f;
}

std::unique_ptr<Force> make_bushing(const Model& m, const BushingSpec& s) {
  if (m.planar) throw ModelError(s.name + ": bushings exist only in spatial models");
  std::vector<index_t> dofs;
  auto refs = bind_bodies(m, {s.body_i, s.body_j}, dofs);
  Bushing k{refs[0], refs[1], s.fi, s.fj, s.stiffness, s.damping};
  auto f = wrap_force<7, 14>(k, std::move(dofs), s.name);
  f->conservative = true;
  for (double c : s.damping) f->conservative &= c == 0;
  return f;
}

std::unique_ptr<Force> make_load(const Model& m, const LoadSpec& s) {
  std::vector<index_t> dofs;
  auto refs = bind_bodies(m, {s.body}, dofs);
  Load k{m.planar, refs[0], s.point, s.force, s.torque, s.body_frame, s.scale};
  auto f = m.planar ? wrap_force<3>(k, std::move(dofs), s.name)
                    : wrap_force<7>(k, std::move(dofs), s.name);
  f->uses_v = false;
  return f;
}

std::unique_ptr<Force> make_ground_contact(const Model& m, const ContactSpec& s) {
  std::vector<index_t> dofs;
  auto refs = bind_bodies(m, {s.body}, dofs);
  Vec3<double> n = s.normal;
  const double len = m.planar ? std::hypot(n[0], n[1]) : norm(n);
  n = n * (1.0 / len);
  GroundContact k{m.planar, refs[0],     s.point,   n,          s.radius,
                  s.offset, s.stiffness, s.damping, s.friction, s.slip_velocity};
  auto f = m.planar ? wrap_force<3>(k, std::move(dofs), s.name)
                    : wrap_force<7>(k, std::move(dofs), s.name);
  f->intermittent = true;
  return f;
}

std::unique_ptr<Force> make_wheel_contact(const Model& m, const WheelContactSpec& s) {
  if (m.planar) throw ModelError(s.name + ": wheel contact exists only in spatial models");
  std::vector<index_t> dofs;
  auto refs = bind_bodies(m, {s.wheel, s.body}, dofs);
  WheelContact k{refs[0],     refs[1],        s.centre,     s.axis * (1.0 / norm(s.axis)),
                 s.point,     s.wheel_radius, s.half_width, s.radius,
                 s.stiffness, s.damping,      s.friction,   s.slip_velocity};
  auto f = wrap_force<7, 14>(k, std::move(dofs), s.name);
  f->intermittent = true;
  f->margin = s.margin;
  return f;
}

}  // namespace strata::mbd
