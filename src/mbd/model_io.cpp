// strata::mbd — JSON model reader (schema in docs/model-format.md). Builds bodies, the
// Euler-parameter normalisation of spatial bodies, joints, forces and flexible bodies,
// resolving global locations and axes to body coordinates at the initial pose.
#include "mbd/model_io.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <set>
#include <sstream>

#include "mbd/constraints.hpp"
#include "mbd/flexible.hpp"
#include "mbd/forces.hpp"
#include "mbd/json_node.hpp"

namespace strata::mbd {
namespace {

using json = nlohmann::json;
using detail::Node;

TimeFunction time_function(const Node& n) {
  if (n.j.is_number()) return TimeFunction::constant(n.number());
  n.keys({"polynomial", "harmonic", "ramp"});
  TimeFunction f;
  if (n.has("polynomial")) {
    const Node p = n.at("polynomial");
    if (!p.j.is_array() || p.size() == 0) p.fail("expected a non-empty array of coefficients");
    f.kind = TimeFunction::Kind::polynomial;
    f.coefficients.clear();
    for (std::size_t i = 0; i < p.size(); ++i) f.coefficients.push_back(p.at(i).number());
  } else if (n.has("harmonic")) {
    const Node h = n.at("harmonic");
    h.keys({"amplitude", "omega", "phase", "offset"});
    f.kind = TimeFunction::Kind::harmonic;
    f.amplitude = h.number("amplitude", 0);
    f.omega = h.number("omega", 0);
    f.phase = h.number("phase", 0);
    f.offset = h.number("offset", 0);
  } else if (n.has("ramp")) {
    const Node r = n.at("ramp");
    r.keys({"rate", "ramp_time", "offset"});
    f.kind = TimeFunction::Kind::smooth_ramp;
    f.rate = r.at("rate").number();
    f.ramp_time = r.positive("ramp_time");
    f.offset = r.number("offset", 0);
  } else {
    n.fail("expected a number or one of \"polynomial\", \"harmonic\", \"ramp\"");
  }
  return f;
}

class Reader {
 public:
  Reader(const json& doc, std::string source) : root_{doc, ""}, source_(std::move(source)) {}

  Model read() {
    const Node& r = root_;
    if (!r.j.is_object()) throw ModelError("the model must be a JSON object");
    r.keys({"name", "type", "gravity", "simulation", "bodies", "joints", "forces",
            "flexible_bodies", "description", "reference"});
    m_.name = r.string("name", "model");
    const std::string type = r.string("type", "spatial");
    if (type != "planar" && type != "spatial")
      r.at("type").fail("expected \"planar\" or \"spatial\", got \"" + type + "\"");
    m_.planar = type == "planar";
    dim_ = m_.planar ? 2 : 3;
    if (r.has("gravity")) m_.gravity = r.at("gravity").vec(dim_);
    if (r.has("simulation")) {
      const Node s = r.at("simulation");
      s.keys({"t_end", "step", "order", "output_interval", "newton_rtol", "newton_atol"});
      m_.output_interval = s.nonnegative("output_interval", 0);
      m_.newton_rtol = s.nonnegative("newton_rtol", 0);
      m_.newton_atol = s.nonnegative("newton_atol", 0);
      m_.t_end = s.has("t_end") ? s.positive("t_end") : m_.t_end;
      m_.step = s.has("step") ? s.positive("step") : m_.step;
      if (s.has("order")) {
        const double k = s.at("order").number();
        if (k != std::floor(k) || k < 1 || k > 5) s.at("order").fail("must be an integer 1..5");
        m_.order = static_cast<int>(k);
      }
    }
    Body ground;
    ground.name = "ground";
    ground.kind = BodyKind::ground;
    ground.fixed = true;
    m_.add_body(ground);
    if (r.has("bodies")) {
      const Node b = r.at("bodies");
      if (!b.j.is_array()) b.fail("expected an array of bodies");
      for (std::size_t i = 0; i < b.size(); ++i) body(b.at(i));
    }
    if (r.has("flexible_bodies")) {
      const Node f = r.at("flexible_bodies");
      if (!f.j.is_array()) f.fail("expected an array");
      for (std::size_t i = 0; i < f.size(); ++i) flexible(f.at(i));
    }
    // inertia and normalisation of rigid bodies
    for (int k = 1; k < static_cast<int>(m_.bodies.size()); ++k) {
      const Body& b = m_.bodies[k];
      if (b.fixed || b.kind == BodyKind::node) continue;
      m_.forces.push_back(make_body_inertia(m_, k));
      if (b.kind == BodyKind::spatial) m_.constraints.push_back(make_normalization(m_, k));
    }
    if (r.has("joints")) {
      const Node js = r.at("joints");
      if (!js.j.is_array()) js.fail("expected an array of joints");
      for (std::size_t i = 0; i < js.size(); ++i) joint(js.at(i));
    }
    if (r.has("forces")) {
      const Node fs = r.at("forces");
      if (!fs.j.is_array()) fs.fail("expected an array of forces");
      for (std::size_t i = 0; i < fs.size(); ++i) force(fs.at(i));
    }
    for (const auto& [path, attach] : attachments_) attachment(path, attach);
    if (r.has("reference")) reference(r.at("reference"));
    if (m_.n == 0) throw ModelError("the model has no moving bodies");
    return std::move(m_);
  }

 private:
  int body_ref(const Node& n) {
    const std::string name = n.string();
    const int k = m_.find_body(name);
    if (k < 0) n.fail("unknown body '" + name + "'");
    return k;
  }
  std::string element_name(const Node& n, const char* kind) {
    // "joints[3] 'J4'" (path without the source prefix, plus the name when given)
    std::string p = n.path;
    if (n.has("name")) p += " '" + n.at("name").string() + "'";
    (void)kind;
    return p;
  }

  void body(const Node& n) {
    Body b;
    b.name = n.at("name").string();
    if (b.name.empty()) n.at("name").fail("must not be empty");
    if (m_.find_body(b.name) >= 0) n.at("name").fail("duplicate body name '" + b.name + "'");
    b.fixed = n.boolean("fixed", false);
    if (m_.planar) {
      n.keys({"name", "mass", "inertia", "position", "angle", "velocity", "angular_velocity",
              "fixed"});
      b.kind = BodyKind::planar;
      b.mass = b.fixed ? n.number("mass", 0) : n.positive("mass");
      b.inertia2 = b.fixed ? n.number("inertia", 0) : n.positive("inertia");
      b.pose.r = n.has("position") ? n.at("position").vec(2) : Vec3<double>{};
      b.pose.phi = n.number("angle", 0);
    } else {
      n.keys({"name", "mass", "inertia", "position", "orientation", "velocity", "angular_velocity",
              "fixed"});
      b.kind = BodyKind::spatial;
      b.mass = b.fixed ? n.number("mass", 0) : n.positive("mass");
      if (n.has("inertia")) {
        const Node in = n.at("inertia");
        if (in.j.is_array() && in.size() == 3 && in.j[0].is_array()) {
          for (int i = 0; i < 3; ++i) {
            const auto row = in.at(i).numbers(3);
            for (int j = 0; j < 3; ++j) b.inertia3(i, j) = row[j];
          }
        } else {
          const auto d = in.numbers(3);
          for (int i = 0; i < 3; ++i) b.inertia3(i, i) = d[i];
        }
        for (int i = 0; i < 3; ++i)
          if (!b.fixed && !(b.inertia3(i, i) > 0)) in.fail("principal moments must be positive");
      } else if (!b.fixed) {
        n.at("inertia");  // throws: missing
      }
      b.pose.r = n.has("position") ? n.at("position").vec(3) : Vec3<double>{};
      if (n.has("orientation")) b.pose.p = orientation(n.at("orientation"));
    }
    const int k = m_.add_body(b);
    const Body& added = m_.bodies[k];
    if (added.offset < 0) return;
    double* v = &m_.v0[added.offset];
    if (n.has("velocity")) {
      const Vec3<double> vel = n.at("velocity").vec(dim_);
      for (int i = 0; i < dim_; ++i) v[i] = vel[i];
    }
    if (n.has("angular_velocity")) {
      if (m_.planar) {
        v[2] = n.at("angular_velocity").number();
      } else {  // ṗ = ½ Gᵀ ω′ with ω′ = Aᵀ ω
        const Vec3<double> w = n.at("angular_velocity").vec(3);
        const Vec3<double> wb = tmul(rot3(added.pose.p), w);
        const Vec4<double> pd = GT_times(added.pose.p, wb);
        for (int i = 0; i < 4; ++i) v[3 + i] = 0.5 * pd[i];
      }
    }
  }

  Vec4<double> orientation(const Node& n) {
    if (n.j.is_array()) {
      const auto e = n.numbers(4);
      const double s = std::sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2] + e[3] * e[3]);
      if (!(s > 0)) n.fail("Euler parameters must not all be zero");
      return {{e[0] / s, e[1] / s, e[2] / s, e[3] / s}};
    }
    n.keys({"axis", "angle"});
    const Vec3<double> axis = n.at("axis").vec(3);
    if (!(norm(axis) > 0)) n.at("axis").fail("must not be the zero vector");
    return axis_angle(axis, n.at("angle").number());
  }

  // Global position and rotation of body k at the initial pose.
  Vec3<double> origin(int k) const { return m_.bodies[k].pose.r; }
  Mat3<double> rotation(int k) const {
    const Body& b = m_.bodies[k];
    if (b.kind == BodyKind::spatial) return rot3(b.pose.p);
    Mat3<double> a = Mat3<double>::identity();
    const double c = std::cos(b.pose.phi), s = std::sin(b.pose.phi);
    a(0, 0) = c;
    a(0, 1) = -s;
    a(1, 0) = s;
    a(1, 1) = c;
    return a;
  }
  Vec3<double> to_body(int k, const Vec3<double>& x) const {
    return tmul(rotation(k), x - origin(k));
  }
  Vec3<double> to_global(int k, const Vec3<double>& s) const { return origin(k) + rotation(k) * s; }
  Vec3<double> dir_to_body(int k, const Vec3<double>& u) const { return tmul(rotation(k), u); }

  // Body-coordinate points on i and j: "point" (global, shared) or "point_i"/"point_j"
  // (body coordinates; a missing one is the other's location).
  void points(const Node& n, int bi, int bj, Vec3<double>& si, Vec3<double>& sj,
              bool shared_default) {
    if (n.has("point")) {
      const Vec3<double> p = n.at("point").vec(dim_);
      si = to_body(bi, p);
      sj = to_body(bj, p);
      return;
    }
    const bool hi = n.has("point_i"), hj = n.has("point_j");
    if (!hi && !hj) {
      if (!shared_default) n.fail("needs \"point\" (global) or \"point_i\"/\"point_j\"");
      n.fail("needs \"point\" (global) or \"point_i\"/\"point_j\" (body coordinates)");
    }
    if (hi) si = n.at("point_i").vec(dim_);
    if (hj) sj = n.at("point_j").vec(dim_);
    if (!hi) si = to_body(bi, to_global(bj, sj));
    if (!hj) sj = to_body(bj, to_global(bi, si));
  }

  // Joint frames: points, axis z ("axis" global or "axis_i"/"axis_j"), x ("x_axis" global,
  // else any perpendicular); frame j coincides with frame i at the initial pose.
  void frames(const Node& n, int bi, int bj, Frame3& fi, Frame3& fj, bool universal) {
    points(n, bi, bj, fi.s, fj.s, true);
    if (m_.planar) {
      Vec3<double> u{{1, 0, 0}};
      if (n.has("axis")) u = n.at("axis").vec(2);
      if (!(norm(u) > 0)) n.at("axis").fail("must not be the zero vector");
      u = u * (1.0 / norm(u));
      fi.x = dir_to_body(bi, u);
      fj.x = dir_to_body(bj, u);
      return;
    }
    Vec3<double> zi{{0, 0, 1}}, zj;
    bool given_j = false;
    if (n.has("axis")) {
      const Vec3<double> a = n.at("axis").vec(3);
      if (!(norm(a) > 0)) n.at("axis").fail("must not be the zero vector");
      zi = dir_to_body(bi, a * (1 / norm(a)));
    } else if (n.has("axis_i")) {
      zi = n.at("axis_i").vec(3);
      if (!(norm(zi) > 0)) n.at("axis_i").fail("must not be the zero vector");
      zi = zi * (1 / norm(zi));
    }
    if (n.has("axis_j")) {
      zj = n.at("axis_j").vec(3);
      if (!(norm(zj) > 0)) n.at("axis_j").fail("must not be the zero vector");
      zj = zj * (1 / norm(zj));
      given_j = true;
    } else {
      zj = dir_to_body(bj, rotation(bi) * zi);
    }
    if (universal && !given_j) n.fail("a universal joint needs \"axis_j\" (the second pin)");
    // x_i ⊥ z_i
    Vec3<double> xg;
    const Vec3<double> zg = rotation(bi) * zi;
    if (n.has("x_axis")) {
      xg = n.at("x_axis").vec(3);
    } else {
      xg = std::abs(zg[0]) < 0.9 ? Vec3<double>{{1, 0, 0}} : Vec3<double>{{0, 1, 0}};
    }
    xg = xg - zg * dot(xg, zg);
    if (!(norm(xg) > 1e-9)) n.at("x_axis").fail("must not be parallel to the axis");
    xg = xg * (1 / norm(xg));
    fi.z = zi;
    fi.x = dir_to_body(bi, xg);
    fi.y = cross(fi.z, fi.x);
    // frame j: z_j as given/derived, x_j = x_i at the initial pose (made ⊥ z_j)
    const Vec3<double> zjg = rotation(bj) * zj;
    Vec3<double> xjg = xg - zjg * dot(xg, zjg);
    if (norm(xjg) < 1e-9) {
      xjg = std::abs(zjg[0]) < 0.9 ? Vec3<double>{{1, 0, 0}} : Vec3<double>{{0, 1, 0}};
      xjg = xjg - zjg * dot(xjg, zjg);
    }
    xjg = xjg * (1 / norm(xjg));
    fj.z = zj;
    fj.x = dir_to_body(bj, xjg);
    fj.y = cross(fj.z, fj.x);
  }

  void joint(const Node& n) {
    n.keys({"name", "type", "body_i", "body_j", "point", "point_i", "point_j", "axis", "axis_i",
            "axis_j", "x_axis", "motion", "length"});
    static const std::map<std::string, JointType> kTypes = {
        {"revolute", JointType::revolute},
        {"translational", JointType::translational},
        {"prismatic", JointType::translational},
        {"fixed", JointType::fixed},
        {"spherical", JointType::spherical},
        {"universal", JointType::universal},
        {"cylindrical", JointType::cylindrical},
        {"distance", JointType::distance},
        {"rotation_driver", JointType::rotation_driver},
        {"translation_driver", JointType::translation_driver}};
    const std::string type = n.at("type").string();
    const auto it = kTypes.find(type);
    if (it == kTypes.end()) n.at("type").fail("unknown joint type '" + type + "'");
    JointSpec s;
    s.type = it->second;
    s.name = element_name(n, "joint");
    s.body_i = body_ref(n.at("body_i"));
    s.body_j = body_ref(n.at("body_j"));
    frames(n, s.body_i, s.body_j, s.fi, s.fj, s.type == JointType::universal);
    check_geometry(n, s, type);
    if (s.type == JointType::rotation_driver || s.type == JointType::translation_driver)
      s.motion = time_function(n.at("motion"));
    else if (n.has("motion"))
      n.at("motion").fail("only drivers (rotation_driver, translation_driver) take a motion");
    // reference values at the initial pose
    const Mat3<double> ai = rotation(s.body_i), aj = rotation(s.body_j);
    const Vec3<double> d = to_global(s.body_j, s.fj.s) - to_global(s.body_i, s.fi.s);
    if (m_.planar) {
      const double rel = m_.bodies[s.body_j].pose.phi - m_.bodies[s.body_i].pose.phi;
      if (s.type == JointType::translation_driver)
        s.reference = dot(ai * s.fi.x, d);
      else
        s.reference = rel;
    } else if (s.type == JointType::translation_driver) {
      s.reference = dot(ai * s.fi.z, d);
    } else if (s.type == JointType::rotation_driver) {
      const Vec3<double> xj = aj * s.fj.x;
      s.reference = std::atan2(dot(xj, ai * s.fi.y), dot(xj, ai * s.fi.x));
    }
    if (s.type == JointType::distance) {
      s.reference = n.has("length") ? n.positive("length") : norm(d);
      if (!(s.reference > 0)) n.fail("distance joint with zero length");
    }
    if (s.type != JointType::distance && n.has("length"))
      n.at("length").fail("only distance joints take a length");
    m_.constraints.push_back(make_joint(m_, s));
  }

  // The joint's equations must hold at the initial pose as given: points that should
  // coincide do, axes that should be parallel are, a universal joint's pins are
  // perpendicular (otherwise the position analysis would silently move the model).
  void check_geometry(const Node& n, const JointSpec& s, const std::string& type) const {
    const Vec3<double> pi = to_global(s.body_i, s.fi.s), pj = to_global(s.body_j, s.fj.s);
    const Vec3<double> d = pj - pi;
    double scale = 1;  // m: the size of the model around the joint
    for (int k : {s.body_i, s.body_j}) scale = std::max(scale, norm(origin(k)));
    const double tol = 1e-6 * scale;
    const bool point = s.type == JointType::revolute || s.type == JointType::spherical ||
                       s.type == JointType::universal || s.type == JointType::fixed;
    const bool line = s.type == JointType::cylindrical || s.type == JointType::translational;
    if (point && norm(d) > tol)
      throw ModelError(s.name + ": " +
                       fmt::format("point_i and point_j are {:.6g} m apart at the initial pose; a "
                                   "{} joint needs them to "
                                   "coincide (give one \"point\", or fix the body poses)",
                                   norm(d), type));
    if (m_.planar) return;
    const Vec3<double> zi = rotation(s.body_i) * s.fi.z, zj = rotation(s.body_j) * s.fj.z;
    if (line) {
      const Vec3<double> off = d - zi * dot(d, zi);
      if (norm(off) > tol)
        throw ModelError(s.name + ": " +
                         fmt::format("point_j lies {:.6g} m off the joint axis through point_i at "
                                     "the initial pose; a {} "
                                     "joint needs it on the axis",
                                     norm(off), type));
    }
    const bool parallel = s.type == JointType::revolute || s.type == JointType::cylindrical ||
                          s.type == JointType::translational;
    const double deg = 180 / std::acos(-1.0);
    if (parallel && norm(cross(zi, zj)) > 1e-6)
      throw ModelError(
          s.name + ": " +
          fmt::format(
              "axis_i and axis_j are {:.6g} deg apart at the initial pose; a {} joint needs them "
              "parallel (give one \"axis\")",
              std::asin(std::min(1.0, norm(cross(zi, zj)))) * deg, type));
    if (s.type == JointType::universal && std::abs(dot(zi, zj)) > 1e-6)
      throw ModelError(
          s.name + ": " +
          fmt::format(
              "the pins axis_i and axis_j make {:.6g} deg at the initial pose; a universal joint "
              "needs perpendicular pins",
              std::acos(std::clamp(dot(zi, zj), -1.0, 1.0)) * deg));
  }

  void force(const Node& n) {
    const std::string type = n.at("type").string();
    const std::string name = element_name(n, "force");
    if (type == "spring_damper") {
      n.keys({"type", "name", "body_i", "body_j", "point_i", "point_j", "point", "stiffness",
              "damping", "free_length", "actuator", "location_i", "location_j"});
      SpringSpec s;
      s.name = name;
      s.body_i = body_ref(n.at("body_i"));
      s.body_j = body_ref(n.at("body_j"));
      s.si = n.has("location_i") ? to_body(s.body_i, n.at("location_i").vec(dim_))
                                 : n.at("point_i").vec(dim_);
      s.sj = n.has("location_j") ? to_body(s.body_j, n.at("location_j").vec(dim_))
                                 : n.at("point_j").vec(dim_);
      s.stiffness = n.nonnegative("stiffness", 0);
      s.damping = n.nonnegative("damping", 0);
      const double l = norm(to_global(s.body_j, s.sj) - to_global(s.body_i, s.si));
      s.free_length = n.has("free_length") ? n.nonnegative("free_length", 0) : l;
      if (!(l > 0)) n.fail("the two points coincide at the initial pose (direction undefined)");
      if (n.has("actuator")) s.actuator = time_function(n.at("actuator"));
      m_.forces.push_back(make_spring_damper(m_, s));
    } else if (type == "rotational_spring_damper") {
      n.keys({"type", "name", "body_i", "body_j", "point", "point_i", "point_j", "axis", "axis_i",
              "axis_j", "x_axis", "stiffness", "damping", "reference", "actuator"});
      RotationalSpringSpec s;
      s.name = name;
      s.body_i = body_ref(n.at("body_i"));
      s.body_j = body_ref(n.at("body_j"));
      if (!m_.planar || n.has("point") || n.has("point_i")) {
        frames(n, s.body_i, s.body_j, s.fi, s.fj, false);
      }
      s.stiffness = n.nonnegative("stiffness", 0);
      s.damping = n.nonnegative("damping", 0);
      // reference: the free angle relative to the initial pose (default 0 → free now)
      double rel0 = 0;
      if (m_.planar) rel0 = m_.bodies[s.body_j].pose.phi - m_.bodies[s.body_i].pose.phi;
      s.reference = rel0 + n.number("reference", 0);
      if (n.has("actuator")) s.actuator = time_function(n.at("actuator"));
      m_.forces.push_back(make_rotational_spring_damper(m_, s));
    } else if (type == "bushing") {
      n.keys({"type", "name", "body_i", "body_j", "point", "point_i", "point_j", "axis", "axis_i",
              "axis_j", "x_axis", "stiffness", "damping"});
      BushingSpec s;
      s.name = name;
      s.body_i = body_ref(n.at("body_i"));
      s.body_j = body_ref(n.at("body_j"));
      frames(n, s.body_i, s.body_j, s.fi, s.fj, false);
      const auto k = n.at("stiffness").numbers(6);
      for (int i = 0; i < 6; ++i) s.stiffness[i] = k[i];
      if (n.has("damping")) {
        const auto c = n.at("damping").numbers(6);
        for (int i = 0; i < 6; ++i) s.damping[i] = c[i];
      }
      m_.forces.push_back(make_bushing(m_, s));
    } else if (type == "force" || type == "torque") {
      n.keys({"type", "name", "body", "point", "location", "force", "torque", "frame", "scale"});
      LoadSpec s;
      s.name = name;
      s.body = body_ref(n.at("body"));
      if (n.has("location")) s.point = to_body(s.body, n.at("location").vec(dim_));
      if (n.has("point")) s.point = n.at("point").vec(dim_);
      if (n.has("force")) s.force = n.at("force").vec(dim_);
      if (n.has("torque")) {
        if (m_.planar)
          s.torque = {{0, 0, n.at("torque").number()}};
        else
          s.torque = n.at("torque").vec(3);
      }
      const std::string frame = n.string("frame", "global");
      if (frame != "global" && frame != "body")
        n.at("frame").fail("expected \"global\" or \"body\"");
      s.body_frame = frame == "body";
      if (n.has("scale")) s.scale = time_function(n.at("scale"));
      m_.forces.push_back(make_load(m_, s));
    } else if (type == "contact") {
      n.keys({"type", "name", "body", "point", "location", "radius", "stiffness", "damping",
              "friction", "slip_velocity", "plane"});
      ContactSpec s;
      s.name = name;
      s.body = body_ref(n.at("body"));
      if (n.has("location")) s.point = to_body(s.body, n.at("location").vec(dim_));
      if (n.has("point")) s.point = n.at("point").vec(dim_);
      s.radius = n.nonnegative("radius", 0);
      s.stiffness = n.positive("stiffness");
      s.damping = n.nonnegative("damping", 0);
      s.friction = n.nonnegative("friction", 0);
      s.slip_velocity = n.has("slip_velocity") ? n.positive("slip_velocity") : 1e-2;
      s.normal = m_.planar ? Vec3<double>{{0, 1, 0}} : Vec3<double>{{0, 0, 1}};
      if (n.has("plane")) {
        const Node p = n.at("plane");
        p.keys({"normal", "offset"});
        if (p.has("normal")) s.normal = p.at("normal").vec(dim_);
        if (!(norm(s.normal) > 0)) p.at("normal").fail("must not be the zero vector");
        s.offset = p.number("offset", 0);
      }
      m_.forces.push_back(make_ground_contact(m_, s));
    } else if (type == "wheel_contact") {
      n.keys({"type", "name", "wheel", "centre", "axis", "wheel_radius", "half_width", "body",
              "point", "radius", "stiffness", "damping", "friction", "slip_velocity", "margin"});
      WheelContactSpec s;
      s.name = name;
      s.wheel = body_ref(n.at("wheel"));
      s.body = body_ref(n.at("body"));
      if (n.has("centre")) s.centre = n.at("centre").vec(3);
      if (n.has("axis")) s.axis = n.at("axis").vec(3);
      if (!(norm(s.axis) > 0)) n.at("axis").fail("must not be the zero vector");
      s.wheel_radius = n.positive("wheel_radius");
      s.half_width = n.positive("half_width");
      if (n.has("point")) s.point = n.at("point").vec(3);
      s.radius = n.nonnegative("radius", 0);
      s.stiffness = n.positive("stiffness");
      s.damping = n.nonnegative("damping", 0);
      s.friction = n.nonnegative("friction", 0);
      s.slip_velocity = n.has("slip_velocity") ? n.positive("slip_velocity") : 1e-2;
      s.margin = n.nonnegative("margin", 0);
      m_.forces.push_back(make_wheel_contact(m_, s));
    } else {
      n.at("type").fail("unknown force type '" + type +
                        "' (spring_damper, rotational_spring_damper, bushing, force, torque, "
                        "contact, wheel_contact)");
    }
  }

  // A node index 0..count-1. Checked as a double before the conversion: casting an
  // out-of-range double to int is undefined behaviour (1e10 was accepted, found with the
  // fuzz harness under UBSan), and 0.5 would silently become node 0.
  static int node_index(const Node& n, std::size_t count) {
    const double v = n.number();
    if (v != std::floor(v) || v < 0 || v >= static_cast<double>(count))
      n.fail("node index " + n.j.dump() + " is not an integer in 0.." + std::to_string(count - 1));
    return static_cast<int>(v);
  }

  void flexible(const Node& n) {
    if (m_.planar) n.fail("flexible bodies exist only in spatial models");
    n.keys({"name", "material", "nodes", "elements", "attachments"});
    FlexMesh mesh;
    mesh.name = n.at("name").string();
    const Node mat = n.at("material");
    mat.keys({"density", "young", "poisson", "damping"});
    HexMaterial hm;
    hm.density = mat.positive("density");
    hm.young = mat.positive("young");
    hm.poisson = mat.at("poisson").number();
    if (!(hm.poisson > -1 && hm.poisson < 0.5)) mat.at("poisson").fail("must be in (-1, 0.5)");
    hm.damping = mat.nonnegative("damping", 0);
    const Node nodes = n.at("nodes");
    if (!nodes.j.is_array() || nodes.size() == 0) nodes.fail("expected an array of [x, y, z]");
    const int mesh_index = static_cast<int>(m_.meshes.size());
    for (std::size_t i = 0; i < nodes.size(); ++i) {
      Body b;
      b.name = mesh.name + ".n" + std::to_string(i);
      if (m_.find_body(b.name) >= 0) n.at("name").fail("duplicate name '" + b.name + "'");
      b.kind = BodyKind::node;
      b.pose.r = nodes.at(i).vec(3);
      b.mesh = mesh_index;
      mesh.node_bodies.push_back(m_.add_body(b));
    }
    const Node els = n.at("elements");
    if (!els.j.is_array()) els.fail("expected an array of 8-node hexahedra");
    for (std::size_t e = 0; e < els.size(); ++e) {
      const Node el = els.at(e);
      const auto ids = el.numbers(8);
      std::array<int, 8> local{}, bodies{};
      for (int k = 0; k < 8; ++k) {
        local[k] = node_index(el.at(k), nodes.size());
        bodies[k] = mesh.node_bodies[local[k]];
      }
      mesh.hexahedra.push_back(local);
      m_.forces.push_back(make_hexahedron(m_, bodies, hm, el.path));
    }
    if (n.has("attachments")) {
      const Node at = n.at("attachments");
      if (!at.j.is_array()) at.fail("expected an array");
      for (std::size_t i = 0; i < at.size(); ++i) {
        const Node a = at.at(i);
        a.keys({"node", "nodes", "body", "point"});
        std::vector<int> list;
        if (a.has("node")) list.push_back(node_index(a.at("node"), nodes.size()));
        if (a.has("nodes")) {
          const Node ns = a.at("nodes");
          if (!ns.j.is_array()) ns.fail("expected an array of node indices");
          for (std::size_t k = 0; k < ns.size(); ++k)
            list.push_back(node_index(ns.at(k), nodes.size()));
        }
        attachments_.push_back({a.path, {mesh.node_bodies, list, a}});
      }
    }
    m_.meshes.push_back(std::move(mesh));
  }

  struct Attach {
    std::vector<int> node_bodies;
    std::vector<int> nodes;
    Node node;
  };
  void attachment(const std::string& path, const Attach& a) {
    const int k = body_ref(a.node.at("body"));
    const Body& b = m_.bodies[k];
    if (b.kind == BodyKind::node || b.kind == BodyKind::planar)
      a.node.at("body").fail("nodes attach to spatial rigid bodies or ground");
    for (int nd : a.nodes) {
      const int nb = a.node_bodies[nd];
      const Vec3<double> s = a.node.has("point") && a.nodes.size() == 1
                                 ? a.node.at("point").vec(3)
                                 : to_body(k, m_.bodies[nb].pose.r);
      m_.constraints.push_back(
          make_node_attachment(m_, nb, k, s, path + " node " + std::to_string(nd)));
    }
  }

  // "reference": {"time": T, "tolerance": e, "source": "...", "points": [{"body": B,
  // "point": [..] (body coordinates), "position": [..] (global)}], "coordinates":
  // {"crank.phi": value}}
  void reference(const Node& n) {
    n.keys({"time", "tolerance", "source", "points", "coordinates"});
    ReferenceSolution& ref = m_.reference;
    ref.time = n.at("time").number();
    if (ref.time < 0) n.at("time").fail("must not be negative");
    ref.tolerance = n.has("tolerance") ? n.positive("tolerance") : 1e-3;
    ref.source = n.string("source", "");
    if (n.has("points")) {
      const Node ps = n.at("points");
      if (!ps.j.is_array()) ps.fail("expected an array of {body, point, position}");
      for (std::size_t i = 0; i < ps.size(); ++i) {
        const Node p = ps.at(i);
        p.keys({"body", "point", "position"});
        ReferenceSolution::PointValue v;
        v.body = body_ref(p.at("body"));
        if (m_.bodies[v.body].offset < 0) p.at("body").fail("names a body that does not move");
        v.point = p.has("point") ? p.at("point").vec(dim_) : Vec3<double>{};
        const Vec3<double> x = p.at("position").vec(dim_);
        v.position.assign(x.x.begin(), x.x.begin() + dim_);
        v.name = p.path + " (" + m_.bodies[v.body].name + ")";
        ref.points.push_back(v);
      }
    }
    if (n.has("coordinates")) {
      const Node cs = n.at("coordinates");
      if (!cs.j.is_object()) cs.fail("expected an object {\"body.coordinate\": value}");
      const std::vector<std::string> names = m_.coordinate_names();
      for (const auto& [key, value] : cs.j.items()) {
        const auto it = std::find(names.begin(), names.end(), key);
        const Node c{value, cs.path + "." + key};
        if (it == names.end()) c.fail("unknown coordinate (e.g. \"crank.phi\", \"link.e0\")");
        ref.coordinates.emplace_back(it - names.begin(), c.number());
        ref.coordinate_names.push_back(key);
      }
    }
    if (ref.points.empty() && ref.coordinates.empty())
      n.fail("needs \"points\" or \"coordinates\"");
  }

  Node root_;
  std::string source_;
  Model m_;
  int dim_ = 3;
  std::vector<std::pair<std::string, Attach>> attachments_;
};

}  // namespace

Model build_model(const json& doc, const std::string& source) {
  try {
    return Reader(doc, source).read();
  } catch (const ModelError& e) {
    throw ModelError(source + ": " + e.what());
  }
}

namespace {

// "WHERE:LINE:COLUMN: invalid JSON: WHAT" for the 1-based byte offset `byte` of text.
[[noreturn]] void throw_json_error(const std::string& text, std::size_t byte,
                                   const std::string& where, const char* what) {
  std::size_t line = 1, col = 1;
  for (std::size_t i = 0; i + 1 < byte && i < text.size(); ++i) {
    if (text[i] == '\n') {
      ++line;
      col = 1;
    } else {
      ++col;
    }
  }
  throw ModelError(where + ":" + std::to_string(line) + ":" + std::to_string(col) +
                   ": invalid JSON: " + what);
}

// Parses JSON text; a syntax error becomes "source:L:C: invalid JSON: ...".
json parse_document(const std::string& text, const std::string& source) {
  try {
    return json::parse(text);
  } catch (const json::parse_error& e) {
    throw_json_error(text, e.byte, source, e.what());
  } catch (const json::exception& e) {
    // Not only parse_error: a number beyond the double range is an out_of_range (406,
    // "number overflow parsing '1e999'", found by fuzzing), without a position; locate
    // the quoted token in the text.
    const std::string what = e.what();
    const auto close = what.rfind('\'');
    const auto open =
        close == std::string::npos || close == 0 ? std::string::npos : what.rfind('\'', close - 1);
    std::size_t at = std::string::npos;
    if (open != std::string::npos) at = text.find(what.substr(open + 1, close - open - 1));
    if (at == std::string::npos) throw ModelError(source + ": invalid JSON: " + what);
    throw_json_error(text, at + 1, source, e.what());
  }
}

}  // namespace

nlohmann::json load_model_document(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw ModelError(path + ": cannot open the model file");
  std::stringstream ss;
  ss << in.rdbuf();
  return parse_document(ss.str(), path);
}

std::string model_file_name(const std::string& path) {
  const auto slash = path.find_last_of('/');
  return slash == std::string::npos ? path : path.substr(slash + 1);
}

Model parse_model(const std::string& text, const std::string& source) {
  return build_model(parse_document(text, source), model_file_name(source));
}

Model load_model(const std::string& path) {
  return build_model(load_model_document(path), model_file_name(path));
}

}  // namespace strata::mbd
