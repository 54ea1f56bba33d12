// strata::mbd — model generators (see generators.hpp).
#include "mbd/generators.hpp"

#include <cmath>
#include <fmt/core.h>

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
  const double be = q0[0], th = q0[1], ga = q0[2], ph = q0[3], de = q0[4], om = q0[5],
               ep = q0[6];
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

json tracked_vehicle(int links) { throw InvalidInput("tracked vehicle: not yet implemented"); }
json bushing_lattice(int n) { throw InvalidInput("lattice: not yet implemented"); }
json flexible_plate(int nx, int ny, int nz) { throw InvalidInput("flexible: not yet implemented"); }

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
