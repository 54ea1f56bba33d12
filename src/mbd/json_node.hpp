// strata::mbd — a JSON value with its path in the document, for the model reader
// (model_io.cpp): typed accessors that check what they read and throw ModelError naming
// the path ("joints[3].axis: expected an array of 3 numbers"), and a check for unknown
// keys, whose usual cause is a typo.
#pragma once

#include <fmt/core.h>

#include <cmath>
#include <initializer_list>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "mbd/linalg.hpp"
#include "mbd/model_io.hpp"

namespace strata::mbd::detail {

// A JSON value together with its path, for messages.
struct Node {
  const nlohmann::json& j;
  std::string path;

  [[noreturn]] void fail(const std::string& msg) const { throw ModelError(path + ": " + msg); }
  bool has(const char* key) const { return j.is_object() && j.contains(key); }
  Node at(const char* key) const {
    if (!j.is_object()) fail("expected an object");
    if (!j.contains(key)) fail(std::string("missing required key \"") + key + "\"");
    return {j.at(key), path.empty() ? std::string(key) : path + "." + key};
  }
  Node at(std::size_t i) const { return {j.at(i), path + "[" + std::to_string(i) + "]"}; }
  std::size_t size() const { return j.size(); }
  // Rejects keys not in `allowed` (typos are the usual cause).
  void keys(std::initializer_list<const char*> allowed) const {
    if (!j.is_object()) fail("expected an object");
    for (const auto& [k, v] : j.items()) {
      bool ok = false;
      for (const char* a : allowed) ok |= k == a;
      if (!ok) {
        std::string list;
        for (const char* a : allowed) list += (list.empty() ? "" : ", ") + std::string(a);
        throw ModelError(path + "." + k + ": unknown key (allowed here: " + list + ")");
      }
    }
  }
  double number() const {
    if (!j.is_number()) fail("expected a number, got " + std::string(j.type_name()));
    const double v = j.get<double>();
    if (!std::isfinite(v)) fail("not a finite number");
    return v;
  }
  double number(const char* key, double def) const { return has(key) ? at(key).number() : def; }
  double positive(const char* key) const {
    const double v = at(key).number();
    if (!(v > 0)) at(key).fail(fmt::format("must be positive, got {:.3e}", v));
    return v;
  }
  double nonnegative(const char* key, double def) const {
    const double v = number(key, def);
    if (v < 0) at(key).fail("must not be negative");
    return v;
  }
  std::string string() const {
    if (!j.is_string()) fail("expected a string, got " + std::string(j.type_name()));
    return j.get<std::string>();
  }
  std::string string(const char* key, const std::string& def) const {
    return has(key) ? at(key).string() : def;
  }
  bool boolean(const char* key, bool def) const {
    if (!has(key)) return def;
    const Node b = at(key);
    if (!b.j.is_boolean()) b.fail("expected true or false");
    return b.j.get<bool>();
  }
  std::vector<double> numbers(std::size_t n) const {
    if (!j.is_array() || j.size() != n)
      fail("expected an array of " + std::to_string(n) + " numbers");
    std::vector<double> r;
    for (std::size_t i = 0; i < n; ++i) r.push_back(at(i).number());
    return r;
  }
  // A point or vector of the model's dimension (planar: 2 numbers, z = 0).
  Vec3<double> vec(int dim) const {
    const auto v = numbers(dim);
    return {{v[0], v[1], dim == 3 ? v[2] : 0.0}};
  }
};

}  // namespace strata::mbd::detail
