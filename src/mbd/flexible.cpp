// strata::mbd — 8-node St. Venant–Kirchhoff hexahedron (see flexible.hpp).
#include "mbd/flexible.hpp"

#include <fmt/core.h>

#include <cmath>

namespace strata::mbd {
namespace {

constexpr int kNat[8][3] = {{-1, -1, -1}, {1, -1, -1}, {1, 1, -1}, {-1, 1, -1},
                            {-1, -1, 1},  {1, -1, 1},  {1, 1, 1},  {-1, 1, 1}};

class Hexahedron : public Force {
 public:
  Hexahedron(const std::array<Vec3<double>, 8>& X, const HexMaterial& mat, const Vec3<double>& g,
             const std::string& name)
      : mat_(mat) {
    uses_a = true;
    uses_v = mat.damping > 0;
    conservative = mat.damping == 0;
    lambda_ = mat.young * mat.poisson / ((1 + mat.poisson) * (1 - 2 * mat.poisson));
    mu_ = mat.young / (2 * (1 + mat.poisson));
    const double gp = 1.0 / std::sqrt(3.0);
    double ms[8][8] = {};
    int k = 0;
    for (int a = 0; a < 2; ++a)
      for (int b = 0; b < 2; ++b)
        for (int c = 0; c < 2; ++c, ++k) {
          const double xi[3] = {a ? gp : -gp, b ? gp : -gp, c ? gp : -gp};
          double N[8], dN[8][3];
          for (int n = 0; n < 8; ++n) {
            double f[3], d[3];
            for (int i = 0; i < 3; ++i) {
              f[i] = 0.5 * (1 + xi[i] * kNat[n][i]);
              d[i] = 0.5 * kNat[n][i];
            }
            N[n] = f[0] * f[1] * f[2];
            dN[n][0] = d[0] * f[1] * f[2];
            dN[n][1] = f[0] * d[1] * f[2];
            dN[n][2] = f[0] * f[1] * d[2];
          }
          Mat3<double> J;  // J_ij = ∂X_i/∂ξ_j
          for (int n = 0; n < 8; ++n)
            for (int i = 0; i < 3; ++i)
              for (int j = 0; j < 3; ++j) J(i, j) += X[n][i] * dN[n][j];
          const double det = J(0, 0) * (J(1, 1) * J(2, 2) - J(1, 2) * J(2, 1)) -
                             J(0, 1) * (J(1, 0) * J(2, 2) - J(1, 2) * J(2, 0)) +
                             J(0, 2) * (J(1, 0) * J(2, 1) - J(1, 1) * J(2, 0));
          if (!(det > 0))
            throw ModelError(name + ": inverted or degenerate hexahedron (det J = " +
                             fmt::format("{:.3e}", det) + "); nodes must follow the VTK order");
          Mat3<double> Ji;  // inverse
          Ji(0, 0) = (J(1, 1) * J(2, 2) - J(1, 2) * J(2, 1)) / det;
          Ji(0, 1) = (J(0, 2) * J(2, 1) - J(0, 1) * J(2, 2)) / det;
          Ji(0, 2) = (J(0, 1) * J(1, 2) - J(0, 2) * J(1, 1)) / det;
          Ji(1, 0) = (J(1, 2) * J(2, 0) - J(1, 0) * J(2, 2)) / det;
          Ji(1, 1) = (J(0, 0) * J(2, 2) - J(0, 2) * J(2, 0)) / det;
          Ji(1, 2) = (J(0, 2) * J(1, 0) - J(0, 0) * J(1, 2)) / det;
          Ji(2, 0) = (J(1, 0) * J(2, 1) - J(1, 1) * J(2, 0)) / det;
          Ji(2, 1) = (J(0, 1) * J(2, 0) - J(0, 0) * J(2, 1)) / det;
          Ji(2, 2) = (J(0, 0) * J(1, 1) - J(0, 1) * J(1, 0)) / det;
          for (int n = 0; n < 8; ++n)
            for (int i = 0; i < 3; ++i) {  // ∇₀N_n = J⁻ᵀ ∂N/∂ξ
              double s = 0;
              for (int j = 0; j < 3; ++j) s += Ji(j, i) * dN[n][j];
              grad_[k][n][i] = s;
            }
          wdet_[k] = det;  // Gauss weights are 1
          for (int m = 0; m < 8; ++m)
            for (int n = 0; n < 8; ++n) ms[m][n] += mat.density * N[m] * N[n] * det;
        }
    for (int m = 0; m < 8; ++m)
      for (int n = 0; n < 8; ++n) mass_[m][n] = ms[m][n];
    for (int m = 0; m < 8; ++m)
      for (int i = 0; i < 3; ++i) {
        double s = 0;
        for (int n = 0; n < 8; ++n) s += ms[m][n];
        gravity_[3 * m + i] = s * g[i];  // M·(g repeated): consistent nodal gravity
      }
  }

  // Elastic nodal forces f (24) at positions x (24); T any scalar type.
  template <class T>
  void elastic(const T* x, T* f) const {
    for (int i = 0; i < 24; ++i) f[i] = T(0.0);
    for (int k = 0; k < 8; ++k) {
      Mat3<T> F;  // F_ij = Σ_n x_n,i ∂N_n/∂X_j
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) {
          T s = x[i] * grad_[k][0][j];
          for (int n = 1; n < 8; ++n) s = s + x[3 * n + i] * grad_[k][n][j];
          F(i, j) = s;
        }
      Mat3<T> E = transpose(F) * F;
      for (int i = 0; i < 3; ++i) E(i, i) = E(i, i) - 1.0;
      for (int i = 0; i < 9; ++i) E.m[i] = E.m[i] * 0.5;
      const T tr = E(0, 0) + E(1, 1) + E(2, 2);
      Mat3<T> S;
      for (int i = 0; i < 9; ++i) S.m[i] = E.m[i] * (2 * mu_);
      for (int i = 0; i < 3; ++i) S(i, i) = S(i, i) + tr * lambda_;
      const Mat3<T> P = F * S;
      for (int n = 0; n < 8; ++n)
        for (int i = 0; i < 3; ++i) {
          T s = P(i, 0) * grad_[k][n][0] + P(i, 1) * grad_[k][n][1] + P(i, 2) * grad_[k][n][2];
          f[3 * n + i] = f[3 * n + i] + s * wdet_[k];
        }
    }
  }

  // The Jacobians of the elastic and damping forces in closed form: dq += ∂(f + β K ẋ)/∂x
  // and dv += β K, K = ∂f/∂x (row-major 24 × 24, rows and columns in the nodes' (x, y, z)
  // order). Per Gauss point (weight w = det J), with G_a = ∇₀N_a, u_a = F G_a and
  // C = F Fᵀ, the 3 × 3 block of nodes a, b is the material part plus the initial-stress
  // part of the total Lagrangian tangent (Bonet & Wood 2008, ch. 9):
  //   K_ab = w [λ u_a u_bᵀ + μ ((G_a·G_b) C + u_b u_aᵀ) + (G_a·S G_b) I].
  // The damping force β K ẋ is β times the derivative of f along ẋ; its ∂/∂x is the second
  // derivative of f along ẋ and x: the same products with F replaced by Ḟ = Σ ẋ_a ⊗ G_a in
  // one factor at a time (u̇_a = Ḟ G_a, Ṡ = λ tr(Ė) I + 2μĖ, Ė = ½(ḞᵀF + FᵀḞ)):
  //   w [λ (u̇_a u_bᵀ + u_a u̇_bᵀ) + μ (u_b u̇_aᵀ + u̇_b u_aᵀ + (G_a·G_b)(Ḟ Fᵀ + F Ḟᵀ))
  //      + (G_a·Ṡ G_b) I].
  // Automatic differentiation of f gives the same to rounding, at the cost of 24-wide dual
  // numbers through every product (tests/unit/test_mbd_flexible.cpp checks the closed form
  // against differences that are exact for the cubic f).
  void tangent(const double* x, const double* xd, double beta, double* dq, double* dv) const {
    const bool damped = beta > 0;
    for (int k = 0; k < 8; ++k) {
      const double(&G)[8][3] = grad_[k];
      const double w = wdet_[k];
      double F[3][3] = {}, Fd[3][3] = {};
      for (int n = 0; n < 8; ++n)
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < 3; ++j) {
            F[i][j] += x[3 * n + i] * G[n][j];
            Fd[i][j] += xd[3 * n + i] * G[n][j];
          }
      // E = ½(FᵀF − I), Ė = ½(ḞᵀF + FᵀḞ); S, Ṡ; C = F Fᵀ, D = Ḟ Fᵀ + F Ḟᵀ
      double E[3][3], Ed[3][3], S[3][3], Sd[3][3], C[3][3], D[3][3];
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) {
          double e = 0, ed = 0, c = 0, d = 0;
          for (int p = 0; p < 3; ++p) {
            e += F[p][i] * F[p][j];
            ed += Fd[p][i] * F[p][j] + F[p][i] * Fd[p][j];
            c += F[i][p] * F[j][p];
            d += Fd[i][p] * F[j][p] + F[i][p] * Fd[j][p];
          }
          E[i][j] = 0.5 * (e - (i == j ? 1.0 : 0.0));
          Ed[i][j] = 0.5 * ed;
          C[i][j] = c;
          D[i][j] = d;
        }
      const double tr = E[0][0] + E[1][1] + E[2][2], trd = Ed[0][0] + Ed[1][1] + Ed[2][2];
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) {
          S[i][j] = 2 * mu_ * E[i][j] + (i == j ? lambda_ * tr : 0.0);
          Sd[i][j] = 2 * mu_ * Ed[i][j] + (i == j ? lambda_ * trd : 0.0);
        }
      // per node: u = F G, u̇ = Ḟ G, S G, Ṡ G
      double U[8][3], Ud[8][3], SG[8][3], SdG[8][3];
      for (int n = 0; n < 8; ++n)
        for (int i = 0; i < 3; ++i) {
          double u = 0, ud = 0, sg = 0, sdg = 0;
          for (int j = 0; j < 3; ++j) {
            u += F[i][j] * G[n][j];
            ud += Fd[i][j] * G[n][j];
            sg += S[i][j] * G[n][j];
            sdg += Sd[i][j] * G[n][j];
          }
          U[n][i] = u;
          Ud[n][i] = ud;
          SG[n][i] = sg;
          SdG[n][i] = sdg;
        }
      for (int a = 0; a < 8; ++a)
        for (int b = 0; b < 8; ++b) {
          const double gab = G[a][0] * G[b][0] + G[a][1] * G[b][1] + G[a][2] * G[b][2];
          const double sab = G[a][0] * SG[b][0] + G[a][1] * SG[b][1] + G[a][2] * SG[b][2];
          const double sdab = G[a][0] * SdG[b][0] + G[a][1] * SdG[b][1] + G[a][2] * SdG[b][2];
          for (int i = 0; i < 3; ++i)
            for (int m = 0; m < 3; ++m) {
              double ke = lambda_ * U[a][i] * U[b][m] + mu_ * (gab * C[i][m] + U[b][i] * U[a][m]);
              if (i == m) ke += sab;
              const std::size_t at = static_cast<std::size_t>(3 * a + i) * 24 + 3 * b + m;
              if (!damped) {
                dq[at] += w * ke;
                continue;
              }
              double kd = lambda_ * (Ud[a][i] * U[b][m] + U[a][i] * Ud[b][m]) +
                          mu_ * (U[b][i] * Ud[a][m] + Ud[b][i] * U[a][m] + gab * D[i][m]);
              if (i == m) kd += sdab;
              dq[at] += w * (ke + beta * kd);
              dv[at] += w * beta * ke;
            }
        }
    }
  }

  // M ⊗ I₃ couples a node's coordinate only with the same coordinate of the other nodes
  std::span<const std::uint32_t> mass_structure() const override {
    static const std::array<std::uint32_t, 192> structure = [] {
      std::array<std::uint32_t, 192> s{};
      std::size_t k = 0;
      for (std::uint32_t r = 0; r < 24; ++r)
        for (std::uint32_t c = r % 3; c < 24; c += 3) s[k++] = r * 24 + c;
      return s;
    }();
    return structure;
  }

  // the consistent mass matrix, constant: M ⊗ I₃ in the nodes' (x, y, z) order
  void mass_matrix(const double*, const double*, double, std::vector<double>& da) const override {
    da.assign(576, 0.0);
    for (int m = 0; m < 8; ++m)
      for (int n = 0; n < 8; ++n)
        for (int i = 0; i < 3; ++i) da[(3 * m + i) * 24 + 3 * n + i] = mass_[m][n];
  }

  void evaluate(const double* q, const double* v, const double* a, double t, bool jacobian,
                ForceEval& out) const override {
    out.g.assign(24, 0.0);
    for (int m = 0; m < 8; ++m)
      for (int n = 0; n < 8; ++n)
        for (int i = 0; i < 3; ++i) out.g[3 * m + i] += mass_[m][n] * a[3 * n + i];
    for (int i = 0; i < 24; ++i) out.g[i] -= gravity_[i];
    const double beta = mat_.damping;
    if (beta > 0) {  // f(x) + β K(x) ẋ: the first-order Taylor coefficient along ẋ
      Jet1<double> x[24], f[24];
      for (int i = 0; i < 24; ++i) x[i] = Jet1<double>(q[i], v[i]);
      elastic(x, f);
      for (int i = 0; i < 24; ++i) out.g[i] += f[i].c0 + beta * f[i].c1;
    } else {
      double f[24];
      elastic(q, f);
      for (int i = 0; i < 24; ++i) out.g[i] += f[i];
    }
    if (!jacobian) return;
    out.dq.assign(576, 0.0);
    out.dv.assign(576, 0.0);
    mass_matrix(q, v, t, out.da);
    tangent(q, v, beta, out.dq.data(), out.dv.data());
  }

  double kinetic_energy(const double* q, const double* v) const override {
    double e = 0;
    for (int m = 0; m < 8; ++m)
      for (int n = 0; n < 8; ++n)
        for (int i = 0; i < 3; ++i) e += 0.5 * v[3 * m + i] * mass_[m][n] * v[3 * n + i];
    return e;
  }
  double potential_energy(const double* q, double t) const override {
    double e = 0;
    for (int i = 0; i < 24; ++i) e -= gravity_[i] * q[i];
    for (int k = 0; k < 8; ++k) {
      Mat3<double> F;
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
          for (int n = 0; n < 8; ++n) F(i, j) += q[3 * n + i] * grad_[k][n][j];
      Mat3<double> E = transpose(F) * F;
      for (int i = 0; i < 3; ++i) E(i, i) -= 1.0;
      double tr = 0, ee = 0;
      for (int i = 0; i < 3; ++i) tr += 0.5 * E(i, i);
      for (int i = 0; i < 9; ++i) ee += 0.25 * E.m[i] * E.m[i];
      e += (0.5 * lambda_ * tr * tr + mu_ * ee) * wdet_[k];
    }
    return e;
  }

 private:
  HexMaterial mat_;
  double lambda_ = 0, mu_ = 0;
  double grad_[8][8][3] = {};
  double wdet_[8] = {};
  double mass_[8][8] = {};
  double gravity_[24] = {};
};

}  // namespace

std::unique_ptr<Force> make_hexahedron(const Model& model, const std::array<int, 8>& nodes,
                                       const HexMaterial& material, std::string name) {
  std::array<Vec3<double>, 8> X;
  std::vector<int> list(nodes.begin(), nodes.end());
  for (int k = 0; k < 8; ++k) {
    const Body& b = model.bodies[nodes[k]];
    if (b.kind != BodyKind::node)
      throw ModelError(name + ": node " + std::to_string(k) + " ('" + b.name +
                       "') is not a flexible-body node");
    X[k] = b.pose.r;
  }
  auto f = std::make_unique<Hexahedron>(X, material, model.gravity, name);
  bind_bodies(model, list, f->dofs);
  f->name = std::move(name);
  return f;
}

}  // namespace strata::mbd
