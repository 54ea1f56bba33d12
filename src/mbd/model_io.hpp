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

/// Reads and parses a model file without building it (the command line keeps the document
/// in checkpoints). Throws ModelError naming the file (and line:column of a JSON error).
nlohmann::json load_model_document(const std::string& path);

/// The name load_model gives a model file in messages: its last path component.
std::string model_file_name(const std::string& path);

/// Parses JSON text and builds the model, as load_model does for a file's contents:
/// `source` (a file path, or e.g. "<dict>") prefixes every message — "source:L:C: invalid
/// JSON: ..." for a syntax error, "name: joints[3].body_j: ..." for a model error, where
/// name is source without its folder. Throws ModelError.
Model parse_model(const std::string& text, const std::string& source = "model");

/// Builds a model from a parsed JSON document; `source` prefixes messages.
Model build_model(const nlohmann::json& doc, const std::string& source = "model");

}  // namespace strata::mbd
