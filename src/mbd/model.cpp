// strata::mbd — model bookkeeping: coordinates of bodies, element binding.
#include "mbd/model.hpp"

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
