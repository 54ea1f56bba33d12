// strata::mbd — ParaView output: one VTK XML unstructured grid (.vtu) per output time and
// a series.pvd collection (VTK file formats, Kitware, "VTK User's Guide" 11th ed., ch. 19).
// Rigid bodies are vertices at their centres of mass with an "orientation" quaternion
// (glyph them in ParaView); bodies joined by a constraint are connected by a line;
// flexible bodies are their hexahedra. Each file is written whole (temporary + rename).
#pragma once

#include <string>
#include <vector>

#include "mbd/model.hpp"

namespace strata::mbd {

class VtkSeries {
 public:
  VtkSeries(const Model& model, std::string dir);
  void write(double t, const double* q);
  /// Writes series.pvd listing every frame written.
  void finish();
  /// (time, file name) of every frame written so far; restore_frames continues a series
  /// whose first frames a checkpointed run wrote into the same folder.
  const std::vector<std::pair<double, std::string>>& frames() const { return frames_; }
  void restore_frames(std::vector<std::pair<double, std::string>> frames) {
    frames_ = std::move(frames);
  }

 private:
  const Model& model_;
  std::string dir_;
  std::vector<int> bodies_;                 // moving bodies, one point each
  std::vector<std::pair<int, int>> lines_;  // point pairs
  std::vector<std::array<int, 8>> hexes_;   // point indices
  std::vector<std::pair<double, std::string>> frames_;
};

}  // namespace strata::mbd
