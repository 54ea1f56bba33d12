// strata::mbd — inertia and force elements.
//
// Body inertia (with gravity): planar, g = [m(ẍ,ÿ) − m g; J φ̈] (Nikravesh 1988, §6.3);
// spatial with Euler parameters, g_r = m r̈ − m g, g_p = 2Gᵀ(J′ω̇′ + ω̃′J′ω′) with
// ω′ = 2Gṗ, ω̇′ = 2Gp̈ (Haug 1989, Eq. 11.1.24: the Newton–Euler equations premultiplied
// by 2Gᵀ). Forces (Haug §11.4, Nikravesh §6.6): translational spring-damper-actuator,
// rotational spring-damper(-actuator), bushing (6-DOF linear spring-damper between two
// frames), applied forces/torques, penalty contact of a sphere with the ground plane and
// of a sphere with a cylinder (wheel) with regularised Coulomb friction.
// Generalized forces of spatial bodies are Q_p = 2Gᵀn′ (Haug Eq. 11.1.17).
#pragma once

#include <array>
#include <memory>
#include <string>
#include <utility>

#include "mbd/constraints.hpp"
#include "mbd/model.hpp"

namespace strata::mbd {

/// A force element from a kernel K with `template <class S> void generalized_force(const
/// Jet1<S>* z, double t, S* Q) const`, optionally `bool inactive(const double* q) const`
/// and `double potential(const double* q, double t) const`.
template <class K, int NZ>
class ForceOf : public ForceT<ForceOf<K, NZ>, NZ> {
 public:
  explicit ForceOf(K k) : k_(std::move(k)) {}
  template <class S>
  void generalized_force(const Jet1<S>* z, double t, S* Q) const {
    for (int i = 0; i < NZ; ++i) Q[i] = S(0.0);
    k_.generalized_force(z, t, Q);
  }
  bool inactive(const double* q) const {
    if constexpr (requires { k_.inactive(q); })
      return k_.inactive(q);
    else
      return false;
  }
  double proximity(const double* q) const override {
    if constexpr (requires { k_.proximity(q); })
      return k_.proximity(q);
    else
      return -1;
  }
  double potential_energy(const double* q, double t) const override {
    if constexpr (requires { k_.potential(q, t); })
      return k_.potential(q, t);
    else
      return 0.0;
  }
  K k_;
};

template <int... Sizes, class K>
std::unique_ptr<Force> wrap_force(K k, std::vector<index_t> dofs, std::string name) {
  std::unique_ptr<Force> f;
  const int nz = static_cast<int>(dofs.size());
  ((nz == Sizes ? (f = std::make_unique<ForceOf<K, Sizes>>(k), 0) : 0), ...);
  if (!f) {
    if (nz == 0) throw ModelError(name + ": acts only on bodies that do not move");
    throw ModelError(name + ": unsupported combination of bodies (" + std::to_string(nz) +
                     " coordinates)");
  }
  f->dofs = std::move(dofs);
  f->name = std::move(name);
  return f;
}

/// Inertia and gravity of rigid body k.
std::unique_ptr<Force> make_body_inertia(const Model& model, int k);

struct SpringSpec {
  std::string name;
  int body_i = 0, body_j = 0;
  Vec3<double> si{}, sj{};  ///< attachment points, body coordinates (m)
  double stiffness = 0;     ///< N/m
  double damping = 0;       ///< N s/m
  double free_length = 0;   ///< m
  TimeFunction actuator;    ///< actuator force (N), tension positive
};
/// Translational spring-damper-actuator: tension f = k(l − l₀) + c l̇ + F(t) pulls the
/// two points together (Haug Eq. 11.4.3).
std::unique_ptr<Force> make_spring_damper(const Model& model, const SpringSpec& spec);

struct RotationalSpringSpec {
  std::string name;
  int body_i = 0, body_j = 0;
  Frame3 fi, fj;          ///< spatial: rotation about zᵢ, angle of xⱼ from xᵢ
  double stiffness = 0;   ///< N m/rad
  double damping = 0;     ///< N m s/rad
  double reference = 0;   ///< angle at which the spring is free (rad)
  TimeFunction actuator;  ///< actuator torque on body j about the axis (N m)
};
/// Rotational spring-damper-actuator: torque on j about the axis
/// −k(θ − θ₀) − c θ̇ + T(t), the opposite on i.
std::unique_ptr<Force> make_rotational_spring_damper(const Model& model,
                                                     const RotationalSpringSpec& spec);

struct BushingSpec {
  std::string name;
  int body_i = 0, body_j = 0;
  Frame3 fi, fj;
  std::array<double, 6> stiffness{};  ///< kx, ky, kz (N/m), krx, kry, krz (N m/rad)
  std::array<double, 6> damping{};    ///< matching dampings
};
/// Bushing: in frame i, F = −K_t δ − C_t δ̇ with δ the position of frame j's origin, and
/// M = −K_r θ − C_r θ̇ with θ the small-angle rotation vector of frame j relative to frame
/// i (θ = vee((R − Rᵀ)/2), R = Fᵢᵀ Fⱼ); F, M act on j at its origin, −F, −M on i there.
std::unique_ptr<Force> make_bushing(const Model& model, const BushingSpec& spec);

struct LoadSpec {
  std::string name;
  int body = 0;
  Vec3<double> point{};     ///< body coordinates
  Vec3<double> force{};     ///< N (planar: x, y)
  Vec3<double> torque{};    ///< N m (planar: z component)
  bool body_frame = false;  ///< force and torque given in body coordinates
  TimeFunction scale = TimeFunction::constant(1.0);
};
/// Applied force and torque, scaled by a function of time.
std::unique_ptr<Force> make_load(const Model& model, const LoadSpec& spec);

struct ContactSpec {
  std::string name;
  int body = 0;
  Vec3<double> point{};            ///< sphere centre, body coordinates
  double radius = 0;               ///< m
  Vec3<double> normal{{0, 0, 1}};  ///< ground plane normal (planar: x, y)
  double offset = 0;               ///< plane: normalᵀx = offset
  double stiffness = 0, damping = 0, friction = 0;
  double slip_velocity = 1e-2;  ///< regularisation speed of the friction law (m/s)
};
/// Penalty contact of a sphere (planar: a disc) with the ground plane: normal force
/// max(0, e(δ) + c s(δ) δ̇) with e(δ) = kδ (after a quadratic onset over the first 0.1 mm)
/// and s(δ) = min(1, δ / 1 mm), so that the force is C¹/C⁰ at first contact; friction −μ f_n
/// v_t/√(|v_t|² + v_s²) at the contact point.
std::unique_ptr<Force> make_ground_contact(const Model& model, const ContactSpec& spec);

struct WheelContactSpec {
  std::string name;
  int wheel = 0;
  Vec3<double> centre{}, axis{{0, 1, 0}};  ///< wheel body coordinates
  double wheel_radius = 0, half_width = 0;
  int body = 0;
  Vec3<double> point{};  ///< sphere centre on `body`
  double radius = 0;
  double stiffness = 0, damping = 0, friction = 0, slip_velocity = 1e-2;
  /// The pair enters the Newton matrix only while the surfaces are closer than this (m);
  /// 0: always. A positive margin keeps the matrix sparse when a body can touch many
  /// wheels but touches few at a time (tracks).
  double margin = 0;
};
/// Penalty contact of a sphere with the outer surface of a cylinder (a wheel) on another
/// body (spatial only); same force law as make_ground_contact.
std::unique_ptr<Force> make_wheel_contact(const Model& model, const WheelContactSpec& spec);

}  // namespace strata::mbd
