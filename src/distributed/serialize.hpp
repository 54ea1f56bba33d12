// strata — the analysis as bytes, so that rank 0 computes it once and broadcasts it
// (docs/distributed.md). Every field of Analysis is written, in declaration order; a
// field added to Analysis (or to a struct inside it) must be added here too — the
// round-trip test in tests/unit/test_distributed_serialize.cpp compares every field.
#pragma once

#include <vector>

#include "analysis/analysis.hpp"

namespace strata::distributed {

/// The bytes of `an` (native byte order and widths: every rank runs the same build).
std::vector<char> serialize(const Analysis& an);

/// The Analysis whose bytes these are. Throws InvalidInput when they are cut short or
/// have bytes left over.
Analysis deserialize(const std::vector<char>& bytes);

}  // namespace strata::distributed
