#include "pipeline/calibration.hpp"

#include <cmath>
#include <set>

#include <fmt/format.h>

#include "core/error.hpp"
#include "core/io.hpp"
#include "core/toml_reader.hpp"
#include "core/units.hpp"
#include "solver/align/profile.hpp"

namespace facecap::pipeline {
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
    if (!value || !std::isfinite(*value))
      throw Error(fmt::format("expected an array of {} finite numbers", N), where(node, file, key));
    v[i] = *value;
  }
  return v;
}

MarkerBinding read_face_marker(const toml::table& entry, const std::string& file, std::size_t index, const Rig& rig) {
  const std::string key = fmt::format("face[{}]", index);
  const auto label = entry["label"].value<std::string>();
  if (!label || label->empty()) throw Error("a face marker needs a label", where(entry, file, key));
  auto check_vertex = [&](double v, const toml::node& node) {
    if (!(v >= 0 && v < double(rig.vertex_count())) || v != std::floor(v))
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

// A hand-written calibration: markers in `marker_units` (default: the rig's), moved into
// rig space by rotation_wxyz and translation. Each face marker's calibration-frame
// position is its bound point carried back into marker space, so the markers carry no
// identity offset; head markers are given in rig space.
Calibration read_hand_written(const toml::table& table, const std::string& file, const Rig& rig) {
  if (table["version"].value_or<int64_t>(0) != 1) throw Error("calibration needs version = 1", {.file = file, .key = "version"});
  Calibration c;
  c.rig_name = rig.name;
  c.rig_hash = rig.content_hash();
  c.rig_mm_per_unit = 1.0 / rig_units_per_mm(rig);
  c.take_mm_per_unit = c.rig_mm_per_unit;
  c.source_take = file;
  if (const toml::node* units = table.get("marker_units")) {
    c.take_mm_per_unit = millimetres_per_unit(units->value_or<std::string>("")).value_or(0.0);
    if (c.take_mm_per_unit <= 0.0)
      throw Error("marker_units must be \"mm\", \"cm\" or \"m\"", where(*units, file, "marker_units"));
  }
  c.take_to_rig.scale = c.take_mm_per_unit / c.rig_mm_per_unit;
  if (const toml::node* rotation = table.get("rotation_wxyz")) {
    const Eigen::Vector4d q = read_vector<4>(*rotation, file, "rotation_wxyz");
    if (q.norm() < 1e-9) throw Error("rotation_wxyz must be a non-zero quaternion", where(*rotation, file, "rotation_wxyz"));
    c.take_to_rig.rotation = Eigen::Quaterniond(q[0], q[1], q[2], q[3]).normalized().toRotationMatrix();
  }
  if (const toml::node* translation = table.get("translation"))
    c.take_to_rig.translation = read_vector<3>(*translation, file, "translation");
  std::set<std::string> labels;
  auto unique = [&](const std::string& label, const toml::node& node, const std::string& key) {
    if (!labels.insert(label).second) throw Error(fmt::format("marker '{}' is given twice", label), where(node, file, key));
  };
  if (const toml::array* face = table["face"].as_array()) {
    for (std::size_t i = 0; i < face->size(); ++i) {
      const toml::table* entry = (*face)[i].as_table();
      if (!entry) throw Error("[[face]] entries must be tables", where((*face)[i], file, "face"));
      align::MarkerCalibration m;
      m.binding = read_face_marker(*entry, file, i, rig);
      m.label = m.binding.label;
      unique(m.label, *entry, fmt::format("face[{}]", i));
      m.bound_point = binding_point(m.binding, rig.neutral);
      m.neutral = c.take_to_rig.inverse().apply(m.bound_point);
      c.markers.push_back(std::move(m));
    }
  }
  if (c.markers.size() < 3) throw Error("a calibration needs at least 3 [[face]] markers", {.file = file, .key = "face"});
  if (const toml::array* head = table["head"].as_array()) {
    for (std::size_t i = 0; i < head->size(); ++i) {
      const toml::table* entry = (*head)[i].as_table();
      const std::string key = fmt::format("head[{}]", i);
      if (!entry) throw Error("[[head]] entries must be tables", where((*head)[i], file, key));
      const auto label = (*entry)["label"].value<std::string>();
      const toml::node* position = entry->get("position");
      if (!label || label->empty() || !position) throw Error("a head marker needs label and position", where(*entry, file, key));
      unique(*label, *entry, key);
      c.head_markers.push_back({*label, c.take_to_rig.inverse().apply(read_vector<3>(*position, file, key))});
      c.stable_markers.push_back(*label);
    }
  }
  const std::size_t heads = c.head_markers.size();
  if (heads == 1 || heads == 2)
    throw Error("head stabilisation needs at least 3 [[head]] markers (or none)", {.file = file, .key = "head"});
  align::find_unobserved_shapes(c, rig);
  return c;
}

}  // namespace

Calibration read_calibration(std::string_view text, const std::string& name, const Rig& rig) {
  const toml::table table = parse_toml(text, name);
  if (!(table.contains("transform") && table.contains("marker"))) return read_hand_written(table, name, rig);
  Calibration profile = align::read_calibration_profile(text, name);
  align::check_profile_matches_rig(profile, rig, name);
  if (!profile.observability_known) align::find_unobserved_shapes(profile, rig);  // a profile from before version 3
  const std::size_t stable = profile.stable_markers.size();
  if (stable == 1 || stable == 2)
    throw Error("head stabilisation needs at least 3 stable markers (or none)", {.file = name, .key = "stabilise.markers"});
  return profile;
}

Calibration load_calibration(const CalibrationSpec& spec, const Rig& rig) {
  if (spec.file.empty()) return default_calibration(rig, spec.face_markers, spec.head_markers);
  const std::vector<char> bytes = read_file_bytes(spec.file);
  return read_calibration(std::string_view(bytes.data(), bytes.size()), spec.file, rig);
}

Calibration default_calibration(const Rig& rig, int face_markers, int head_markers) {
  const MarkerSet set = default_marker_set(rig, face_markers, head_markers);
  Calibration c;
  c.rig_name = rig.name;
  c.rig_hash = rig.content_hash();
  c.rig_mm_per_unit = 1.0 / rig_units_per_mm(rig);
  c.take_mm_per_unit = c.rig_mm_per_unit;
  c.source_take = "default marker set";
  for (const MarkerBinding& binding : set.face) {
    align::MarkerCalibration m;
    m.label = binding.label;
    m.binding = binding;
    m.bound_point = binding_point(binding, rig.neutral);
    m.neutral = m.bound_point;
    c.markers.push_back(std::move(m));
  }
  for (const HeadMarker& h : set.head) {
    c.head_markers.push_back({h.label, h.position});
    c.stable_markers.push_back(h.label);
  }
  align::find_unobserved_shapes(c, rig);
  return c;
}

MarkerSet rest_marker_set(const Calibration& c) {
  MarkerSet set;
  for (const auto& m : c.markers) set.face.push_back(m.binding);
  for (const auto& h : c.head_markers) set.head.push_back({h.label, c.take_to_rig.apply(h.neutral)});
  return set;
}

}  // namespace facecap::pipeline
