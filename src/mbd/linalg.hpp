// strata::mbd — small fixed-size vectors and matrices over any scalar type (double, Dual,
// Jet), and the rotation kinematics of planar angles and Euler parameters.
//
// Euler parameters p = (e0, e) follow Haug, "Computer-Aided Kinematics and Dynamics of
// Mechanical Systems", 1989, §6.3: E(p) = [-e, ẽ + e0 I], G(p) = [-e, -ẽ + e0 I],
// A(p) = E Gᵀ (homogeneous quadratic form, a rotation when pᵀp = 1), body angular
// velocity ω' = 2 G ṗ, ṗ = ½ Gᵀ ω' for a unit p. Planar: A(φ) = [c -s; s c]
// (Nikravesh, "Computer-Aided Analysis of Mechanical Systems", 1988, §2.4).
#pragma once

#include <array>
#include <cmath>

#include "mbd/autodiff.hpp"

namespace strata::mbd {

template <class T, int N>
struct Vec {
  std::array<T, N> x{};
  T& operator[](int i) { return x[i]; }
  const T& operator[](int i) const { return x[i]; }
};
template <class T>
using Vec2 = Vec<T, 2>;
template <class T>
using Vec3 = Vec<T, 3>;
template <class T>
using Vec4 = Vec<T, 4>;

template <class T, int N>
Vec<T, N> operator+(const Vec<T, N>& a, const Vec<T, N>& b) {
  Vec<T, N> r;
  for (int i = 0; i < N; ++i) r[i] = a[i] + b[i];
  return r;
}
template <class T, int N>
Vec<T, N> operator-(const Vec<T, N>& a, const Vec<T, N>& b) {
  Vec<T, N> r;
  for (int i = 0; i < N; ++i) r[i] = a[i] - b[i];
  return r;
}
template <class T, int N>
Vec<T, N> operator-(const Vec<T, N>& a) {
  Vec<T, N> r;
  for (int i = 0; i < N; ++i) r[i] = -a[i];
  return r;
}
template <class T, int N, class U>
Vec<T, N> operator*(const Vec<T, N>& a, const U& s) {
  Vec<T, N> r;
  for (int i = 0; i < N; ++i) r[i] = a[i] * s;
  return r;
}
template <class T, int N, class U>
Vec<T, N> operator*(const U& s, const Vec<T, N>& a) {
  Vec<T, N> r;
  for (int i = 0; i < N; ++i) r[i] = a[i] * s;
  return r;
}
template <class T, int N>
T dot(const Vec<T, N>& a, const Vec<T, N>& b) {
  T s = a[0] * b[0];
  for (int i = 1; i < N; ++i) s = s + a[i] * b[i];
  return s;
}
template <class T>
Vec3<T> cross(const Vec3<T>& a, const Vec3<T>& b) {
  return {{a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]}};
}
/// Promotes a double vector to scalar type T.
template <class T, int N>
Vec<T, N> lift(const Vec<double, N>& a) {
  Vec<T, N> r;
  for (int i = 0; i < N; ++i) r[i] = T(a[i]);
  return r;
}
template <class T, int N>
Vec<double, N> values(const Vec<T, N>& a) {
  Vec<double, N> r;
  for (int i = 0; i < N; ++i) r[i] = value(a[i]);
  return r;
}
inline double norm(const Vec3<double>& a) { return std::sqrt(dot(a, a)); }

/// Square matrix, row-major.
template <class T, int N>
struct Mat {
  std::array<T, N * N> m{};
  T& operator()(int i, int j) { return m[i * N + j]; }
  const T& operator()(int i, int j) const { return m[i * N + j]; }
  static Mat identity() {
    Mat r;
    for (int i = 0; i < N; ++i) r(i, i) = T(1.0);
    return r;
  }
};
template <class T>
using Mat2 = Mat<T, 2>;
template <class T>
using Mat3 = Mat<T, 3>;

template <class T, int N, class U>
Vec<decltype(T() * U()), N> operator*(const Mat<T, N>& a, const Vec<U, N>& b) {
  Vec<decltype(T() * U()), N> r;
  for (int i = 0; i < N; ++i) {
    r[i] = a(i, 0) * b[0];
    for (int j = 1; j < N; ++j) r[i] = r[i] + a(i, j) * b[j];
  }
  return r;
}
/// Aᵀ b.
template <class T, int N, class U>
Vec<decltype(T() * U()), N> tmul(const Mat<T, N>& a, const Vec<U, N>& b) {
  Vec<decltype(T() * U()), N> r;
  for (int i = 0; i < N; ++i) {
    r[i] = a(0, i) * b[0];
    for (int j = 1; j < N; ++j) r[i] = r[i] + a(j, i) * b[j];
  }
  return r;
}
template <class T, int N>
Mat<T, N> operator*(const Mat<T, N>& a, const Mat<T, N>& b) {
  Mat<T, N> r;
  for (int i = 0; i < N; ++i)
    for (int j = 0; j < N; ++j) {
      r(i, j) = a(i, 0) * b(0, j);
      for (int k = 1; k < N; ++k) r(i, j) = r(i, j) + a(i, k) * b(k, j);
    }
  return r;
}
template <class T, int N>
Mat<T, N> transpose(const Mat<T, N>& a) {
  Mat<T, N> r;
  for (int i = 0; i < N; ++i)
    for (int j = 0; j < N; ++j) r(i, j) = a(j, i);
  return r;
}
template <class T, int N>
Mat<T, N> lift(const Mat<double, N>& a) {
  Mat<T, N> r;
  for (int i = 0; i < N * N; ++i) r.m[i] = T(a.m[i]);
  return r;
}

// ------------------------------------------------------------------ rotations --------
/// Planar rotation matrix A(φ).
template <class T>
Mat2<T> rot2(const T& phi) {
  using std::cos, std::sin;
  const T c = cos(phi), s = sin(phi);
  Mat2<T> a;
  a(0, 0) = c;
  a(0, 1) = -s;
  a(1, 0) = s;
  a(1, 1) = c;
  return a;
}
/// Planar "perpendicular" R = [0 -1; 1 0]: R v turns v by +90°.
template <class T>
Vec2<T> perp(const Vec2<T>& v) {
  return {{-v[1], v[0]}};
}

/// A(p) = E(p) G(p)ᵀ for Euler parameters p (Haug 1989, Eq. 6.3.20).
template <class T>
Mat3<T> rot3(const Vec4<T>& p) {
  const T &e0 = p[0], &e1 = p[1], &e2 = p[2], &e3 = p[3];
  const T e00 = e0 * e0, e11 = e1 * e1, e22 = e2 * e2, e33 = e3 * e3;
  const T e01 = e0 * e1, e02 = e0 * e2, e03 = e0 * e3;
  const T e12 = e1 * e2, e13 = e1 * e3, e23 = e2 * e3;
  Mat3<T> a;
  a(0, 0) = e00 + e11 - e22 - e33;
  a(1, 1) = e00 - e11 + e22 - e33;
  a(2, 2) = e00 - e11 - e22 + e33;
  a(0, 1) = 2.0 * (e12 - e03);
  a(1, 0) = 2.0 * (e12 + e03);
  a(0, 2) = 2.0 * (e13 + e02);
  a(2, 0) = 2.0 * (e13 - e02);
  a(1, 2) = 2.0 * (e23 - e01);
  a(2, 1) = 2.0 * (e23 + e01);
  return a;
}
/// G(p) w for a 4-vector w (3-vector result): G = [-e, -ẽ + e0 I].
template <class T, class U>
Vec3<T> G_times(const Vec4<T>& p, const Vec4<U>& w) {
  const T &e0 = p[0], &e1 = p[1], &e2 = p[2], &e3 = p[3];
  return {{-e1 * w[0] + e0 * w[1] + e3 * w[2] - e2 * w[3],
           -e2 * w[0] - e3 * w[1] + e0 * w[2] + e1 * w[3],
           -e3 * w[0] + e2 * w[1] - e1 * w[2] + e0 * w[3]}};
}
/// G(p)ᵀ u for a 3-vector u (4-vector result).
template <class T, class U>
Vec4<T> GT_times(const Vec4<T>& p, const Vec3<U>& u) {
  const T &e0 = p[0], &e1 = p[1], &e2 = p[2], &e3 = p[3];
  return {{-e1 * u[0] - e2 * u[1] - e3 * u[2], e0 * u[0] - e3 * u[1] + e2 * u[2],
           e3 * u[0] + e0 * u[1] - e1 * u[2], -e2 * u[0] + e1 * u[1] + e0 * u[2]}};
}

/// Euler parameters of a rotation matrix (Shepperd's method), unit norm, e0 ≥ 0.
inline Vec4<double> euler_parameters(const Mat3<double>& a) {
  const double tr = a(0, 0) + a(1, 1) + a(2, 2);
  Vec4<double> p;
  const double c[4] = {tr, a(0, 0), a(1, 1), a(2, 2)};
  int k = 0;
  for (int i = 1; i < 4; ++i)
    if (c[i] > c[k]) k = i;
  if (k == 0) {
    const double e0 = 0.5 * std::sqrt(1 + tr);
    p = {{e0, (a(2, 1) - a(1, 2)) / (4 * e0), (a(0, 2) - a(2, 0)) / (4 * e0),
          (a(1, 0) - a(0, 1)) / (4 * e0)}};
  } else {
    const int i = k - 1, j = (i + 1) % 3, l = (i + 2) % 3;
    const double ei = 0.5 * std::sqrt(1 + 2 * a(i, i) - tr);
    p[0] = (a(l, j) - a(j, l)) / (4 * ei);
    p[1 + i] = ei;
    p[1 + j] = (a(j, i) + a(i, j)) / (4 * ei);
    p[1 + l] = (a(l, i) + a(i, l)) / (4 * ei);
  }
  if (p[0] < 0)
    for (double& e : p.x) e = -e;
  return p;
}

/// Euler parameters of a rotation by `angle` (rad) about the unit axis `axis`.
inline Vec4<double> axis_angle(const Vec3<double>& axis, double angle) {
  const double n = norm(axis), s = std::sin(angle / 2) / n;
  return {{std::cos(angle / 2), axis[0] * s, axis[1] * s, axis[2] * s}};
}

}  // namespace strata::mbd
