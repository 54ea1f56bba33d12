// strata::mbd — constraint kernels (see constraints.hpp for sources). Each kernel states
// its equations; signs follow Haug (1989): dᵢⱼ = (rⱼ + Aⱼsⱼ) − (rᵢ + Aᵢsᵢ).
#include "mbd/constraints.hpp"

namespace strata::mbd {
namespace {

// ------------------------------------------------------------------- planar --------
Vec2<double> xy(const Vec3<double>& v) { return {{v[0], v[1]}}; }

struct PlanarPair {
  BodyRef bi, bj;
  Vec2<double> si, sj, ui;
  template <class T>
  void poses(const T* z, Pose2<T>& pi, Pose2<T>& pj) const {
    pi = pose2(bi, z);
    pj = pose2(bj, z);
  }
};

/// Revolute: dᵢⱼ = 0 (Haug Eq. 3.3.10).
struct PlanarRevolute : PlanarPair {
  static constexpr int NR = 2;
  template <class T>
  void phi(const T* z, const T&, T* o) const {
    Pose2<T> pi, pj;
    poses(z, pi, pj);
    const Vec2<T> d = pj.point(sj) - pi.point(si);
    o[0] = d[0];
    o[1] = d[1];
  }
};
/// Translational: (R uᵢ)ᵀ dᵢⱼ = 0 and φⱼ − φᵢ − θ₀ = 0 (Haug Eq. 3.3.13–14).
struct PlanarTranslational : PlanarPair {
  static constexpr int NR = 2;
  double theta0 = 0;
  template <class T>
  void phi(const T* z, const T&, T* o) const {
    Pose2<T> pi, pj;
    poses(z, pi, pj);
    const Vec2<T> d = pj.point(sj) - pi.point(si);
    o[0] = dot(perp(pi.vec(ui)), d);
    o[1] = pj.phi - pi.phi - theta0;
  }
};
/// Fixed (weld): dᵢⱼ = 0 and φⱼ − φᵢ − θ₀ = 0.
struct PlanarFixed : PlanarPair {
  static constexpr int NR = 3;
  double theta0 = 0;
  template <class T>
  void phi(const T* z, const T&, T* o) const {
    Pose2<T> pi, pj;
    poses(z, pi, pj);
    const Vec2<T> d = pj.point(sj) - pi.point(si);
    o[0] = d[0];
    o[1] = d[1];
    o[2] = pj.phi - pi.phi - theta0;
  }
};
/// Distance: ½(dᵢⱼᵀdᵢⱼ − L²) = 0 (Haug Eq. 3.3.8).
struct PlanarDistance : PlanarPair {
  static constexpr int NR = 1;
  double length = 0;
  template <class T>
  void phi(const T* z, const T&, T* o) const {
    Pose2<T> pi, pj;
    poses(z, pi, pj);
    const Vec2<T> d = pj.point(sj) - pi.point(si);
    o[0] = (dot(d, d) - length * length) * 0.5;
  }
};
/// Relative rotation driver: φⱼ − φᵢ − (θ₀ + f(t)) = 0 (Haug Eq. 3.5.1).
struct PlanarRotationDriver : PlanarPair {
  static constexpr int NR = 1;
  double theta0 = 0;
  TimeFunction f;
  template <class T>
  void phi(const T* z, const T& t, T* o) const {
    Pose2<T> pi, pj;
    poses(z, pi, pj);
    o[0] = pj.phi - pi.phi - (f(t) + theta0);
  }
};
/// Relative translation driver along uᵢ: uᵢᵀdᵢⱼ − (d₀ + f(t)) = 0 (Haug Eq. 3.5.3).
struct PlanarTranslationDriver : PlanarPair {
  static constexpr int NR = 1;
  double d0 = 0;
  TimeFunction f;
  template <class T>
  void phi(const T* z, const T& t, T* o) const {
    Pose2<T> pi, pj;
    poses(z, pi, pj);
    o[0] = dot(pi.vec(ui), pj.point(sj) - pi.point(si)) - (f(t) + d0);
  }
};

// ------------------------------------------------------------------ spatial --------
// A spatial body's pose in doubles with the derivatives of A(p) with respect to its Euler
// parameters (rot3's entries are quadratic forms in p: Haug 1989, Eq. 6.3.20), giving its
// points and vectors as dual numbers whose derivative lanes are the body's coordinates
// local … local+6 (r, then p), for duals seeded with the unit directions of the
// constraint's local coordinates. The values are computed as pose3's are (the same
// operations in the same order).
template <int N>
class PoseLanes {
 public:
  using D = Dual<double, N>;
  PoseLanes(const BodyRef& b, const D* z) : moving_(b.moving()), local_(b.local) {
    Vec4<double> p;
    if (moving_) {
      for (int i = 0; i < 3; ++i) r_[i] = z[local_ + i].v;
      for (int i = 0; i < 4; ++i) p[i] = z[local_ + 3 + i].v;
    } else {
      r_ = b.r;
      p = b.p;
    }
    a_ = rot3(p);
    if (!moving_) return;
    const double e0 = 2 * p[0], e1 = 2 * p[1], e2 = 2 * p[2], e3 = 2 * p[3];
    // ∂a_ij/∂e_k, k = 0..3, row by row
    const double da[3][3][4] = {{{e0, e1, -e2, -e3}, {-e3, e2, e1, -e0}, {e2, e3, e0, e1}},
                                {{e3, e2, e1, e0}, {e0, -e1, e2, -e3}, {-e1, -e0, e3, e2}},
                                {{-e2, e3, -e0, e1}, {e1, e0, e3, e2}, {e0, -e1, -e2, e3}}};
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j)
        for (int k = 0; k < 4; ++k) da_[k](i, j) = da[i][j][k];
  }
  /// A u, and its derivatives in the Euler parameters' lanes.
  Vec3<D> vec(const Vec3<double>& u) const {
    const Vec3<double> v = a_ * u;
    Vec3<D> out;
    for (int i = 0; i < 3; ++i) out[i].v = v[i];
    if (!moving_) return out;
    for (int k = 0; k < 4; ++k) {
      const Vec3<double> dv = da_[k] * u;
      for (int i = 0; i < 3; ++i) out[i].d[local_ + 3 + k] = dv[i];
    }
    return out;
  }
  /// r + A s, and its derivatives (the identity in the position lanes).
  Vec3<D> point(const Vec3<double>& s) const {
    Vec3<D> out = vec(s);
    for (int i = 0; i < 3; ++i) out[i].v = r_[i] + out[i].v;
    if (moving_)
      for (int i = 0; i < 3; ++i) out[i].d[local_ + i] = 1.0;
    return out;
  }

 private:
  bool moving_;
  int local_;
  Vec3<double> r_{};
  Mat3<double> a_{};
  Mat3<double> da_[4]{};
};

// Whether the body's coordinates in z are seeded with their own unit directions (the
// gradient pass of ConstraintT::evaluate_gradient), the condition of PoseLanes.
template <int N>
bool unit_seeded(const BodyRef& b, const Dual<double, N>* z) {
  if (!b.moving()) return true;
  if (b.local < 0 || b.local + 7 > N) return false;
  for (int c = b.local; c < b.local + 7; ++c)
    for (int k = 0; k < N; ++k)
      if (z[c].d[k] != (k == c ? 1.0 : 0.0)) return false;
  return true;
}

struct SpatialPair {
  BodyRef bi, bj;
  Frame3 fi, fj;
  template <class T>
  struct Kin {
    Vec3<T> d, xi, yi, zi, xj, yj, zj;
  };
  template <class T>
  Kin<T> kin(const T* z) const {
    return kin_of<T>(pose3(bi, z), pose3(bj, z));
  }
  // The gradient pass: the rotations' derivatives in doubles (PoseLanes) rather than dual
  // arithmetic through A(p), most of a residual evaluation's time in the joints.
  template <int N>
  Kin<Dual<double, N>> kin(const Dual<double, N>* z) const {
    if (!unit_seeded(bi, z) || !unit_seeded(bj, z)) return kin<Dual<double, N>>(z);
    return kin_of<Dual<double, N>>(PoseLanes<N>(bi, z), PoseLanes<N>(bj, z));
  }
  // The joint frames' points and axes from the bodies' poses (Pose3 or PoseLanes).
  template <class T, class Pose>
  Kin<T> kin_of(const Pose& pi, const Pose& pj) const {
    return {pj.point(fj.s) - pi.point(fi.s),
            pi.vec(fi.x),
            pi.vec(fi.y),
            pi.vec(fi.z),
            pj.vec(fj.x),
            pj.vec(fj.y),
            pj.vec(fj.z)};
  }
};
/// Spherical: dᵢⱼ = 0 (Haug Eq. 9.4.1).
struct Spherical : SpatialPair {
  static constexpr int NR = 3;
  template <class T>
  void phi(const T* z, const T&, T* o) const {
    const auto k = kin(z);
    for (int i = 0; i < 3; ++i) o[i] = k.d[i];
  }
};
/// Revolute: spherical + dot-1(xᵢ, zⱼ) + dot-1(yᵢ, zⱼ) (Haug Eq. 9.4.11).
struct Revolute : SpatialPair {
  static constexpr int NR = 5;
  template <class T>
  void phi(const T* z, const T&, T* o) const {
    const auto k = kin(z);
    for (int i = 0; i < 3; ++i) o[i] = k.d[i];
    o[3] = dot(k.xi, k.zj);
    o[4] = dot(k.yi, k.zj);
  }
};
/// Universal: spherical + dot-1(zᵢ, zⱼ), the two cross axes (Haug Eq. 9.4.9).
struct Universal : SpatialPair {
  static constexpr int NR = 4;
  template <class T>
  void phi(const T* z, const T&, T* o) const {
    const auto k = kin(z);
    for (int i = 0; i < 3; ++i) o[i] = k.d[i];
    o[3] = dot(k.zi, k.zj);
  }
};
/// Cylindrical: dot-1(xᵢ, zⱼ), dot-1(yᵢ, zⱼ), dot-2(xᵢ, dᵢⱼ), dot-2(yᵢ, dᵢⱼ) (Haug Eq. 9.4.13).
struct Cylindrical : SpatialPair {
  static constexpr int NR = 4;
  template <class T>
  void phi(const T* z, const T&, T* o) const {
    const auto k = kin(z);
    o[0] = dot(k.xi, k.zj);
    o[1] = dot(k.yi, k.zj);
    o[2] = dot(k.xi, k.d);
    o[3] = dot(k.yi, k.d);
  }
};
/// Translational: cylindrical + dot-1(xᵢ, yⱼ) (Haug Eq. 9.4.15).
struct Translational : SpatialPair {
  static constexpr int NR = 5;
  template <class T>
  void phi(const T* z, const T&, T* o) const {
    const auto k = kin(z);
    o[0] = dot(k.xi, k.zj);
    o[1] = dot(k.yi, k.zj);
    o[2] = dot(k.xi, k.d);
    o[3] = dot(k.yi, k.d);
    o[4] = dot(k.xi, k.yj);
  }
};
/// Fixed: spherical + dot-1(xᵢ, yⱼ), dot-1(yᵢ, zⱼ), dot-1(zᵢ, xⱼ).
struct Fixed : SpatialPair {
  static constexpr int NR = 6;
  template <class T>
  void phi(const T* z, const T&, T* o) const {
    const auto k = kin(z);
    for (int i = 0; i < 3; ++i) o[i] = k.d[i];
    o[3] = dot(k.xi, k.yj);
    o[4] = dot(k.yi, k.zj);
    o[5] = dot(k.zi, k.xj);
  }
};
/// Distance: ½(dᵢⱼᵀdᵢⱼ − L²) = 0 (Haug Eq. 9.4.5).
struct Distance : SpatialPair {
  static constexpr int NR = 1;
  double length = 0;
  template <class T>
  void phi(const T* z, const T&, T* o) const {
    const auto k = kin(z);
    o[0] = (dot(k.d, k.d) - length * length) * 0.5;
  }
};
/// Rotation driver about zᵢ: xⱼᵀ(yᵢ cos θ − xᵢ sin θ) = 0 with θ = θ₀ + f(t), i.e.
/// sin(θ_actual − θ) = 0 for the angle θ_actual of xⱼ measured from xᵢ about zᵢ
/// (Haug §9.5.1). Use with a revolute or cylindrical joint on the same frames.
struct RotationDriver : SpatialPair {
  static constexpr int NR = 1;
  double theta0 = 0;
  TimeFunction f;
  template <class T>
  void phi(const T* z, const T& t, T* o) const {
    using std::cos, std::sin;
    const auto k = kin(z);
    const T th = f(t) + theta0;
    o[0] = dot(k.xj, k.yi) * cos(th) - dot(k.xj, k.xi) * sin(th);
  }
};
/// Translation driver along zᵢ: zᵢᵀdᵢⱼ − (d₀ + f(t)) = 0 (Haug §9.5.2).
struct TranslationDriver : SpatialPair {
  static constexpr int NR = 1;
  double d0 = 0;
  TimeFunction f;
  template <class T>
  void phi(const T* z, const T& t, T* o) const {
    const auto k = kin(z);
    o[0] = dot(k.zi, k.d) - (f(t) + d0);
  }
};
/// Euler-parameter normalisation: pᵀp − 1 = 0 (Haug Eq. 9.6.1).
struct Normalization {
  static constexpr int NR = 1;
  template <class T>
  void phi(const T* z, const T&, T* o) const {
    o[0] = z[3] * z[3] + z[4] * z[4] + z[5] * z[5] + z[6] * z[6] - 1.0;
  }
};
/// Node attachment: r_node − (r_k + A_k s) = 0.
struct NodeAttachment {
  static constexpr int NR = 3;
  BodyRef node, body;
  Vec3<double> s;
  template <class T>
  void phi(const T* z, const T&, T* o) const {
    const Vec3<T> d = node_position(node, z) - pose3(body, z).point(s);
    for (int i = 0; i < 3; ++i) o[i] = d[i];
  }
};

template <class K>
std::unique_ptr<Constraint> planar(K k, const Model& m, const JointSpec& s) {
  std::vector<index_t> dofs;
  auto refs = bind_bodies(m, {s.body_i, s.body_j}, dofs);
  k.bi = refs[0];
  k.bj = refs[1];
  k.si = xy(s.fi.s);
  k.sj = xy(s.fj.s);
  k.ui = xy(s.fi.x);
  auto c = wrap_constraint<3, 6>(std::move(k), std::move(dofs), s.name);
  c->reaction_dim = 2;
  c->reaction_local = refs[1].moving() ? refs[1].local : refs[0].local;
  return c;
}
template <class K>
std::unique_ptr<Constraint> spatial(K k, const Model& m, const JointSpec& s) {
  std::vector<index_t> dofs;
  auto refs = bind_bodies(m, {s.body_i, s.body_j}, dofs);
  k.bi = refs[0];
  k.bj = refs[1];
  k.fi = s.fi;
  k.fj = s.fj;
  auto c = wrap_constraint<7, 14>(std::move(k), std::move(dofs), s.name);
  c->reaction_dim = 3;
  c->reaction_local = refs[1].moving() ? refs[1].local : refs[0].local;
  return c;
}

}  // namespace

namespace {
std::unique_ptr<Constraint> make_joint_element(const Model& m, const JointSpec& s);
}  // namespace

std::unique_ptr<Constraint> make_joint(const Model& m, const JointSpec& s) {
  auto c = make_joint_element(m, s);
  c->rheonomic = s.type == JointType::rotation_driver || s.type == JointType::translation_driver;
  return c;
}

namespace {
std::unique_ptr<Constraint> make_joint_element(const Model& m, const JointSpec& s) {
  for (int b : {s.body_i, s.body_j})
    if (m.bodies[b].kind == BodyKind::node)
      throw ModelError(s.name + ": '" + m.bodies[b].name +
                       "' is a flexible-body node; attach nodes with the flexible body's "
                       "\"attachments\"");
  if (s.body_i == s.body_j)
    throw ModelError(s.name + ": body_i and body_j are the same body '" + m.bodies[s.body_i].name +
                     "'");
  if (m.planar) {
    switch (s.type) {
      case JointType::revolute:
        return planar(PlanarRevolute{}, m, s);
      case JointType::translational: {
        PlanarTranslational k;
        k.theta0 = s.reference;
        return planar(k, m, s);
      }
      case JointType::fixed: {
        PlanarFixed k;
        k.theta0 = s.reference;
        return planar(k, m, s);
      }
      case JointType::distance: {
        PlanarDistance k;
        k.length = s.reference;
        return planar(k, m, s);
      }
      case JointType::rotation_driver: {
        PlanarRotationDriver k;
        k.theta0 = s.reference;
        k.f = s.motion;
        return planar(k, m, s);
      }
      case JointType::translation_driver: {
        PlanarTranslationDriver k;
        k.d0 = s.reference;
        k.f = s.motion;
        return planar(k, m, s);
      }
      default:
        throw ModelError(s.name + ": this joint type exists only in spatial models");
    }
  }
  switch (s.type) {
    case JointType::revolute:
      return spatial(Revolute{}, m, s);
    case JointType::spherical:
      return spatial(Spherical{}, m, s);
    case JointType::universal:
      return spatial(Universal{}, m, s);
    case JointType::cylindrical:
      return spatial(Cylindrical{}, m, s);
    case JointType::translational:
      return spatial(Translational{}, m, s);
    case JointType::fixed:
      return spatial(Fixed{}, m, s);
    case JointType::distance: {
      Distance k;
      k.length = s.reference;
      return spatial(k, m, s);
    }
    case JointType::rotation_driver: {
      RotationDriver k;
      k.theta0 = s.reference;
      k.f = s.motion;
      return spatial(k, m, s);
    }
    case JointType::translation_driver: {
      TranslationDriver k;
      k.d0 = s.reference;
      k.f = s.motion;
      return spatial(k, m, s);
    }
  }
  throw ModelError(s.name + ": unknown joint type");
}
}  // namespace

std::unique_ptr<Constraint> make_normalization(const Model& m, int k) {
  std::vector<index_t> dofs;
  bind_bodies(m, {k}, dofs);
  return wrap_constraint<7>(Normalization{}, std::move(dofs),
                            "bodies '" + m.bodies[k].name + "' (Euler-parameter normalisation)");
}

std::unique_ptr<Constraint> make_node_attachment(const Model& m, int node, int k,
                                                 const Vec3<double>& s, std::string name) {
  std::vector<index_t> dofs;
  auto refs = bind_bodies(m, {node, k}, dofs);
  NodeAttachment a{};
  a.node = refs[0];
  a.body = refs[1];
  a.s = s;
  return wrap_constraint<3, 10>(std::move(a), std::move(dofs), std::move(name));
}

}  // namespace strata::mbd
