// strata::mbd — flexible bodies: 8-node hexahedral solid elements in absolute nodal
// coordinates with a St. Venant–Kirchhoff material.
//
// The nodal unknowns are absolute positions (the position-only "ANCF solid" of
// Shabana, "Dynamics of Multibody Systems", 4th ed. 2020, ch. 7; Olshevskiy, Dmitrochenko
// & Kim 2014), so the mass matrix M = ∫ρ NᵀN dV is constant and the elastic forces are
// f = ∫ P : ∇₀N dV with P = F S, S = λ tr(E) I + 2μE, E = ½(FᵀF − I), F = Σ x_a ⊗ ∇₀N_a
// (total Lagrangian; Bonet & Wood, "Nonlinear Continuum Mechanics for FEA", 2008, ch. 6).
// Integration: 2×2×2 Gauss points. The consistent tangent ∂f/∂x is formed in closed form
// (material and initial-stress parts; Bonet & Wood ch. 9). Optional stiffness-proportional
// damping β K(x) ẋ.
#pragma once

#include <array>
#include <memory>

#include "mbd/model.hpp"

namespace strata::mbd {

struct HexMaterial {
  double density = 0;  ///< kg/m³
  double young = 0;    ///< Pa
  double poisson = 0;  ///< −
  double damping = 0;  ///< stiffness-proportional Rayleigh coefficient β (s)
};

/// An 8-node hexahedron on the node bodies `nodes` (VTK_HEXAHEDRON order), reference
/// geometry = the nodes' initial positions in the model. Gravity of the model acts on
/// it. Throws ModelError for an inverted or degenerate element.
std::unique_ptr<Force> make_hexahedron(const Model& model, const std::array<int, 8>& nodes,
                                       const HexMaterial& material, std::string name);

}  // namespace strata::mbd
