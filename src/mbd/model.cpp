// strata::mbd — model bookkeeping: coordinates of bodies, element binding.
#include "mbd/model.hpp"

#include <cmath>

namespace strata::mbd {

index_t Model::n_constraints() const {
  index_t m = 0;
  for (const auto& c : constraints) m += c->rows;
  return m;
}

bool Model::conservative() const {
  for (const auto& f : forces)
    if (!f->conservative) return false;
  for (const auto& c : constraints)
    if (c->rheonomic) return false;
  return true;
}

Vec3<double> Model::point_position(int k, const Vec3<double>& s, const double* q) const {
  const Body& b = bodies[k];
  if (b.kind == BodyKind::planar) {
    const double x = b.offset >= 0 ? q[b.offset] : b.pose.r[0];
    const double y = b.offset >= 0 ? q[b.offset + 1] : b.pose.r[1];
    const double phi = b.offset >= 0 ? q[b.offset + 2] : b.pose.phi;
    const double c = std::cos(phi), sn = std::sin(phi);
    return {{x + c * s[0] - sn * s[1], y + sn * s[0] + c * s[1], 0.0}};
  }
  if (b.offset < 0) return b.pose.r + rot3(b.pose.p) * s;
  const Vec3<double> r{{q[b.offset], q[b.offset + 1], q[b.offset + 2]}};
  if (b.kind == BodyKind::node) return r;
  const Vec4<double> p{{q[b.offset + 3], q[b.offset + 4], q[b.offset + 5], q[b.offset + 6]}};
  return r + rot3(p) * s;
}

double Model::reference_error(const double* q, std::string* what) const {
  double worst = 0;
  for (const auto& p : reference.points) {
    const Vec3<double> x = point_position(p.body, p.point, q);
    double d2 = 0;
    for (std::size_t i = 0; i < p.position.size(); ++i)
      d2 += (x[i] - p.position[i]) * (x[i] - p.position[i]);
    if (std::sqrt(d2) >= worst) {
      worst = std::sqrt(d2);
      if (what) *what = p.name;
    }
  }
  for (std::size_t k = 0; k < reference.coordinates.size(); ++k) {
    const auto& [i, v] = reference.coordinates[k];
    if (std::abs(q[i] - v) >= worst) {
      worst = std::abs(q[i] - v);
      if (what) *what = reference.coordinate_names[k];
    }
  }
  return worst;
}

int Model::find_body(const std::string& name) const {
  auto it = body_index.find(name);
  return it == body_index.end() ? -1 : it->second;
}

int Model::add_body(Body b) {
  const int k = static_cast<int>(bodies.size());
  if (b.kind != BodyKind::ground && !b.fixed) {
    b.n_coords = b.kind == BodyKind::spatial ? 7 : 3;
    b.offset = n;
    n += b.n_coords;
    q0.resize(n, 0.0);
    v0.resize(n, 0.0);
    if (b.kind == BodyKind::planar) {
      q0[b.offset] = b.pose.r[0];
      q0[b.offset + 1] = b.pose.r[1];
      q0[b.offset + 2] = b.pose.phi;
    } else {
      for (int i = 0; i < 3; ++i) q0[b.offset + i] = b.pose.r[i];
      if (b.kind == BodyKind::spatial)
        for (int i = 0; i < 4; ++i) q0[b.offset + 3 + i] = b.pose.p[i];
    }
  } else {
    b.n_coords = 0;
    b.offset = -1;
  }
  body_index[b.name] = k;
  bodies.push_back(std::move(b));
  return k;
}

std::vector<std::string> Model::coordinate_names() const {
  std::vector<std::string> names(n);
  static const char* planar[] = {"x", "y", "phi"};
  static const char* spatial[] = {"x", "y", "z", "e0", "e1", "e2", "e3"};
  static const char* node[] = {"x", "y", "z"};
  for (const Body& b : bodies) {
    if (b.offset < 0) continue;
    const char** s = b.kind == BodyKind::planar    ? planar
                     : b.kind == BodyKind::spatial ? spatial
                                                   : node;
    for (int i = 0; i < b.n_coords; ++i) names[b.offset + i] = b.name + "." + s[i];
  }
  return names;
}

BodyRef Model::ref(int k, int local) const {
  BodyRef r = bodies[k].pose;
  r.local = bodies[k].offset >= 0 ? local : -1;
  return r;
}

std::vector<BodyRef> bind_bodies(const Model& model, const std::vector<int>& bodies,
                                 std::vector<index_t>& dofs) {
  std::vector<BodyRef> refs;
  dofs.clear();
  for (int k : bodies) {
    const Body& b = model.bodies[k];
    refs.push_back(model.ref(k, static_cast<int>(dofs.size())));
    for (int i = 0; i < b.n_coords; ++i) dofs.push_back(b.offset + i);
  }
  return refs;
}

}  // namespace strata::mbd
