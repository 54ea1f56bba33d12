// strata::mbd — ParaView series writer (see vtk.hpp).
#include "mbd/vtk.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include "base/atomic_file.hpp"
#include "strata/errors.hpp"

namespace strata::mbd {

VtkSeries::VtkSeries(const Model& model, std::string dir) : model_(model), dir_(std::move(dir)) {
  std::filesystem::create_directories(dir_);
  std::map<index_t, int> point_of_offset;
  for (int k = 0; k < static_cast<int>(model.bodies.size()); ++k)
    if (model.bodies[k].offset >= 0) {
      point_of_offset[model.bodies[k].offset] = static_cast<int>(bodies_.size());
      bodies_.push_back(k);
    }
  // a line between the first two moving bodies of each constraint
  std::set<std::pair<int, int>> seen;
  for (const auto& c : model.constraints) {
    std::vector<int> pts;
    for (index_t d : c->dofs) {
      auto it = point_of_offset.find(d);
      if (it != point_of_offset.end()) pts.push_back(it->second);
    }
    if (pts.size() >= 2) {
      auto e = std::minmax(pts[0], pts[1]);
      if (seen.insert(e).second) lines_.push_back(e);
    }
  }
  for (const FlexMesh& mesh : model.meshes)
    for (const auto& h : mesh.hexahedra) {
      std::array<int, 8> p;
      for (int k = 0; k < 8; ++k)
        p[k] = point_of_offset.at(model.bodies[mesh.node_bodies[h[k]]].offset);
      hexes_.push_back(p);
    }
}

void VtkSeries::write(double t, const double* q) {
  const std::string name = fmt::format("frame_{:06d}.vtu", frames_.size());
  std::ostringstream out;  // written whole (base/atomic_file.hpp) at the end
  const std::size_t np = bodies_.size();
  std::size_t nv = 0;
  for (int k : bodies_) nv += model_.bodies[k].kind != BodyKind::node;
  const std::size_t nc = nv + lines_.size() + hexes_.size();
  out << "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"0.1\">\n"
      << "<UnstructuredGrid>\n<Piece NumberOfPoints=\"" << np << "\" NumberOfCells=\"" << nc
      << "\">\n<Points>\n<DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"ascii\">\n";
  std::vector<std::array<double, 4>> quat(np, {1, 0, 0, 0});
  for (std::size_t i = 0; i < np; ++i) {
    const Body& b = model_.bodies[bodies_[i]];
    const double* x = q + b.offset;
    if (b.kind == BodyKind::planar) {
      out << fmt::format("{:.9g} {:.9g} 0\n", x[0], x[1]);
      quat[i] = {std::cos(x[2] / 2), 0, 0, std::sin(x[2] / 2)};
    } else {
      out << fmt::format("{:.9g} {:.9g} {:.9g}\n", x[0], x[1], x[2]);
      if (b.kind == BodyKind::spatial) quat[i] = {x[3], x[4], x[5], x[6]};
    }
  }
  out << "</DataArray>\n</Points>\n<Cells>\n"
      << "<DataArray type=\"Int64\" Name=\"connectivity\" format=\"ascii\">\n";
  for (std::size_t i = 0; i < np; ++i)
    if (model_.bodies[bodies_[i]].kind != BodyKind::node) out << i << "\n";
  for (const auto& [a, b] : lines_) out << a << " " << b << "\n";
  for (const auto& h : hexes_) {
    for (int k = 0; k < 8; ++k) out << h[k] << (k < 7 ? " " : "\n");
  }
  out << "</DataArray>\n<DataArray type=\"Int64\" Name=\"offsets\" format=\"ascii\">\n";
  std::size_t off = 0, cells = 0;
  for (std::size_t i = 0; i < np; ++i)
    if (model_.bodies[bodies_[i]].kind != BodyKind::node) {
      out << ++off << "\n";
      ++cells;
    }
  for (std::size_t i = 0; i < lines_.size(); ++i) out << (off += 2) << "\n";
  for (std::size_t i = 0; i < hexes_.size(); ++i) out << (off += 8) << "\n";
  out << "</DataArray>\n<DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">\n";
  for (std::size_t i = 0; i < cells; ++i) out << "1\n";
  for (std::size_t i = 0; i < lines_.size(); ++i) out << "3\n";
  for (std::size_t i = 0; i < hexes_.size(); ++i) out << "12\n";
  out << "</DataArray>\n</Cells>\n<PointData>\n"
      << "<DataArray type=\"Float64\" Name=\"orientation\" NumberOfComponents=\"4\" "
         "format=\"ascii\">\n";
  for (const auto& e : quat)
    out << fmt::format("{:.9g} {:.9g} {:.9g} {:.9g}\n", e[0], e[1], e[2], e[3]);
  out << "</DataArray>\n</PointData>\n</Piece>\n</UnstructuredGrid>\n</VTKFile>\n";
  write_file_atomically(dir_ + "/" + name, out.str(), false);
  frames_.emplace_back(t, name);
}

void VtkSeries::finish() {
  std::ostringstream out;
  out << "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\">\n<Collection>\n";
  for (const auto& [t, f] : frames_)
    out << fmt::format("<DataSet timestep=\"{:.9g}\" part=\"0\" file=\"{}\"/>\n", t, f);
  out << "</Collection>\n</VTKFile>\n";
  write_file_atomically(dir_ + "/series.pvd", out.str());
}

}  // namespace strata::mbd
