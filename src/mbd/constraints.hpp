// strata::mbd — joints and driving constraints built from the basic constraints of
// Haug, "Computer-Aided Kinematics and Dynamics of Mechanical Systems" (1989):
// planar (§3.3–3.5): revolute, translational, fixed, distance, rotational and
// translational drivers; spatial (§9.2–9.4): dot-1 (aᵢᵀaⱼ = 0), dot-2 (aᵢᵀdᵢⱼ = 0),
// spherical (dᵢⱼ = 0) and the joints composed of them — spherical, revolute,
// universal, cylindrical, translational, fixed — plus rotational/translational drivers
// (§9.5), the Euler-parameter normalisation pᵀp − 1 = 0 (§9.6) and the attachment of a
// flexible-body node to a rigid body.
//
// Every kernel is a plain struct with `NR` equations and a templated `phi(z, t, out)`;
// wrap_constraint turns it into a Constraint whose Jacobians come from autodiff.hpp.
// A joint frame on body k is a body-fixed point s and orthonormal axes (x, y, z); the
// joint axis is z.
#pragma once

#include <memory>
#include <stdexcept>
#include <string>
#include <utility>

#include "mbd/model.hpp"

namespace strata::mbd {

/// A constraint from a kernel K (see the file comment).
template <class K, int NZ>
class ConstraintOf : public ConstraintT<ConstraintOf<K, NZ>, NZ> {
 public:
  static constexpr int NR = K::NR;
  explicit ConstraintOf(K k) : k_(std::move(k)) { this->rows = NR; }
  template <class T>
  void phi(const T* z, const T& t, T* out) const {
    k_.phi(z, t, out);
  }
  K k_;
};

/// Wraps kernel K into a Constraint for a local vector of dofs.size() coordinates; the
/// allowed sizes are the template arguments. Throws ModelError otherwise.
template <int... Sizes, class K>
std::unique_ptr<Constraint> wrap_constraint(K k, std::vector<index_t> dofs, std::string name) {
  std::unique_ptr<Constraint> c;
  const int nz = static_cast<int>(dofs.size());
  ((nz == Sizes ? (c = std::make_unique<ConstraintOf<K, Sizes>>(k), 0) : 0), ...);
  if (!c) {
    if (nz == 0) throw ModelError(name + ": connects two bodies that do not move");
    throw ModelError(name + ": unsupported combination of bodies (" + std::to_string(nz) +
                     " coordinates)");
  }
  c->dofs = std::move(dofs);
  c->name = std::move(name);
  return c;
}

/// Body-fixed joint frame: origin s and axes x, y, z (joint axis z), body coordinates.
struct Frame3 {
  Vec3<double> s{}, x{{1, 0, 0}}, y{{0, 1, 0}}, z{{0, 0, 1}};
};
/// A planar joint frame: point s and unit direction u (translational axis), body coords.
struct Frame2 {
  Vec2<double> s{}, u{{1, 0}};
};

/// Types of joints and drivers the model format knows.
enum class JointType {
  revolute,
  translational,
  fixed,
  spherical,
  universal,
  cylindrical,
  distance,
  rotation_driver,
  translation_driver
};

/// Everything a joint needs, resolved to body-fixed quantities.
struct JointSpec {
  JointType type = JointType::revolute;
  std::string name;  ///< for messages, e.g. "joints[3] 'J4'"
  int body_i = 0, body_j = 0;
  Frame3 fi, fj;         ///< spatial frames (planar joints use s and x of these)
  double reference = 0;  ///< initial relative angle / displacement / distance
  TimeFunction motion;   ///< drivers: value = reference + motion(t)
};

/// Builds the constraint of a joint or driver of a planar or spatial model.
std::unique_ptr<Constraint> make_joint(const Model& model, const JointSpec& spec);

/// The normalisation constraint pᵀp − 1 = 0 of spatial body k.
std::unique_ptr<Constraint> make_normalization(const Model& model, int k);

/// Attaches the node `node` (a body of kind node) to the body-fixed point s of body k
/// (3 equations: r_node − (r_k + A_k s) = 0).
std::unique_ptr<Constraint> make_node_attachment(const Model& model, int node, int k,
                                                 const Vec3<double>& s, std::string name);

}  // namespace strata::mbd
