// strata::mbd — every constraint's and force's Jacobian against central finite
// differences of its own residual (an independent check of the automatic derivatives).
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "mbd/model_io.hpp"

namespace strata::mbd {
namespace {

using json = nlohmann::json;

// Two spatial bodies and ground with one of every joint and force.
json spatial_model() {
  json j = json::parse(R"({
    "type": "spatial", "gravity": [0, 0, -9.81],
    "bodies": [
      {"name": "a", "mass": 2, "inertia": [[0.3, 0.01, 0.02], [0.01, 0.4, 0.03], [0.02, 0.03, 0.5]],
       "position": [0, 0, 1], "orientation": {"axis": [1, 2, 3], "angle": 0.4}},
      {"name": "b", "mass": 3, "inertia": [0.2, 0.5, 0.6], "position": [1, 0.2, 1.1],
       "orientation": {"axis": [0, 1, 1], "angle": -0.3}}],
    "joints": [
      {"type": "spherical", "body_i": "a", "body_j": "b", "point": [0.5, 0.1, 1]},
      {"type": "revolute", "body_i": "a", "body_j": "b", "point": [0.5, 0.1, 1], "axis": [0, 1, 0]},
      {"type": "universal", "body_i": "a", "body_j": "b", "point": [0.5, 0.1, 1],
       "axis_i": [1, 0, 0], "axis_j": [0, 1, 0]},
      {"type": "cylindrical", "body_i": "a", "body_j": "b", "point": [0.5, 0.1, 1], "axis": [1, 0, 0]},
      {"type": "translational", "body_i": "a", "body_j": "b", "point": [0.5, 0.1, 1], "axis": [1, 0, 0]},
      {"type": "fixed", "body_i": "a", "body_j": "b", "point": [0.5, 0.1, 1]},
      {"type": "distance", "body_i": "a", "body_j": "b", "point_i": [0.1, 0, 0], "point_j": [0, 0.1, 0]},
      {"type": "revolute", "body_i": "ground", "body_j": "a", "point": [0, 0, 1.5], "axis": [0, 0, 1]},
      {"type": "rotation_driver", "body_i": "a", "body_j": "b", "point": [0.5, 0.1, 1], "axis": [0, 1, 0],
       "motion": {"harmonic": {"amplitude": 0.5, "omega": 3, "phase": 0.2}}},
      {"type": "translation_driver", "body_i": "ground", "body_j": "b", "point": [1, 0.2, 1.1], "axis": [1, 0, 0],
       "motion": {"polynomial": [0, 0.1, 0.3]}}],
    "forces": [
      {"type": "spring_damper", "body_i": "a", "body_j": "b", "point_i": [0.1, 0.2, 0],
       "point_j": [0, 0, 0.1], "stiffness": 100, "damping": 3, "free_length": 0.5,
       "actuator": {"ramp": {"rate": 2, "ramp_time": 1}}},
      {"type": "rotational_spring_damper", "body_i": "a", "body_j": "b", "point": [0.5, 0.1, 1],
       "axis": [0, 1, 0], "stiffness": 50, "damping": 2, "reference": 0.1},
      {"type": "bushing", "body_i": "a", "body_j": "b", "point": [0.5, 0.1, 1],
       "stiffness": [1e3, 2e3, 3e3, 10, 20, 30], "damping": [1, 2, 3, 0.1, 0.2, 0.3]},
      {"type": "force", "body": "a", "point": [0.1, 0.2, 0.3], "force": [1, 2, 3], "torque": [0.1, 0, 0.2],
       "frame": "body", "scale": {"harmonic": {"amplitude": 1, "omega": 2, "offset": 1}}},
      {"type": "contact", "body": "b", "point": [0, 0, -0.1], "radius": 1.2, "stiffness": 1e4,
       "damping": 10, "friction": 0.5, "slip_velocity": 0.1},
      {"type": "wheel_contact", "wheel": "a", "axis": [0, 1, 0], "wheel_radius": 0.8, "half_width": 1,
       "body": "b", "point": [0, 0, 0], "radius": 0.5, "stiffness": 1e4, "damping": 10,
       "friction": 0.4, "slip_velocity": 0.1}],
    "flexible_bodies": [
      {"name": "block", "material": {"density": 1000, "young": 1e6, "poisson": 0.3, "damping": 0.01},
       "nodes": [[2,0,0],[3,0,0],[3,1,0],[2,1,0],[2,0,1],[3,0,1],[3,1,1],[2,1,1]],
       "elements": [[0,1,2,3,4,5,6,7]],
       "attachments": [{"node": 0, "body": "b"}, {"nodes": [1, 2], "body": "ground"}]}]
  })");
  // the universal joint's second pin (body b coordinates) perpendicular to the first at the
  // initial pose, as the model reader requires
  const Vec3<double> pin_i = rot3(axis_angle({{1, 2, 3}}, 0.4)) * Vec3<double>{{1, 0, 0}};
  Vec3<double> w = cross(pin_i, Vec3<double>{{0, 0, 1}});
  w = w * (1 / norm(w));
  const Vec3<double> pin_j = tmul(rot3(axis_angle({{0, 1, 1}}, -0.3)), w);
  j["joints"][2]["axis_j"] = {pin_j[0], pin_j[1], pin_j[2]};
  return j;
}

json planar_model() {
  return json::parse(R"({
    "type": "planar", "gravity": [0, -9.81],
    "bodies": [
      {"name": "a", "mass": 2, "inertia": 0.3, "position": [0, 1], "angle": 0.4},
      {"name": "b", "mass": 3, "inertia": 0.5, "position": [1, 1.2], "angle": -0.2}],
    "joints": [
      {"type": "revolute", "body_i": "a", "body_j": "b", "point": [0.5, 1.1]},
      {"type": "translational", "body_i": "a", "body_j": "b", "point": [0.5, 1.1], "axis": [1, 0.3]},
      {"type": "fixed", "body_i": "a", "body_j": "b", "point": [0.5, 1.1]},
      {"type": "distance", "body_i": "ground", "body_j": "b", "point_i": [0, 0], "point_j": [0.1, 0]},
      {"type": "rotation_driver", "body_i": "a", "body_j": "b", "point": [0.5, 1.1],
       "motion": {"polynomial": [0, 1, 0.5]}},
      {"type": "translation_driver", "body_i": "ground", "body_j": "a", "point": [0, 1], "axis": [0, 1],
       "motion": {"harmonic": {"amplitude": 0.1, "omega": 5}}}],
    "forces": [
      {"type": "spring_damper", "body_i": "ground", "body_j": "b", "point_i": [0, 0],
       "point_j": [0.1, 0.1], "stiffness": 100, "damping": 3},
      {"type": "rotational_spring_damper", "body_i": "a", "body_j": "b", "stiffness": 50, "damping": 2},
      {"type": "force", "body": "a", "point": [0.1, 0.2], "force": [1, 2], "torque": 0.3, "frame": "body"},
      {"type": "contact", "body": "b", "point": [0, -0.1], "radius": 1.2, "stiffness": 1e4,
       "damping": 10, "friction": 0.5, "slip_velocity": 0.1}]
  })");
}

// Relative difference with an absolute floor scaled by the matrix size.
void expect_close(const std::vector<double>& an, const std::vector<double>& fd,
                  const std::string& what) {
  double scale = 1e-8;
  for (double v : fd) scale = std::max(scale, std::abs(v));
  double worst = 0;
  std::size_t at = 0;
  for (std::size_t k = 0; k < an.size(); ++k) {
    const double d = std::abs(an[k] - fd[k]) / scale;
    if (d > worst) worst = d, at = k;
  }
  EXPECT_LT(worst, 2e-6) << what << ": entry " << at << " analytic " << an[at] << " vs FD "
                         << fd[at];
}

// Returns the number of constraints whose Hessian is computed over fewer coordinates than
// they have (the rest having zero rows), so that the checks below cover that path.
int check_model(const Model& m, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1, 1);
  const double t = 0.37;
  int reduced = 0;
  for (const auto& c : m.constraints) {
    SCOPED_TRACE(c->name);
    const std::size_t nz = c->dofs.size();
    std::vector<double> q(nz), v(nz), a(nz), lam(c->rows);
    for (std::size_t i = 0; i < nz; ++i) {
      q[i] = m.q0[c->dofs[i]] + 0.05 * u(rng);
      v[i] = u(rng);
      a[i] = u(rng);
    }
    for (double& l : lam) l = u(rng);
    ConstraintEval e, ep, em;
    c->evaluate(q.data(), v.data(), a.data(), t, true, e);
    std::vector<double> fq(e.jq.size()), fvq(e.jq.size()), faq(e.jq.size()), fh(nz * nz),
        h(nz * nz);
    const double eps = 1e-6;
    for (std::size_t k = 0; k < nz; ++k) {
      auto qp = q, qm = q;
      qp[k] += eps;
      qm[k] -= eps;
      c->evaluate(qp.data(), v.data(), a.data(), t, true, ep);
      c->evaluate(qm.data(), v.data(), a.data(), t, true, em);
      for (int r = 0; r < c->rows; ++r) {
        fq[r * nz + k] = (ep.phi[r] - em.phi[r]) / (2 * eps);
        fvq[r * nz + k] = (ep.phid[r] - em.phid[r]) / (2 * eps);
        faq[r * nz + k] = (ep.phidd[r] - em.phidd[r]) / (2 * eps);
      }
      // H(:, k) = ∂(Φ_qᵀλ)/∂q_k
      for (std::size_t i = 0; i < nz; ++i) {
        double s = 0;
        for (int r = 0; r < c->rows; ++r) s += lam[r] * (ep.jq[r * nz + i] - em.jq[r * nz + i]);
        fh[i * nz + k] = s / (2 * eps);
      }
    }
    expect_close(e.jq, fq, "Phi_q");
    {
      // the gradient pass computes Φ_q its own way (the spatial joints' rotation
      // derivatives in doubles): equal to the dual numbers' Φ_q to rounding
      ConstraintEval g;
      c->evaluate_gradient(q.data(), v.data(), a.data(), t, g);
      expect_close(g.jq, e.jq, "Phi_q of evaluate_gradient");
      double jmax = 0, diff = 0;
      for (std::size_t k = 0; k < e.jq.size(); ++k) {
        jmax = std::max(jmax, std::abs(e.jq[k]));
        diff = std::max(diff, std::abs(g.jq[k] - e.jq[k]));
      }
      EXPECT_LE(diff, 1e-14 * std::max(jmax, 1.0)) << "Phi_q of evaluate_gradient";
      expect_close(g.phidd, e.phidd, "d2Phi/dt2 of evaluate_gradient");
    }
    expect_close(e.jvq, fvq, "d(dPhi/dt)/dq");
    expect_close(e.jaq, faq, "d(d2Phi/dt2)/dq");
    c->hessian(q.data(), t, lam.data(), h.data());
    expect_close(h, fh, "Hessian of lambda^T Phi");
    reduced += c->hessian_coordinates() < static_cast<int>(nz);
    // the coordinates left out have zero rows and columns in the finite differences too
    {
      double hmax = 0, outside = 0;
      std::vector<char> kept(nz, 0);
      for (std::size_t k = 0; k < nz; ++k)
        for (std::size_t l = 0; l < nz; ++l) {
          hmax = std::max(hmax, std::abs(fh[k * nz + l]));
          if (h[k * nz + l] != 0) kept[k] = kept[l] = 1;
        }
      for (std::size_t k = 0; k < nz; ++k)
        for (std::size_t l = 0; l < nz; ++l)
          if (!kept[k]) outside = std::max(outside, std::abs(fh[k * nz + l]));
      EXPECT_LE(outside, 1e-6 * std::max(hmax, 1.0)) << "a coordinate with second derivatives";
    }
    // Φ̇ = Φ_q v + Φ_t and Φ̈ linear in a with slope Φ_q: check against the time derivative
    std::vector<double> phid_fd(c->rows), phidd_fd(c->rows);
    {
      const double dt = 1e-6;
      auto qp = q, qm = q, vp = v, vm = v;
      for (std::size_t i = 0; i < nz; ++i) {
        qp[i] += dt * v[i] + 0.5 * dt * dt * a[i];
        qm[i] += -dt * v[i] + 0.5 * dt * dt * a[i];
        vp[i] += dt * a[i];
        vm[i] -= dt * a[i];
      }
      c->evaluate(qp.data(), vp.data(), a.data(), t + dt, false, ep);
      c->evaluate(qm.data(), vm.data(), a.data(), t - dt, false, em);
      for (int r = 0; r < c->rows; ++r) {
        phid_fd[r] = (ep.phi[r] - em.phi[r]) / (2 * dt);
        phidd_fd[r] = (ep.phid[r] - em.phid[r]) / (2 * dt);
      }
      expect_close(e.phid, phid_fd, "dPhi/dt");
      expect_close(e.phidd, phidd_fd, "d2Phi/dt2");
    }
  }
  for (const auto& f : m.forces) {
    SCOPED_TRACE(f->name);
    const std::size_t nz = f->dofs.size();
    std::vector<double> q(nz), v(nz), a(nz);
    for (std::size_t i = 0; i < nz; ++i) {
      q[i] = m.q0[f->dofs[i]] + 0.05 * u(rng);
      v[i] = u(rng);
      a[i] = u(rng);
    }
    ForceEval e, ep, em;
    f->evaluate(q.data(), v.data(), a.data(), t, true, e);
    bool active = false;
    for (double g : e.g) active |= g != 0;
    EXPECT_TRUE(active) << "element inactive at the test state";
    std::vector<double> fq(nz * nz), fv(nz * nz), fa(nz * nz);
    const double eps = 1e-6;
    for (std::size_t k = 0; k < nz; ++k)
      for (int which = 0; which < 3; ++which) {
        auto qp = q, qm = q, vp = v, vm = v, ap = a, am = a;
        auto& xp = which == 0 ? qp : which == 1 ? vp : ap;
        auto& xm = which == 0 ? qm : which == 1 ? vm : am;
        xp[k] += eps;
        xm[k] -= eps;
        f->evaluate(qp.data(), vp.data(), ap.data(), t, false, ep);
        f->evaluate(qm.data(), vm.data(), am.data(), t, false, em);
        auto& dst = which == 0 ? fq : which == 1 ? fv : fa;
        for (std::size_t i = 0; i < nz; ++i) dst[i * nz + k] = (ep.g[i] - em.g[i]) / (2 * eps);
      }
    expect_close(e.dq, fq, "dg/dq");
    if (f->uses_v) expect_close(e.dv, fv, "dg/dv");
    if (f->uses_a) expect_close(e.da, fa, "dg/da");
    // the declared mass structure: ascending positions of the nz × nz block, and every
    // entry outside it exactly zero (the acceleration analysis leaves those out)
    const auto listed = f->mass_structure();
    if (f->uses_a && !listed.empty()) {
      std::vector<char> in(nz * nz, 0);
      for (std::size_t k = 0; k < listed.size(); ++k) {
        EXPECT_LT(listed[k], nz * nz) << f->name;
        if (k) EXPECT_LT(listed[k - 1], listed[k]) << f->name << ": not ascending";
        if (listed[k] < nz * nz) in[listed[k]] = 1;
      }
      std::vector<double> mass;
      f->mass_matrix(q.data(), v.data(), t, mass);
      for (std::size_t k = 0; k < nz * nz; ++k)
        if (!in[k]) {
          EXPECT_EQ(e.da[k], 0.0) << f->name << ": dg/da(" << k / nz << ", " << k % nz
                                  << ") outside the mass structure";
          EXPECT_EQ(mass[k], 0.0) << f->name << ": mass_matrix outside the mass structure";
          EXPECT_LT(std::abs(fa[k]), 1e-7) << f->name << ": finite difference outside it";
        }
      EXPECT_EQ(f->mass_entries(), listed.size());
    }
    double fvmax = 0, famax = 0;
    for (double x : fv) fvmax = std::max(fvmax, std::abs(x));
    for (double x : fa) famax = std::max(famax, std::abs(x));
    if (!f->uses_v) EXPECT_LT(fvmax, 1e-7) << "depends on v but declares uses_v = false";
    if (!f->uses_a) EXPECT_LT(famax, 1e-7) << "depends on a but declares uses_a = false";
  }
  return reduced;
}

TEST(MbdJacobians, SpatialElementsMatchFiniteDifferences) {
  std::mt19937_64 rng(7);
  const Model m = build_model(spatial_model(), "spatial");
  int reduced = 0;
  for (int rep = 0; rep < 3; ++rep) reduced += check_model(m, rng);
  EXPECT_GT(reduced, 0) << "no spatial joint's Hessian over a subset of its coordinates";
}

TEST(MbdJacobians, PlanarElementsMatchFiniteDifferences) {
  std::mt19937_64 rng(11);
  const Model m = build_model(planar_model(), "planar");
  for (int rep = 0; rep < 3; ++rep) check_model(m, rng);
}

}  // namespace
}  // namespace strata::mbd
