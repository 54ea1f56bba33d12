// strata::mbd — a multibody model: bodies, their coordinates, constraints and forces.
//
// Coordinates (Haug 1989, ch. 6 and 9; Nikravesh 1988): a planar rigid body has
// q = (x, y, φ) of its centre of mass; a spatial rigid body has q = (r, p), the position
// of its centre of mass and Euler parameters p (with the normalisation constraint
// pᵀp = 1, added as a constraint of its own); a node of a flexible body has its
// absolute position (3 coordinates). Ground and bodies marked fixed have no coordinates.
// Units: SI throughout (m, kg, s, N, rad).
#pragma once

#include <map>
#include <memory>
#include <string>
#include <vector>

#include "mbd/elements.hpp"
#include "mbd/linalg.hpp"
#include "strata/errors.hpp"

namespace strata::mbd {

/// A model file or generator input is wrong. what() starts with the JSON path of the
/// offending value, e.g. "joints[3].body_j: unknown body 'wheel7'".
class ModelError : public InvalidInput {
 public:
  using InvalidInput::InvalidInput;
};

/// A scalar function of time, smooth enough (C²) for driving constraints.
struct TimeFunction {
  enum class Kind { polynomial, harmonic, smooth_ramp };
  Kind kind = Kind::polynomial;
  std::vector<double> coefficients{0.0};                   ///< polynomial: Σ c_k t^k
  double amplitude = 0, omega = 0, phase = 0, offset = 0;  ///< harmonic: off + A sin(ωt+φ)
  double rate = 0, ramp_time = 1;  ///< smooth_ramp: slope `rate` reached at ramp_time (C²)

  static TimeFunction constant(double c) { return TimeFunction{Kind::polynomial, {c}}; }
  /// Identically zero (the default of actuators).
  bool is_zero() const {
    if (kind == Kind::harmonic) return amplitude == 0 && offset == 0;
    if (kind == Kind::smooth_ramp) return rate == 0 && offset == 0;
    for (double c : coefficients)
      if (c != 0) return false;
    return true;
  }

  template <class T>
  T operator()(const T& t) const {
    using std::sin;
    switch (kind) {
      case Kind::polynomial: {
        T r(coefficients.back());
        for (int k = static_cast<int>(coefficients.size()) - 2; k >= 0; --k)
          r = r * t + coefficients[k];
        return r;
      }
      case Kind::harmonic:
        return sin(t * omega + phase) * amplitude + offset;
      case Kind::smooth_ramp: {
        if (value(t) <= 0) return T(offset);
        if (value(t) >= ramp_time) return (t - 0.5 * ramp_time) * rate + offset;
        const T x = t / ramp_time;  // ∫ (3x² − 2x³) = x³ − x⁴/2
        return (x * x * x - x * x * x * x * 0.5) * (rate * ramp_time) + offset;
      }
    }
    return T(0.0);
  }
};

enum class BodyKind { ground, planar, spatial, node };

struct Body {
  std::string name;
  BodyKind kind = BodyKind::ground;
  bool fixed = false;       ///< has no coordinates (ground, or declared fixed)
  index_t offset = -1;      ///< first global coordinate, -1 when fixed
  int n_coords = 0;         ///< 3 (planar, node) or 7 (spatial)
  double mass = 0;          ///< kg
  double inertia2 = 0;      ///< planar: kg m² about the centre of mass
  Mat3<double> inertia3{};  ///< spatial: body-frame inertia tensor about the centre of mass
  BodyRef pose;             ///< initial pose (the constant pose of a fixed body)
  int mesh = -1;            ///< for nodes: index of the flexible body
};

/// A flexible body's mesh, kept for output (ParaView).
struct FlexMesh {
  std::string name;
  std::vector<int> node_bodies;               ///< body index of each node
  std::vector<std::array<int, 8>> hexahedra;  ///< local node numbers (VTK order)
};

/// A reference solution the model file carries ("reference" object): values of points and
/// coordinates at one time, and how close a run should come (docs/model-format.md).
struct ReferenceSolution {
  double time = -1;  ///< s; < 0: the model has no reference
  double tolerance = 1e-3;
  std::string source;  ///< where the values come from (free text)
  struct PointValue {
    int body = 0;                  ///< body index
    Vec3<double> point{};          ///< body coordinates (m)
    std::vector<double> position;  ///< global position expected (2 or 3 numbers, m)
    std::string name;              ///< "points[0] (crank0)" for messages
  };
  std::vector<PointValue> points;
  std::vector<std::pair<index_t, double>> coordinates;  ///< (coordinate index, value)
  std::vector<std::string> coordinate_names;
};

/// The model of a mechanical system: what the integrator needs.
struct Model {
  std::string name;
  bool planar = false;
  Vec3<double> gravity{};
  std::vector<Body> bodies;  ///< bodies[0] is ground
  std::map<std::string, int> body_index;
  std::vector<FlexMesh> meshes;
  index_t n = 0;               ///< number of coordinates
  std::vector<double> q0, v0;  ///< initial coordinates and velocities
  std::vector<std::unique_ptr<Constraint>> constraints;
  std::vector<std::unique_ptr<Force>> forces;
  /// Simulation defaults read from the model file ("simulation" object); the command
  /// line overrides them.
  double t_end = 1.0, step = 1e-3;
  int order = 2;
  double output_interval = 0;  ///< s between rows of the large CSV files (0: every step)
  double newton_rtol = 0, newton_atol = 0;  ///< Newton tolerances (0: the integrator's)
  ReferenceSolution reference;              ///< optional reference values (time < 0: none)

  /// Total number of constraint equations m.
  index_t n_constraints() const;
  /// Every force is conservative and no constraint depends on time: the total energy
  /// (kinetic + potential) of the exact motion is constant.
  bool conservative() const;
  /// Index of a body by name, or -1.
  int find_body(const std::string& name) const;
  /// Global position of the point s (body coordinates; planar: z ignored) of body k at q.
  Vec3<double> point_position(int k, const Vec3<double>& s, const double* q) const;
  /// Largest deviation from the reference values (m for points, the coordinate's unit for
  /// coordinates) of the state q at reference.time; "what" names the worst entry.
  double reference_error(const double* q, std::string* what = nullptr) const;
  /// Adds a body and assigns its coordinates; returns its index.
  int add_body(Body b);
  /// Per-coordinate names ("crank.x", "link3.e2", "beam.n17.z"), for output headers.
  std::vector<std::string> coordinate_names() const;
  /// Sets BodyRef b for body index k as seen by an element whose local vector starts
  /// its copy of body k's coordinates at `local` (ignored for fixed bodies).
  BodyRef ref(int k, int local) const;
};

/// Builds the element's dofs from the moving bodies among `bodies` (in order) and
/// returns their BodyRefs.
std::vector<BodyRef> bind_bodies(const Model& model, const std::vector<int>& bodies,
                                 std::vector<index_t>& dofs);

}  // namespace strata::mbd
