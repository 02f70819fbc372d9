#include "daemon/calibration.hpp"

#include <cmath>

#include <fmt/format.h>
#include <toml++/toml.h>

#include "core/error.hpp"
#include "core/toml_reader.hpp"
#include "core/units.hpp"
#include "solver/align/profile.hpp"

namespace facecap::daemon {
namespace {

ErrorLocation where(const toml::node& node, const std::string& file, std::string key) {
  const auto& begin = node.source().begin;
  return {.file = file, .line = int64_t(begin.line), .column = int64_t(begin.column), .key = std::move(key)};
}

template <int N>
Eigen::Matrix<double, N, 1> read_vector(const toml::node& node, const std::string& file, const std::string& key) {
  const toml::array* array = node.as_array();
  if (!array || array->size() != std::size_t(N))
    throw Error(fmt::format("expected an array of {} numbers", N), where(node, file, key));
  Eigen::Matrix<double, N, 1> v;
  for (int i = 0; i < N; ++i) {
    const auto value = (*array)[std::size_t(i)].value<double>();
    if (!value || !std::isfinite(*value))  // toml++ reads nan and inf as numbers
      throw Error(fmt::format("expected an array of {} finite numbers", N), where(node, file, key));
    v[i] = *value;
  }
  return v;
}

MarkerBinding read_face_marker(const toml::table& entry, const std::string& file, std::size_t index, const Rig& rig) {
  const std::string key = fmt::format("face[{}]", index);
  const auto label = entry["label"].value<std::string>();
  if (!label || label->empty()) throw Error("a face marker needs a label", where(entry, file, key));
  auto check_vertex = [&](double v, const toml::node& node) {  // double: vertices are read as numbers
    if (!(v >= 0 && v < double(rig.vertex_count())))
      throw Error(fmt::format("vertex {} is not in the rig's 0 to {}", v, rig.vertex_count() - 1), where(node, file, key));
    return int(v);
  };
  if (const toml::node* vertex = entry.get("vertex")) {
    const auto v = vertex->value_exact<int64_t>();
    if (!v) throw Error("vertex must be an integer", where(*vertex, file, key));
    return MarkerBinding::at_vertex(*label, check_vertex(double(*v), *vertex));
  }
  const toml::node* vertices = entry.get("vertices");
  const toml::node* barycentric = entry.get("barycentric");
  if (!vertices || !barycentric)
    throw Error(fmt::format("face marker '{}' needs vertex, or vertices and barycentric", *label), where(entry, file, key));
  const Eigen::Vector3d ids = read_vector<3>(*vertices, file, key);
  MarkerBinding b;
  b.label = *label;
  for (int i = 0; i < 3; ++i) b.vertices[std::size_t(i)] = check_vertex(ids[i], *vertices);
  b.barycentric = read_vector<3>(*barycentric, file, key);
  if (std::abs(b.barycentric.sum() - 1.0) > 1e-6)
    throw Error("barycentric coordinates must sum to 1", where(*barycentric, file, key));
  return b;
}

// A `facecap calibrate` profile: the similarity it measured maps markers to rig space,
// its stable markers become the head markers (at their calibration-frame positions),
// and each face marker's rest position off its bound point becomes its offset.
MarkerCalibration from_profile(const std::string& file, const Rig& rig) {
  const align::Calibration profile = align::load_calibration_profile(file);
  align::check_profile_matches_rig(profile, rig, file);
  MarkerCalibration calibration;
  calibration.origin = file + " (facecap calibrate profile)";
  calibration.marker_mm_per_unit = profile.take_mm_per_unit;
  calibration.marker_scale = profile.take_to_rig.scale;
  calibration.T_rig_marker.linear() = profile.take_to_rig.rotation;
  calibration.T_rig_marker.translation() = profile.take_to_rig.translation;
  for (const align::MarkerCalibration& marker : profile.markers) {
    MarkerBinding binding = marker.binding;
    binding.label = marker.label;
    calibration.markers.face.push_back(std::move(binding));
    calibration.face_offsets.push_back(profile.take_to_rig.apply(marker.neutral) - marker.bound_point);
  }
  for (const std::string& label : profile.stable_markers) {
    const int k = profile.find(label);
    if (k < 0)
      throw Error(fmt::format("stable marker '{}' is not among the profile's markers", label),
                  {.file = file, .key = "stabilise.markers"});
    calibration.markers.head.push_back({label, profile.take_to_rig.apply(profile.markers[std::size_t(k)].neutral)});
  }
  const std::size_t heads = calibration.markers.head.size();
  if (heads == 1 || heads == 2)
    throw Error("head stabilisation needs at least 3 stable markers (or none)", {.file = file, .key = "stabilise.markers"});
  return calibration;
}

MarkerCalibration read_calibration_file(const std::string& file, const Rig& rig) {
  const toml::table table = parse_toml_file(file);
  if (table.contains("transform") && table.contains("marker")) return from_profile(file, rig);
  if (table["version"].value_or<int64_t>(0) != 1) throw Error("calibration needs version = 1", {.file = file, .key = "version"});
  MarkerCalibration calibration;
  calibration.origin = file;
  if (const toml::node* units = table.get("marker_units")) {
    calibration.marker_mm_per_unit = millimetres_per_unit(units->value_or<std::string>("")).value_or(0.0);
    if (calibration.marker_mm_per_unit <= 0.0)
      throw Error("marker_units must be \"mm\", \"cm\" or \"m\"", where(*units, file, "marker_units"));
  }
  if (const toml::node* rotation = table.get("rotation_wxyz")) {
    const Eigen::Vector4d q = read_vector<4>(*rotation, file, "rotation_wxyz");
    if (q.norm() < 1e-9) throw Error("rotation_wxyz must be a non-zero quaternion", where(*rotation, file, "rotation_wxyz"));
    calibration.T_rig_marker.linear() = Eigen::Quaterniond(q[0], q[1], q[2], q[3]).normalized().toRotationMatrix();
  }
  if (const toml::node* translation = table.get("translation"))
    calibration.T_rig_marker.translation() = read_vector<3>(*translation, file, "translation");
  if (const toml::array* face = table["face"].as_array()) {
    for (std::size_t i = 0; i < face->size(); ++i) {
      const toml::table* entry = (*face)[i].as_table();
      if (!entry) throw Error("[[face]] entries must be tables", where((*face)[i], file, "face"));
      calibration.markers.face.push_back(read_face_marker(*entry, file, i, rig));
    }
  }
  if (calibration.markers.face.size() < 3) throw Error("a calibration needs at least 3 [[face]] markers", {.file = file, .key = "face"});
  if (const toml::array* head = table["head"].as_array()) {
    for (std::size_t i = 0; i < head->size(); ++i) {
      const toml::table* entry = (*head)[i].as_table();
      const std::string key = fmt::format("head[{}]", i);
      if (!entry) throw Error("[[head]] entries must be tables", where((*head)[i], file, key));
      const auto label = (*entry)["label"].value<std::string>();
      const toml::node* position = entry->get("position");
      if (!label || !position) throw Error("a head marker needs label and position", where(*entry, file, key));
      calibration.markers.head.push_back({*label, read_vector<3>(*position, file, key)});
    }
  }
  const std::size_t heads = calibration.markers.head.size();
  if (heads == 1 || heads == 2) throw Error("head stabilisation needs at least 3 [[head]] markers (or none)", {.file = file, .key = "head"});
  return calibration;
}

}  // namespace

MarkerCalibration load_calibration(const config::CalibrationSection& section, const Rig& rig) {
  if (!section.file.empty()) return read_calibration_file(section.file, rig);
  MarkerCalibration calibration;
  calibration.markers = default_marker_set(rig, int(section.face_markers), int(section.head_markers));
  calibration.origin = "default marker set";
  return calibration;
}

double marker_to_rig_scale(const MarkerCalibration& calibration, const std::string& source_units, const Rig& rig) {
  if (calibration.marker_scale > 0.0) return calibration.marker_scale;
  const double mm_per_unit = calibration.marker_mm_per_unit > 0.0 ? calibration.marker_mm_per_unit
                                                                  : millimetres_per_unit(source_units).value_or(0.0);
  return mm_per_unit > 0.0 ? mm_per_unit * rig_units_per_mm(rig) : 1.0;
}

}  // namespace facecap::daemon
