// strata fuzz target — the multibody model loader (JSON, docs/model-format.md).
//
// What. Each input is parsed and built with strata::mbd::parse_model, the function
// load_model applies to a file's contents (JSON parse, schema checks, bodies, joints,
// forces, flexible bodies). The defined outcomes are a Model or a ModelError (a
// strata::Error) naming the JSON path; anything else — another exception type
// (nlohmann::json's type_error, std::out_of_range, ...), a crash, a sanitizer report —
// is a finding. A model that builds must have coordinates (Model::n > 0) and initial
// positions and velocities that are finite. Seeds: models/*.json and
// fuzz/corpus/model_json (small models of every body, joint and force type).
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "mbd/model_io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    const strata::mbd::Model m = strata::mbd::parse_model(text, "fuzz.json");
    bool ok = m.n > 0;
    for (double v : m.q0) ok = ok && std::isfinite(v);
    for (double v : m.v0) ok = ok && std::isfinite(v);
    if (!ok) {
      std::fprintf(stderr, "FINDING: a model built with no coordinates or non-finite state\n");
      std::abort();
    }
  } catch (const strata::Error&) {
  }
  return 0;
}
