// strata::mbd — model generators: the validation and benchmark models as JSON documents
// (the same schema as model files, docs/model-format.md), sized by a parameter.
#pragma once

#include <array>
#include <nlohmann/json.hpp>
#include <string>

namespace strata::mbd {

/// Andrews' squeezer mechanism (Hairer & Wanner, "Solving ODEs II", §VII.7; Mazzia &
/// Magherini, Test Set for IVP Solvers, problem "andrews"): 7 planar rigid bodies in
/// absolute coordinates with 10 revolute joints, the spring and the driving torque.
nlohmann::json andrews_squeezer();

/// The relative angles (β, Θ, γ, Φ, δ, Ω, ε) of the test set from the absolute
/// coordinates q of the model made by andrews_squeezer() (bodies in order K1..K7).
std::array<double, 7> andrews_relative_angles(const double* q);

/// A tracked vehicle: chassis, two track loops of `links` links each (revolute joints,
/// the loop closed by a bushing), a driven sprocket, an idler and road wheels per side,
/// sphere–wheel contact between links and wheels and link–ground contact.
nlohmann::json tracked_vehicle(int links);

/// A cubic lattice of n³ rigid bodies joined to their neighbours by bushings, the bottom
/// layer held to the ground by bushings, under gravity.
nlohmann::json bushing_lattice(int n);

/// A flexible plate of nx × ny × nz hexahedra (absolute nodal coordinates, St. Venant–
/// Kirchhoff) clamped at one end to a rigid crank driven by a rotation driver.
nlohmann::json flexible_plate(int nx, int ny, int nz);

/// A chain of `n` links hanging from the ground by spherical (spatial) or revolute
/// (planar) joints; conservative (for energy tests).
nlohmann::json pendulum_chain(int n, bool spatial);

/// Generates by name: "andrews", "tracked:N", "lattice:N", "flexible:NX[xNYxNZ]",
/// "chain:N", "chain2d:N". Throws strata::InvalidInput for an unknown name.
nlohmann::json generate(const std::string& spec);

}  // namespace strata::mbd
