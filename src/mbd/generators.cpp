// strata::mbd — model generators (see generators.hpp).
#include "mbd/generators.hpp"

#include <fmt/core.h>

#include <cmath>

#include "mbd/linalg.hpp"
#include "strata/errors.hpp"

namespace strata::mbd {

using json = nlohmann::json;

namespace {
json vec2(double x, double y) { return json::array({x, y}); }
json vec3(double x, double y, double z) { return json::array({x, y, z}); }
}  // namespace

// ------------------------------------------------------------- Andrews' squeezer ------
// Data of Hairer & Wanner (1996), §VII.7, Table 7.1 and the test set's andrews.f.
// Body k has its frame at its centre of mass and its absolute angle φ_k:
//   φ1 = β, φ2 = β+Θ, φ3 = γ, φ4 = Φ+δ, φ5 = δ, φ6 = Ω+ε, φ7 = ε.
// Geometry from the test set's constraint equations g(1..6) and mass matrix:
//   K1 turns about O = (0,0), its centre of mass at ra from O towards P = rr(cos β, sin β);
//   K2 hangs on P, its centre of mass at da from P towards Q = P − d(cos φ2, sin φ2);
//   K3 turns about B, Q = B + R(γ)(0, −ss), spring point D = B + R(γ)(sd, −sc);
//   K5 turns about A, C4 = A + zt(cos δ, sin δ); K4 hangs on C4, Q = C4 + e R(φ4)(0, −1),
//     centre of mass at e − ea from C4;
//   K7 turns about A, C6 = A + u R(ε)(0, −1); K6 hangs on C6, Q = C6 + zf R(φ6)(1, 0),
//     centre of mass at zf − fa from C6;
//   K2, K3, K4 and K6 meet at Q. The bodies turning about fixed points (K1, K3, K5, K7)
//   have their centre of mass at the distance given by the mass matrix (ra,
//   √(sa²+sb²), √(ta²+tb²), √(ua²+ub²)); its direction is immaterial without gravity and
//   is taken as (sa, sb), (ta, tb), (ua, ub) in the body frame.
namespace andrews {
constexpr double m[7] = {.04325, .00365, .02373, .00706, .07050, .00706, .05498};
constexpr double I[7] = {2.194e-6, 4.410e-7, 5.255e-6, 5.667e-7, 1.169e-5, 5.667e-7, 1.912e-5};
constexpr double xa = -.06934, ya = -.00227, xb = -.03635, yb = .03273, xc = .014, yc = .072;
constexpr double d = 28e-3, da = 115e-4, e = 2e-2, ea = 1421e-5, rr = 7e-3, ra = 92e-5;
constexpr double l0 = 7785e-5, ss = 35e-3, sa = 1874e-5, sb = 1043e-5, sc = 18e-3, sd = 2e-2;
constexpr double ta = 2308e-5, tb = 916e-5, u = 4e-2, ua = 1228e-5, ub = 449e-5;
constexpr double zf = 2e-2, zt = 4e-2, fa = 1421e-5, mom = 33e-3, c0 = 4530;
// consistent initial values of the test set (β, Θ, γ, Φ, δ, Ω, ε)
constexpr double q0[7] = {-0.0617138900142764496358948458001, 0.,
                          0.455279819163070380255912382449,   0.222668390165885884674473185609,
                          0.487364979543842550225598953530,   -0.222668390165885884674473185609,
                          1.23054744454982119249735015568};
}  // namespace andrews

json andrews_squeezer() {
  using namespace andrews;
  const double be = q0[0], th = q0[1], ga = q0[2], ph = q0[3], de = q0[4], om = q0[5], ep = q0[6];
  const double phi[7] = {be, be + th, ga, ph + de, de, om + ep, ep};
  auto R = [](double a, double x, double y) {
    return std::array<double, 2>{std::cos(a) * x - std::sin(a) * y,
                                 std::sin(a) * x + std::cos(a) * y};
  };
  // centres of mass at the initial pose
  std::array<double, 2> com[7];
  const auto P = R(be, rr, 0);
  com[0] = R(be, ra, 0);
  com[1] = {P[0] - da * std::cos(phi[1]), P[1] - da * std::sin(phi[1])};
  const auto c3 = R(ga, sa, sb);
  com[2] = {xb + c3[0], yb + c3[1]};
  const auto c4 = R(de, zt, 0), k4 = R(phi[3], 0, -(e - ea));
  com[3] = {xa + c4[0] + k4[0], ya + c4[1] + k4[1]};
  const auto c5 = R(de, ta, tb);
  com[4] = {xa + c5[0], ya + c5[1]};
  const auto c6 = R(ep, 0, -u), k6 = R(phi[5], zf - fa, 0);
  com[5] = {xa + c6[0] + k6[0], ya + c6[1] + k6[1]};
  const auto c7 = R(ep, ua, ub);
  com[6] = {xa + c7[0], ya + c7[1]};

  json j;
  j["name"] = "Andrews' squeezer mechanism";
  j["description"] =
      "Hairer & Wanner, Solving ODEs II, VII.7; Test Set for IVP Solvers, problem andrews";
  j["type"] = "planar";
  j["simulation"] = {{"t_end", 0.03}, {"step", 1e-5}, {"order", 2}};
  for (int k = 0; k < 7; ++k)
    j["bodies"].push_back({{"name", fmt::format("K{}", k + 1)},
                           {"mass", m[k]},
                           {"inertia", I[k]},
                           {"position", vec2(com[k][0], com[k][1])},
                           {"angle", phi[k]}});
  auto rev = [&](const char* name, const char* bi, json si, const char* bj, json sj) {
    j["joints"].push_back({{"name", name},
                           {"type", "revolute"},
                           {"body_i", bi},
                           {"body_j", bj},
                           {"point_i", si},
                           {"point_j", sj}});
  };
  rev("O", "ground", vec2(0, 0), "K1", vec2(-ra, 0));
  rev("P", "K1", vec2(rr - ra, 0), "K2", vec2(da, 0));
  rev("Q3", "K2", vec2(da - d, 0), "K3", vec2(-sa, -ss - sb));
  rev("B", "ground", vec2(xb, yb), "K3", vec2(-sa, -sb));
  rev("Q4", "K2", vec2(da - d, 0), "K4", vec2(0, -ea));
  rev("C4", "K4", vec2(0, e - ea), "K5", vec2(zt - ta, -tb));
  rev("A5", "ground", vec2(xa, ya), "K5", vec2(-ta, -tb));
  rev("Q6", "K2", vec2(da - d, 0), "K6", vec2(fa, 0));
  rev("C6", "K6", vec2(-(zf - fa), 0), "K7", vec2(-ua, -u - ub));
  rev("A7", "ground", vec2(xa, ya), "K7", vec2(-ua, -ub));
  j["forces"].push_back({{"name", "spring"},
                         {"type", "spring_damper"},
                         {"body_i", "ground"},
                         {"point_i", vec2(xc, yc)},
                         {"body_j", "K3"},
                         {"point_j", vec2(sd - sa, -sc - sb)},
                         {"stiffness", c0},
                         {"free_length", l0}});
  j["forces"].push_back({{"name", "motor"}, {"type", "torque"}, {"body", "K1"}, {"torque", mom}});
  return j;
}

std::array<double, 7> andrews_relative_angles(const double* q) {
  double phi[7];
  for (int k = 0; k < 7; ++k) phi[k] = q[3 * k + 2];
  return {phi[0], phi[1] - phi[0], phi[2], phi[3] - phi[4], phi[4], phi[5] - phi[6], phi[6]};
}

// ------------------------------------------------------------------ pendulum chain ----
json pendulum_chain(int n, bool spatial) {
  if (n < 1) throw InvalidInput("pendulum chain: need at least one link");
  const double L = 0.5, mass = 1.0, r = 0.02;
  json j;
  j["name"] = fmt::format("{} pendulum chain of {} links", spatial ? "spatial" : "planar", n);
  j["type"] = spatial ? "spatial" : "planar";
  j["gravity"] = spatial ? vec3(0, 0, -9.81) : vec2(0, -9.81);
  j["simulation"] = {{"t_end", 1.0}, {"step", 1e-3}, {"order", 2}};
  const double Ia = 0.5 * mass * r * r, It = mass * (3 * r * r + L * L) / 12;
  for (int k = 0; k < n; ++k) {
    json b = {{"name", fmt::format("link{}", k)}, {"mass", mass}};
    const double x = (k + 0.5) * L;
    if (spatial) {
      b["inertia"] = vec3(Ia, It, It);  // rod along the body x axis
      b["position"] = vec3(x, 0, 0);
      b["velocity"] = vec3(0, 0.3 * (k + 0.5) * L, 0);  // start turning about z: 3D motion
      b["angular_velocity"] = vec3(0, 0, 0.3);
    } else {
      b["inertia"] = It;
      b["position"] = vec2(x, 0);
    }
    j["bodies"].push_back(b);
    json jt = {{"name", fmt::format("J{}", k)},
               {"type", spatial ? "spherical" : "revolute"},
               {"body_i", k == 0 ? "ground" : fmt::format("link{}", k - 1)},
               {"body_j", fmt::format("link{}", k)}};
    jt["point"] = spatial ? vec3(k * L, 0, 0) : vec2(k * L, 0);
    j["joints"].push_back(jt);
  }
  return j;
}

// ----------------------------------------------------------------- tracked vehicle -----
// A small tracked vehicle (x forward, y left, z up, ground z = 0). Per side: a driven
// sprocket (front), an idler (rear) and five road wheels, all of radius R on revolute
// joints to the chassis at the same height, so that the track loop is a "stadium" of two
// half circles joined by straight runs; the lower run lies on the ground. The loop has
// `links` links placed at equal arc length, joined by revolute joints (axis y) and
// closed by one stiff bushing (a closed loop of parallel revolute joints has redundant
// constraints). Contact: one sphere on the inner face of each link against every wheel
// of its side (sphere–cylinder), two spheres on the outer face against the ground. The
// sprocket turns by a rotation driver with a smooth speed ramp.
// The point at arc length s (modulo the perimeter) of a "stadium" in the x–z plane: a
// lower straight run of length D from x = −D/2 forward at height zc − rc, a half circle
// of radius rc about (D/2, zc), the upper run back, the half circle about (−D/2, zc).
std::array<double, 2> stadium_point(double s, double D, double rc, double zc) {
  const double half = M_PI * rc;
  s = std::fmod(s, 2 * D + 2 * half);
  if (s < D) return {-D / 2 + s, zc - rc};
  s -= D;
  if (s < half) {
    const double a = -M_PI / 2 + s / rc;
    return {D / 2 + rc * std::cos(a), zc + rc * std::sin(a)};
  }
  s -= half;
  if (s < D) return {D / 2 - s, zc + rc};
  s -= D;
  const double a = M_PI / 2 + s / rc;
  return {-D / 2 + rc * std::cos(a), zc + rc * std::sin(a)};
}

json tracked_vehicle(int links) {
  if (links < 8) throw InvalidInput("tracked vehicle: need at least 8 links per track");
  const double R = 0.25, t = 0.04, D = 3.0, y_track = 0.9, width = 0.3;
  const double zc = R + t / 2;  // wheel centre height: lower run of link centres at t/2
  const double rc = R + t / 2;  // radius of the link-centre path around sprocket/idler
  const double perimeter = 2 * D + 2 * M_PI * rc;
  const double m_chassis = 1500, m_wheel = 40, m_track = 200;
  const double m_link = m_track / links;
  // a chord of the half circles passes closer to the wheel centre than its ends: make the
  // contact cylinder that much smaller, so that nothing penetrates at the start
  const double sag = rc * (1 - std::cos(0.5 * perimeter / links / rc));
  // a link–wheel pair is part of the Newton matrix only while within `margin`
  const double margin = std::max(0.05, 1.5 * perimeter / links);
  // contact: stiff enough for millimetre penetrations, soft and smooth enough (friction
  // regularised over 0.2 m/s) for Newton's method to converge in a few iterations
  // (values for 100 links per track; per contact they scale with 100/links, so that the
  // whole track is as stiff and each link's contact frequency the same for every size)
  const double scale = 100.0 / links;
  const double k_ground = 2e5 * scale, c_ground = 2e3 * scale, k_wheel = 1e6 * scale,
               c_wheel = 2e3 * scale, v_slip = 0.2;
  const double speed = 1.0, ramp = 0.5;  // m/s reached after `ramp` seconds
  json j;
  j["name"] = fmt::format("tracked vehicle, 2 x {} links", links);
  j["type"] = "spatial";
  j["gravity"] = vec3(0, 0, -9.81);
  j["simulation"] = {{"t_end", 1.0},        {"step", 1e-3},
                     {"order", 2},          {"output_interval", 0.01},
                     {"newton_rtol", 1e-5}, {"newton_atol", 1e-6}};
  auto box = [](double m, double a, double b, double c) {  // inertia of a box a×b×c
    return vec3(m * (b * b + c * c) / 12, m * (a * a + c * c) / 12, m * (a * a + b * b) / 12);
  };
  j["bodies"].push_back({{"name", "chassis"},
                         {"mass", m_chassis},
                         {"inertia", box(m_chassis, D + 0.6, 2 * y_track, 0.8)},
                         {"position", vec3(0, 0, zc)}});
  const double wheel_x[7] = {D / 2, -D / 2, -D / 3, -D / 6, 0, D / 6, D / 3};
  const char* wheel_kind[7] = {"sprocket", "idler",  "wheel1", "wheel2",
                               "wheel3",   "wheel4", "wheel5"};
  const double Iw = 0.5 * m_wheel * R * R, Iwt = m_wheel * (3 * R * R + width * width) / 12;
  for (int side = 0; side < 2; ++side) {
    const double y = side == 0 ? y_track : -y_track;
    const std::string sname = side == 0 ? "left" : "right";
    for (int w = 0; w < 7; ++w) {
      const std::string wn = sname + "_" + wheel_kind[w];
      j["bodies"].push_back({{"name", wn},
                             {"mass", m_wheel},
                             {"inertia", vec3(Iwt, Iw, Iwt)},
                             {"position", vec3(wheel_x[w], y, zc)}});
      j["joints"].push_back({{"name", wn + "_axle"},
                             {"type", "revolute"},
                             {"body_i", "chassis"},
                             {"body_j", wn},
                             {"point", vec3(wheel_x[w], y, zc)},
                             {"axis", vec3(0, 1, 0)}});
    }
    j["joints"].push_back({{"name", sname + "_drive"},
                           {"type", "rotation_driver"},
                           {"body_i", "chassis"},
                           {"body_j", sname + "_sprocket"},
                           {"point", vec3(D / 2, y, zc)},
                           {"axis", vec3(0, 1, 0)},
                           {"motion", {{"ramp", {{"rate", speed / R}, {"ramp_time", ramp}}}}}});
    // joint points on the stadium path at equal arc length, starting at the rear end of
    // the lower run and running forward along it (the loop turns about +y)
    std::vector<std::array<double, 2>> jp(links + 1);
    for (int k = 0; k <= links; ++k) jp[k] = stadium_point(perimeter * k / links, D, rc, zc);
    std::vector<double> len(links);
    for (int k = 0; k < links; ++k) {
      const double dx = jp[k + 1][0] - jp[k][0], dz = jp[k + 1][1] - jp[k][1];
      len[k] = std::hypot(dx, dz);
      const double cx = dx / len[k], cz = dz / len[k];
      // link frame: x along the chord, y lateral, z = x × y (towards the wheels)
      Mat3<double> A;
      A(0, 0) = cx, A(1, 0) = 0, A(2, 0) = cz;
      A(0, 1) = 0, A(1, 1) = 1, A(2, 1) = 0;
      A(0, 2) = -cz, A(1, 2) = 0, A(2, 2) = cx;
      const Vec4<double> p = euler_parameters(A);
      const std::string ln = fmt::format("{}_link{}", sname, k);
      j["bodies"].push_back(
          {{"name", ln},
           {"mass", m_link},
           {"inertia", box(m_link, len[k], width, t)},
           {"position", vec3(0.5 * (jp[k][0] + jp[k + 1][0]), y, 0.5 * (jp[k][1] + jp[k + 1][1]))},
           {"orientation", json::array({p[0], p[1], p[2], p[3]})}});
    }
    for (int k = 0; k < links; ++k) {
      const int k1 = (k + 1) % links;
      json jt = {{"name", fmt::format("{}_pin{}", sname, k)},
                 {"body_i", fmt::format("{}_link{}", sname, k)},
                 {"body_j", fmt::format("{}_link{}", sname, k1)},
                 {"point_i", vec3(len[k] / 2, 0, 0)},
                 {"point_j", vec3(-len[k1] / 2, 0, 0)}};
      if (k1 != 0) {
        jt["type"] = "revolute";
        jt["axis_i"] = vec3(0, 1, 0);
        j["joints"].push_back(jt);
      } else {  // loop closure: a stiff bushing, free in rotation about y
        jt["type"] = "bushing";
        jt["axis_i"] = vec3(0, 1, 0);
        jt["stiffness"] = json::array({1e7, 1e7, 1e7, 1e5, 1e5, 0});
        jt["damping"] = json::array({1e3, 1e3, 1e3, 10, 10, 0});
        j["forces"].push_back(jt);
      }
    }
    for (int k = 0; k < links; ++k) {
      const std::string ln = fmt::format("{}_link{}", sname, k);
      const double rs = 0.01;
      for (int w = 0; w < 7; ++w)
        j["forces"].push_back({{"name", fmt::format("{}_c{}", ln, w)},
                               {"type", "wheel_contact"},
                               {"wheel", sname + "_" + wheel_kind[w]},
                               {"axis", vec3(0, 1, 0)},
                               {"wheel_radius", R - sag - 1e-4},
                               {"half_width", width / 2},
                               {"body", ln},
                               {"point", vec3(0, 0, t / 2 - rs)},
                               {"radius", rs},
                               {"stiffness", k_wheel},
                               {"damping", c_wheel},
                               {"friction", w == 0 ? 0.8 : 0.2},
                               {"slip_velocity", v_slip},
                               {"margin", margin}});
      for (int g = 0; g < 2; ++g)
        j["forces"].push_back({{"name", fmt::format("{}_g{}", ln, g)},
                               {"type", "contact"},
                               {"body", ln},
                               {"point", vec3((g ? 0.3 : -0.3) * len[k], 0, -t / 2 + rs)},
                               {"radius", rs},
                               {"stiffness", k_ground},
                               {"damping", c_ground},
                               {"friction", 0.6},
                               {"slip_velocity", v_slip}});
    }
  }
  return j;
}

// ------------------------------------------------------------------ bushing lattice -----
// n³ rigid cubes on a cubic grid (spacing 0.2 m), each joined to its +x, +y and +z
// neighbours by a bushing at the midpoint; the bottom layer is held to the ground by
// bushings; gravity, and an initial shear velocity profile so that the lattice sways.
json bushing_lattice(int n) {
  if (n < 1) throw InvalidInput("lattice: need n >= 1");
  const double d = 0.2, a = 0.1, mass = 1.0;
  const double k = 2e4, kr = 2e2, c = 20, cr = 0.2;
  json j;
  j["name"] = fmt::format("bushing lattice {0}x{0}x{0}", n);
  j["type"] = "spatial";
  j["gravity"] = vec3(0, 0, -9.81);
  j["simulation"] = {{"t_end", 0.5}, {"step", 2e-3}, {"order", 2}, {"output_interval", 0.01}};
  auto name = [](int i, int jj, int kk) { return fmt::format("b{}_{}_{}", i, jj, kk); };
  const double I = mass * a * a / 6;
  for (int kk = 0; kk < n; ++kk)
    for (int jj = 0; jj < n; ++jj)
      for (int i = 0; i < n; ++i)
        j["bodies"].push_back({{"name", name(i, jj, kk)},
                               {"mass", mass},
                               {"inertia", vec3(I, I, I)},
                               {"position", vec3(i * d, jj * d, (kk + 1) * d)},
                               {"velocity", vec3(0.2 * (kk + 1) / n, 0, 0)}});
  const json stiff = json::array({k, k, k, kr, kr, kr});
  const json damp = json::array({c, c, c, cr, cr, cr});
  auto bushing = [&](const std::string& bi, const std::string& bj, json point) {
    j["forces"].push_back({{"name", bi + "-" + bj},
                           {"type", "bushing"},
                           {"body_i", bi},
                           {"body_j", bj},
                           {"point", point},
                           {"stiffness", stiff},
                           {"damping", damp}});
  };
  for (int kk = 0; kk < n; ++kk)
    for (int jj = 0; jj < n; ++jj)
      for (int i = 0; i < n; ++i) {
        const double x = i * d, y = jj * d, z = (kk + 1) * d;
        if (i + 1 < n) bushing(name(i, jj, kk), name(i + 1, jj, kk), vec3(x + d / 2, y, z));
        if (jj + 1 < n) bushing(name(i, jj, kk), name(i, jj + 1, kk), vec3(x, y + d / 2, z));
        if (kk + 1 < n) bushing(name(i, jj, kk), name(i, jj, kk + 1), vec3(x, y, z + d / 2));
        if (kk == 0) bushing("ground", name(i, jj, kk), vec3(x, y, z - d / 2));
      }
  return j;
}

// ------------------------------------------------------------------- flexible plate -----
// A flexible plate (aluminium, 1 m × 0.1 m × 0.02 m) meshed with nx × ny × nz 8-node
// hexahedra in absolute nodal coordinates, its root face attached to a rigid hub that a
// rotation driver spins up about the vertical axis (the spin-up beam of Simo & Vu-Quoc
// 1986, here as a 3D continuum), under gravity.
json flexible_plate(int nx, int ny, int nz) {
  if (nx < 1 || ny < 1 || nz < 1) throw InvalidInput("flexible plate: need nx, ny, nz >= 1");
  const double L = 1.0, W = 0.1, T = 0.02, r_hub = 0.05;
  json j;
  j["name"] = fmt::format("flexible plate {}x{}x{} hexahedra", nx, ny, nz);
  j["type"] = "spatial";
  j["gravity"] = vec3(0, 0, -9.81);
  j["simulation"] = {{"t_end", 0.5}, {"step", 1e-3}, {"order", 2}, {"output_interval", 0.01}};
  j["bodies"].push_back({{"name", "hub"},
                         {"mass", 5.0},
                         {"inertia", vec3(0.01, 0.01, 0.01)},
                         {"position", vec3(0, 0, 0)}});
  j["joints"].push_back({{"name", "bearing"},
                         {"type", "revolute"},
                         {"body_i", "ground"},
                         {"body_j", "hub"},
                         {"point", vec3(0, 0, 0)},
                         {"axis", vec3(0, 0, 1)}});
  j["joints"].push_back({{"name", "motor"},
                         {"type", "rotation_driver"},
                         {"body_i", "ground"},
                         {"body_j", "hub"},
                         {"point", vec3(0, 0, 0)},
                         {"axis", vec3(0, 0, 1)},
                         {"motion", {{"ramp", {{"rate", 6.0}, {"ramp_time", 0.5}}}}}});
  json nodes = json::array(), elements = json::array();
  auto id = [&](int i, int jj, int kk) { return (kk * (ny + 1) + jj) * (nx + 1) + i; };
  for (int kk = 0; kk <= nz; ++kk)
    for (int jj = 0; jj <= ny; ++jj)
      for (int i = 0; i <= nx; ++i)
        nodes.push_back(vec3(r_hub + L * i / nx, -W / 2 + W * jj / ny, -T / 2 + T * kk / nz));
  for (int kk = 0; kk < nz; ++kk)
    for (int jj = 0; jj < ny; ++jj)
      for (int i = 0; i < nx; ++i)
        elements.push_back({id(i, jj, kk), id(i + 1, jj, kk), id(i + 1, jj + 1, kk),
                            id(i, jj + 1, kk), id(i, jj, kk + 1), id(i + 1, jj, kk + 1),
                            id(i + 1, jj + 1, kk + 1), id(i, jj + 1, kk + 1)});
  json root = json::array();
  for (int kk = 0; kk <= nz; ++kk)
    for (int jj = 0; jj <= ny; ++jj) root.push_back(id(0, jj, kk));
  j["flexible_bodies"].push_back(
      {{"name", "plate"},
       {"material", {{"density", 2700}, {"young", 7e10}, {"poisson", 0.3}, {"damping", 1e-4}}},
       {"nodes", nodes},
       {"elements", elements},
       {"attachments", json::array({{{"nodes", root}, {"body", "hub"}}})}});
  return j;
}

json generate(const std::string& spec) {
  const auto colon = spec.find(':');
  const std::string kind = spec.substr(0, colon);
  const std::string arg = colon == std::string::npos ? "" : spec.substr(colon + 1);
  auto size = [&](int def) {
    if (arg.empty()) return def;
    try {
      std::size_t used = 0;
      const int v = std::stoi(arg, &used);
      if (used != arg.size() || v < 1) throw std::invalid_argument(arg);
      return v;
    } catch (const std::exception&) {
      throw InvalidInput("generator '" + spec + "': the size must be a positive integer");
    }
  };
  if (kind == "andrews") return andrews_squeezer();
  if (kind == "tracked") return tracked_vehicle(size(100));
  if (kind == "lattice") return bushing_lattice(size(6));
  if (kind == "chain") return pendulum_chain(size(5), true);
  if (kind == "chain2d") return pendulum_chain(size(5), false);
  if (kind == "flexible") {
    int nx = 16, ny = 2, nz = 2;
    if (!arg.empty() && std::sscanf(arg.c_str(), "%dx%dx%d", &nx, &ny, &nz) < 1)
      throw InvalidInput("generator '" + spec + "': expected flexible:NX or flexible:NXxNYxNZ");
    return flexible_plate(nx, ny, nz);
  }
  throw InvalidInput("unknown model generator '" + kind +
                     "' (andrews, tracked:N, lattice:N, flexible:NXxNYxNZ, chain:N, chain2d:N)");
}

}  // namespace strata::mbd
