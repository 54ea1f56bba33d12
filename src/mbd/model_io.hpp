// strata::mbd — reading models from JSON (schema: docs/model-format.md).
//
// Every error is a ModelError whose message starts with the file and the JSON path of
// the offending value, e.g. "squeezer.json: joints[3].body_j: unknown body 'wheel7'".
// Unknown keys are errors too (they are usually typos).
#pragma once

#include <nlohmann/json.hpp>
#include <string>

#include "mbd/model.hpp"

namespace strata::mbd {

/// Reads and builds the model in a JSON file. Throws ModelError.
Model load_model(const std::string& path);

/// Parses JSON `text` and builds the model; `source` (a file name) prefixes messages,
/// and invalid JSON is reported as "SOURCE:LINE:COLUMN: invalid JSON: ...". Throws
/// ModelError. load_model is this on the contents of a file.
Model parse_model(const std::string& text, const std::string& source = "model");

/// Builds a model from a parsed JSON document; `source` prefixes messages.
Model build_model(const nlohmann::json& doc, const std::string& source = "model");

}  // namespace strata::mbd
