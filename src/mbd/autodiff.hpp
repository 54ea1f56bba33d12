// strata::mbd — forward-mode automatic differentiation and truncated Taylor series.
//
// Every constraint and force of the engine is written once as a template over a scalar
// type T. Evaluating it with
//   - double                     gives the value;
//   - Dual<double, N>            gives the value and N first derivatives (a Jacobian row);
//   - Dual<Dual<double, N>, N>   gives second derivatives (Hessians);
//   - Jet1<S> / Jet2<S>          gives the first / second time derivative along the
//                                 path q(s) = q + v s + a s²/2 (truncated Taylor series,
//                                 Griewank & Walther, "Evaluating Derivatives", 2008, §13).
// Derivatives obtained this way are exact to rounding (no differencing), so the Newton
// Jacobian is the consistent tangent of the residual. Units: none (pure arithmetic).
#pragma once

#include <array>
#include <cmath>

namespace strata::mbd {

// ---------------------------------------------------------------- Dual numbers --------
/// A value with N directional derivatives: x = v + Σ d_k ε_k, ε_k ε_l = 0.
template <class S, int N>
struct Dual {
  S v{};
  std::array<S, N> d{};
  Dual() = default;
  Dual(double c) : v(c) {}  // NOLINT: constants promote implicitly
  Dual(const S& value, int k) : v(value) { d[k] = S(1.0); }
};

/// The plain value of any scalar type (for branching and output).
inline double value(double x) { return x; }
template <class S, int N>
double value(const Dual<S, N>& x) {
  return value(x.v);
}

template <class S, int N>
Dual<S, N> operator-(const Dual<S, N>& a) {
  Dual<S, N> r;
  r.v = -a.v;
  for (int k = 0; k < N; ++k) r.d[k] = -a.d[k];
  return r;
}
template <class S, int N>
Dual<S, N> operator+(const Dual<S, N>& a, const Dual<S, N>& b) {
  Dual<S, N> r;
  r.v = a.v + b.v;
  for (int k = 0; k < N; ++k) r.d[k] = a.d[k] + b.d[k];
  return r;
}
template <class S, int N>
Dual<S, N> operator-(const Dual<S, N>& a, const Dual<S, N>& b) {
  Dual<S, N> r;
  r.v = a.v - b.v;
  for (int k = 0; k < N; ++k) r.d[k] = a.d[k] - b.d[k];
  return r;
}
template <class S, int N>
Dual<S, N> operator*(const Dual<S, N>& a, const Dual<S, N>& b) {
  Dual<S, N> r;
  r.v = a.v * b.v;
  for (int k = 0; k < N; ++k) r.d[k] = a.v * b.d[k] + a.d[k] * b.v;
  return r;
}
template <class S, int N>
Dual<S, N> operator*(const Dual<S, N>& a, double c) {
  Dual<S, N> r;
  r.v = a.v * c;
  for (int k = 0; k < N; ++k) r.d[k] = a.d[k] * c;
  return r;
}
template <class S, int N>
Dual<S, N> operator*(double c, const Dual<S, N>& a) {
  return a * c;
}
template <class S, int N>
Dual<S, N> operator+(const Dual<S, N>& a, double c) {
  Dual<S, N> r = a;
  r.v = r.v + c;
  return r;
}
template <class S, int N>
Dual<S, N> operator+(double c, const Dual<S, N>& a) {
  return a + c;
}
template <class S, int N>
Dual<S, N> operator-(const Dual<S, N>& a, double c) {
  return a + (-c);
}
template <class S, int N>
Dual<S, N> operator-(double c, const Dual<S, N>& a) {
  return (-a) + c;
}
/// Applies a function with value f and derivative df (both at a.v) by the chain rule.
template <class S, int N>
Dual<S, N> chain(const Dual<S, N>& a, const S& f, const S& df) {
  Dual<S, N> r;
  r.v = f;
  for (int k = 0; k < N; ++k) r.d[k] = df * a.d[k];
  return r;
}
template <class S, int N>
Dual<S, N> operator/(const Dual<S, N>& a, const Dual<S, N>& b) {
  const S inv = 1.0 / b.v;
  return a * chain(b, inv, -(inv * inv));
}
template <class S, int N>
Dual<S, N> operator/(const Dual<S, N>& a, double c) {
  return a * (1.0 / c);
}
template <class S, int N>
Dual<S, N> operator/(double c, const Dual<S, N>& b) {
  const S inv = 1.0 / b.v;
  return chain(b, c * inv, -(c * inv * inv));
}
template <class S, int N>
Dual<S, N> sin(const Dual<S, N>& a) {
  using std::cos, std::sin;
  return chain(a, S(sin(a.v)), S(cos(a.v)));
}
template <class S, int N>
Dual<S, N> cos(const Dual<S, N>& a) {
  using std::cos, std::sin;
  return chain(a, S(cos(a.v)), S(-sin(a.v)));
}
template <class S, int N>
Dual<S, N> sqrt(const Dual<S, N>& a) {
  using std::sqrt;
  const S r = sqrt(a.v);
  return chain(a, r, S(0.5 / r));
}
template <class S, int N>
Dual<S, N> atan2(const Dual<S, N>& y, const Dual<S, N>& x) {
  using std::atan2;
  const S inv = 1.0 / (x.v * x.v + y.v * y.v);
  Dual<S, N> r;
  r.v = atan2(y.v, x.v);
  for (int k = 0; k < N; ++k) r.d[k] = (x.v * y.d[k] - y.v * x.d[k]) * inv;
  return r;
}

// ------------------------------------------------------- Taylor series in time -------
/// First-order Taylor series c0 + c1 s: a quantity and its time derivative.
template <class S>
struct Jet1 {
  S c0{}, c1{};
  Jet1() = default;
  Jet1(double c) : c0(c) {}  // NOLINT
  Jet1(const S& a, const S& b) : c0(a), c1(b) {}
};
template <class S>
double value(const Jet1<S>& x) {
  return value(x.c0);
}
template <class S>
Jet1<S> operator-(const Jet1<S>& a) {
  return {-a.c0, -a.c1};
}
template <class S>
Jet1<S> operator+(const Jet1<S>& a, const Jet1<S>& b) {
  return {a.c0 + b.c0, a.c1 + b.c1};
}
template <class S>
Jet1<S> operator-(const Jet1<S>& a, const Jet1<S>& b) {
  return {a.c0 - b.c0, a.c1 - b.c1};
}
template <class S>
Jet1<S> operator*(const Jet1<S>& a, const Jet1<S>& b) {
  return {a.c0 * b.c0, a.c0 * b.c1 + a.c1 * b.c0};
}
template <class S>
Jet1<S> operator*(const Jet1<S>& a, double c) {
  return {a.c0 * c, a.c1 * c};
}
template <class S>
Jet1<S> operator*(double c, const Jet1<S>& a) {
  return a * c;
}
template <class S>
Jet1<S> operator+(const Jet1<S>& a, double c) {
  return {a.c0 + c, a.c1};
}
template <class S>
Jet1<S> operator+(double c, const Jet1<S>& a) {
  return a + c;
}
template <class S>
Jet1<S> operator-(const Jet1<S>& a, double c) {
  return {a.c0 - c, a.c1};
}
template <class S>
Jet1<S> operator-(double c, const Jet1<S>& a) {
  return {c - a.c0, -a.c1};
}
template <class S>
Jet1<S> operator/(const Jet1<S>& a, const Jet1<S>& b) {
  const S q0 = a.c0 / b.c0;
  return {q0, (a.c1 - q0 * b.c1) / b.c0};
}
template <class S>
Jet1<S> operator/(const Jet1<S>& a, double c) {
  return a * (1.0 / c);
}
template <class S>
Jet1<S> operator/(double c, const Jet1<S>& b) {
  return Jet1<S>(c) / b;
}
template <class S>
Jet1<S> sin(const Jet1<S>& a) {
  using std::cos, std::sin;
  return {sin(a.c0), cos(a.c0) * a.c1};
}
template <class S>
Jet1<S> cos(const Jet1<S>& a) {
  using std::cos, std::sin;
  return {cos(a.c0), -(sin(a.c0) * a.c1)};
}
template <class S>
Jet1<S> sqrt(const Jet1<S>& a) {
  using std::sqrt;
  const S r = sqrt(a.c0);
  return {r, a.c1 / (2.0 * r)};
}
template <class S>
Jet1<S> atan2(const Jet1<S>& y, const Jet1<S>& x) {
  using std::atan2;
  return {atan2(y.c0, x.c0), (x.c0 * y.c1 - y.c0 * x.c1) / (x.c0 * x.c0 + y.c0 * y.c0)};
}

/// Second-order Taylor series c0 + c1 s + c2 s². Along q(s) = q + v s + a s²/2 a
/// function Φ(q(s), t + s) has c0 = Φ, c1 = Φ̇, 2 c2 = Φ̈.
template <class S>
struct Jet2 {
  S c0{}, c1{}, c2{};
  Jet2() = default;
  Jet2(double c) : c0(c) {}  // NOLINT
  Jet2(const S& a, const S& b, const S& c) : c0(a), c1(b), c2(c) {}
};
template <class S>
double value(const Jet2<S>& x) {
  return value(x.c0);
}
template <class S>
Jet2<S> operator-(const Jet2<S>& a) {
  return {-a.c0, -a.c1, -a.c2};
}
template <class S>
Jet2<S> operator+(const Jet2<S>& a, const Jet2<S>& b) {
  return {a.c0 + b.c0, a.c1 + b.c1, a.c2 + b.c2};
}
template <class S>
Jet2<S> operator-(const Jet2<S>& a, const Jet2<S>& b) {
  return {a.c0 - b.c0, a.c1 - b.c1, a.c2 - b.c2};
}
template <class S>
Jet2<S> operator*(const Jet2<S>& a, const Jet2<S>& b) {
  return {a.c0 * b.c0, a.c0 * b.c1 + a.c1 * b.c0, a.c0 * b.c2 + a.c1 * b.c1 + a.c2 * b.c0};
}
template <class S>
Jet2<S> operator*(const Jet2<S>& a, double c) {
  return {a.c0 * c, a.c1 * c, a.c2 * c};
}
template <class S>
Jet2<S> operator*(double c, const Jet2<S>& a) {
  return a * c;
}
template <class S>
Jet2<S> operator+(const Jet2<S>& a, double c) {
  return {a.c0 + c, a.c1, a.c2};
}
template <class S>
Jet2<S> operator+(double c, const Jet2<S>& a) {
  return a + c;
}
template <class S>
Jet2<S> operator-(const Jet2<S>& a, double c) {
  return {a.c0 - c, a.c1, a.c2};
}
template <class S>
Jet2<S> operator-(double c, const Jet2<S>& a) {
  return {c - a.c0, -a.c1, -a.c2};
}
template <class S>
Jet2<S> operator/(const Jet2<S>& a, const Jet2<S>& b) {
  const S q0 = a.c0 / b.c0;
  const S q1 = (a.c1 - q0 * b.c1) / b.c0;
  return {q0, q1, (a.c2 - q0 * b.c2 - q1 * b.c1) / b.c0};
}
template <class S>
Jet2<S> operator/(const Jet2<S>& a, double c) {
  return a * (1.0 / c);
}
template <class S>
Jet2<S> operator/(double c, const Jet2<S>& b) {
  return Jet2<S>(c) / b;
}
template <class S>
Jet2<S> sin(const Jet2<S>& a) {
  using std::cos, std::sin;
  const S s = sin(a.c0), c = cos(a.c0);
  return {s, c * a.c1, c * a.c2 - 0.5 * (s * a.c1 * a.c1)};
}
template <class S>
Jet2<S> cos(const Jet2<S>& a) {
  using std::cos, std::sin;
  const S s = sin(a.c0), c = cos(a.c0);
  return {c, -(s * a.c1), -(s * a.c2) - 0.5 * (c * a.c1 * a.c1)};
}
template <class S>
Jet2<S> sqrt(const Jet2<S>& a) {
  using std::sqrt;
  const S r0 = sqrt(a.c0);
  const S r1 = a.c1 / (2.0 * r0);
  return {r0, r1, (a.c2 - r1 * r1) / (2.0 * r0)};
}

}  // namespace strata::mbd
