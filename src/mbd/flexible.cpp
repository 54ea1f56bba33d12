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
    if (!jacobian) {
      if (beta > 0) {
        Jet1<double> x[24], f[24];
        for (int i = 0; i < 24; ++i) x[i] = Jet1<double>(q[i], v[i]);
        elastic(x, f);
        for (int i = 0; i < 24; ++i) out.g[i] += f[i].c0 + beta * f[i].c1;
      } else {
        double f[24];
        elastic(q, f);
        for (int i = 0; i < 24; ++i) out.g[i] += f[i];
      }
      return;
    }
    using S = Dual<double, 24>;
    out.dq.assign(576, 0.0);
    out.dv.assign(576, 0.0);
    mass_matrix(q, v, t, out.da);
    if (beta > 0) {
      Jet1<S> x[24], f[24];
      for (int i = 0; i < 24; ++i) x[i] = Jet1<S>(S(q[i], i), S(v[i]));
      elastic(x, f);
      for (int i = 0; i < 24; ++i) {
        out.g[i] += f[i].c0.v + beta * f[i].c1.v;
        for (int k = 0; k < 24; ++k) {
          out.dq[i * 24 + k] = f[i].c0.d[k] + beta * f[i].c1.d[k];
          out.dv[i * 24 + k] = beta * f[i].c0.d[k];
        }
      }
      return;
    }
    S x[24], f[24];
    for (int i = 0; i < 24; ++i) x[i] = S(q[i], i);
    elastic(x, f);
    for (int i = 0; i < 24; ++i) {
      out.g[i] += f[i].v;
      for (int k = 0; k < 24; ++k) out.dq[i * 24 + k] = f[i].d[k];
    }
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
