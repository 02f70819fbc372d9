#include "solver/align/profile.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <set>

#include <fmt/format.h>
#include <toml++/toml.h>

#include "core/error.hpp"
#include "core/io.hpp"
#include "core/toml_reader.hpp"
#include "core/units.hpp"

namespace facecap::align {

namespace {

std::string quote(std::string_view s) {
  std::string out = "\"";
  for (char c : s) {
    if (c == '"' || c == '\\') out += '\\', out += c;
    else if (static_cast<unsigned char>(c) < 0x20) out += fmt::format("\\u{:04x}", int(c));
    else out += c;
  }
  return out + "\"";
}
std::string vec3(const Eigen::Vector3d& v) { return fmt::format("[{}, {}, {}]", v.x(), v.y(), v.z()); }

constexpr std::string_view kChecksumKey = "checksum = ";

uint64_t body_checksum(std::string_view text) {
  Fnv1a64 h;
  std::size_t pos = 0;
  while (pos < text.size()) {
    std::size_t end = text.find('\n', pos);
    if (end == std::string_view::npos) end = text.size();
    const std::string_view line = text.substr(pos, end - pos);
    if (line.substr(0, kChecksumKey.size()) != kChecksumKey) {
      h.add(line.data(), line.size());
      h.add("\n", 1);
    }
    pos = end + 1;
  }
  return h.digest();
}

}  // namespace

std::string write_calibration_profile(const Calibration& c) {
  std::string body;
  auto out = [&body](std::string_view s) { body += s; };
  out("# facecap calibration profile: written by `facecap calibrate`, read by solve, eval and facecapd.\n");
  // The lowest version that holds what is written, so that older readers keep reading the rest.
  out(fmt::format("version = {}\n", !c.observability_known ? (!c.head_markers.empty() ? 2 : 1) : c.distinct_shape_mm > 0.0 ? 4 : 3));
  out("\n[rig]\n");
  out(fmt::format("name = {}\ncontent_hash = \"{:016x}\"\nunits = {}\n", quote(c.rig_name), c.rig_hash, quote(unit_name(c.rig_mm_per_unit))));
  out("\n[source]\n");
  out(fmt::format("take = {}\nframe = {}\nunits = {}\nunits_detected = {}\n", quote(c.source_take), c.source_frame,
                  quote(unit_name(c.take_mm_per_unit)), c.units_detected));
  out("\n[transform]  # rig = scale * rotation * take + translation\n");
  const Eigen::Matrix3d& R = c.take_to_rig.rotation;
  out(fmt::format("scale = {}\nrotation = [{}, {}, {}]\ntranslation = {}\n", c.take_to_rig.scale,
                  vec3(R.row(0).transpose()), vec3(R.row(1).transpose()), vec3(R.row(2).transpose()),
                  vec3(c.take_to_rig.translation)));
  if (c.start_index >= 0) {  // only a calibration fitted to a take has a fit to report
    out("\n[fit]  # rig millimetres\n");
    out(fmt::format("hull_rms_mm = {}\ntrimmed_rms_mm = {}\nstart = {}\n", c.hull_rms_mm, c.trimmed_rms_mm,
                    c.start_index));
  }
  out("\n[stabilise]\nmarkers = [");
  for (std::size_t i = 0; i < c.stable_markers.size(); ++i) out((i ? ", " : "") + quote(c.stable_markers[i]));
  out("]\n");
  if (!c.notes.empty()) {
    out("\n[notes]\ntext = [\n");
    for (const auto& n : c.notes) out("  " + quote(n) + ",\n");
    out("]\n");
  }
  for (const auto& m : c.markers) {
    out("\n[[marker]]\n");
    out(fmt::format("label = {}\nvertices = [{}, {}, {}]\nbarycentric = {}\nneutral = {}\nbound_point = {}\noffset = {}\nresidual_mm = {}\n",
                    quote(m.label), m.binding.vertices[0], m.binding.vertices[1], m.binding.vertices[2],
                    vec3(m.binding.barycentric), vec3(m.neutral), vec3(m.bound_point),
                    vec3(c.take_to_rig.apply(m.neutral) - m.bound_point), m.residual_mm));
  }
  for (const auto& h : c.head_markers) {
    out("\n[[head_marker]]  # head pose only: not bound, not pinned\n");
    out(fmt::format("label = {}\nneutral = {}\n", quote(h.label), vec3(h.neutral)));
  }
  if (c.observability_known) {
    out(fmt::format("\n[observability]  # shapes moving no bound point by threshold_mm at full weight are left out of the "
                    "weight fit\nthreshold_mm = {}\n", c.observable_shape_mm));
    if (c.distinct_shape_mm > 0.0)
      out(fmt::format("distinct_mm = {}  # nor are shapes moving them within this of a larger fitted shape (same_as)\n",
                      c.distinct_shape_mm));
    for (const auto& u : c.unobserved_shapes) {
      out("\n[[unobserved_shape]]  # the markers cannot observe it: its weight stays 0\n");
      out(fmt::format("name = {}\nmax_displacement_mm = {}\n", quote(u.name), u.max_displacement_mm));
      if (!u.same_as.empty()) out(fmt::format("same_as = {}\ndistinct_mm = {}\n", quote(u.same_as), u.distinct_mm));
    }
  }
  // The checksum line goes second; it is left out of its own sum.
  const std::size_t first_break = body.find('\n') + 1;
  body.insert(first_break, fmt::format("{}\"fnv1a64:{:016x}\"\n", kChecksumKey, body_checksum(body)));
  return body;
}

void save_calibration_profile(const std::filesystem::path& path, const Calibration& calibration) {
  const std::string text = write_calibration_profile(calibration);
  write_file_atomically(path, std::span<const char>(text.data(), text.size()));
}

namespace {

class Reader {
 public:
  explicit Reader(std::string name) : name_(std::move(name)) {}

  [[noreturn]] void fail(const toml::node* node, const std::string& what, const std::string& key) const {
    ErrorLocation where{.file = name_, .key = key};
    if (node) {
      where.line = node->source().begin.line;
      where.column = node->source().begin.column;
    }
    throw Error(what, where);
  }
  void only_keys(const toml::table& t, std::initializer_list<std::string_view> keys, const std::string& path) const {
    for (const auto& [k, v] : t) {
      if (std::find(keys.begin(), keys.end(), k.str()) == keys.end()) {
        std::string allowed;
        for (auto a : keys) allowed += (allowed.empty() ? "" : ", ") + std::string(a);
        fail(&v, fmt::format("unknown key '{}' (allowed here: {})", k.str(), allowed), path + std::string(k.str()));
      }
    }
  }
  const toml::table& table(const toml::table& t, std::string_view key, const std::string& path) const {
    const toml::node* n = t.get(key);
    if (!n) fail(&t, fmt::format("missing table [{}]", key), path + std::string(key));
    if (!n->is_table()) fail(n, fmt::format("'{}' must be a table", key), path + std::string(key));
    return *n->as_table();
  }
  const toml::node& need(const toml::table& t, std::string_view key, const std::string& path) const {
    const toml::node* n = t.get(key);
    if (!n) fail(&t, fmt::format("missing key '{}'", key), path + std::string(key));
    return *n;
  }
  std::string string(const toml::table& t, std::string_view key, const std::string& path) const {
    const toml::node& n = need(t, key, path);
    if (!n.is_string()) fail(&n, fmt::format("'{}' must be a string", key), path + std::string(key));
    return std::string(n.as_string()->get());
  }
  double number(const toml::node& n, const std::string& key) const {
    if (n.is_floating_point()) return n.as_floating_point()->get();
    if (n.is_integer()) return double(n.as_integer()->get());
    fail(&n, fmt::format("'{}' must be a number", key), key);
  }
  double number(const toml::table& t, std::string_view key, const std::string& path) const {
    const double v = number(need(t, key, path), path + std::string(key));
    if (!std::isfinite(v)) fail(t.get(key), fmt::format("'{}' must be finite", key), path + std::string(key));
    return v;
  }
  int64_t integer(const toml::table& t, std::string_view key, const std::string& path) const {
    const toml::node& n = need(t, key, path);
    if (!n.is_integer()) fail(&n, fmt::format("'{}' must be an integer", key), path + std::string(key));
    return n.as_integer()->get();
  }
  bool boolean(const toml::table& t, std::string_view key, const std::string& path) const {
    const toml::node& n = need(t, key, path);
    if (!n.is_boolean()) fail(&n, fmt::format("'{}' must be true or false", key), path + std::string(key));
    return n.as_boolean()->get();
  }
  Eigen::Vector3d vector3(const toml::node& n, const std::string& key) const {
    const toml::array* a = n.as_array();
    if (!a || a->size() != 3) fail(&n, fmt::format("'{}' must be an array of 3 numbers", key), key);
    Eigen::Vector3d v;
    for (std::size_t i = 0; i < 3; ++i) v[Eigen::Index(i)] = number(*a->get(i), key);
    if (!v.allFinite()) fail(&n, fmt::format("'{}' must be finite", key), key);
    return v;
  }
  Eigen::Vector3d vector3(const toml::table& t, std::string_view key, const std::string& path) const {
    return vector3(need(t, key, path), path + std::string(key));
  }
  std::vector<std::string> strings(const toml::table& t, std::string_view key, const std::string& path) const {
    const toml::node& n = need(t, key, path);
    const toml::array* a = n.as_array();
    if (!a) fail(&n, fmt::format("'{}' must be an array of strings", key), path + std::string(key));
    std::vector<std::string> out;
    for (const auto& e : *a) {
      if (!e.is_string()) fail(&e, fmt::format("'{}' must be an array of strings", key), path + std::string(key));
      out.emplace_back(e.as_string()->get());
    }
    return out;
  }
  const std::string& name() const { return name_; }

 private:
  std::string name_;
};

bool is_hex16(const std::string& s) {
  return s.size() == 16 && s.find_first_not_of("0123456789abcdefABCDEF") == std::string::npos;
}

}  // namespace

Calibration read_calibration_profile(std::string_view text, const std::string& name) {
  const toml::table root = parse_toml(text, name);
  Reader r(name);
  r.only_keys(root, {"version", "checksum", "rig", "source", "transform", "fit", "stabilise", "notes", "marker", "head_marker",
                     "observability", "unobserved_shape"}, "");
  const int64_t version = r.integer(root, "version", "");
  if (version < 1 || version > kCalibrationProfileVersion)
    r.fail(root.get("version"), fmt::format("profile version {} is not readable by this facecap (reads 1..{})", version,
                                            kCalibrationProfileVersion), "version");
  if (const toml::node* sum = root.get("checksum")) {
    const std::string expected = fmt::format("fnv1a64:{:016x}", body_checksum(text));
    if (!sum->is_string() || sum->as_string()->get() != expected)
      r.fail(sum, fmt::format("checksum mismatch (the file was changed after calibration; expected {}): remove the "
                              "checksum line to accept hand edits", expected), "checksum");
  }
  Calibration c;
  const auto& rig = r.table(root, "rig", "");
  r.only_keys(rig, {"name", "content_hash", "units"}, "rig.");
  c.rig_name = r.string(rig, "name", "rig.");
  const std::string hash = r.string(rig, "content_hash", "rig.");
  if (!is_hex16(hash)) r.fail(rig.get("content_hash"), "content_hash must be 16 hex digits", "rig.content_hash");
  c.rig_hash = std::stoull(hash, nullptr, 16);
  const std::string rig_units = r.string(rig, "units", "rig.");
  const auto rig_mm = millimetres_per_unit(rig_units);
  if (!rig_mm) r.fail(rig.get("units"), fmt::format("units '{}' are not mm, cm or m", rig_units), "rig.units");
  c.rig_mm_per_unit = *rig_mm;

  const auto& src = r.table(root, "source", "");
  r.only_keys(src, {"take", "frame", "units", "units_detected"}, "source.");
  c.source_take = r.string(src, "take", "source.");
  c.source_frame = r.integer(src, "frame", "source.");
  const std::string take_units = r.string(src, "units", "source.");
  const auto take_mm = millimetres_per_unit(take_units);
  if (!take_mm) r.fail(src.get("units"), fmt::format("units '{}' are not mm, cm or m", take_units), "source.units");
  c.take_mm_per_unit = *take_mm;
  c.units_detected = r.boolean(src, "units_detected", "source.");

  const auto& tf = r.table(root, "transform", "");
  r.only_keys(tf, {"scale", "rotation", "translation"}, "transform.");
  c.take_to_rig.scale = r.number(tf, "scale", "transform.");
  if (!(c.take_to_rig.scale > 0.0)) r.fail(tf.get("scale"), "scale must be positive", "transform.scale");
  const toml::node& rot = r.need(tf, "rotation", "transform.");
  const toml::array* rows = rot.as_array();
  if (!rows || rows->size() != 3) r.fail(&rot, "rotation must be 3 rows of 3 numbers", "transform.rotation");
  for (std::size_t i = 0; i < 3; ++i)
    c.take_to_rig.rotation.row(Eigen::Index(i)) = r.vector3(*rows->get(i), "transform.rotation").transpose();
  const Eigen::Matrix3d& R = c.take_to_rig.rotation;
  if ((R.transpose() * R - Eigen::Matrix3d::Identity()).norm() > 1e-6 || R.determinant() < 0.0)
    r.fail(&rot, "rotation is not a proper rotation matrix", "transform.rotation");
  c.take_to_rig.translation = r.vector3(tf, "translation", "transform.");

  if (const toml::node* fit_node = root.get("fit")) {
    if (!fit_node->is_table()) r.fail(fit_node, "'fit' must be a table", "fit");
    const auto& fit = *fit_node->as_table();
    r.only_keys(fit, {"hull_rms_mm", "trimmed_rms_mm", "start"}, "fit.");
    c.hull_rms_mm = r.number(fit, "hull_rms_mm", "fit.");
    c.trimmed_rms_mm = r.number(fit, "trimmed_rms_mm", "fit.");
    const int64_t start = r.integer(fit, "start", "fit.");
    if (start < 0 || start > std::numeric_limits<int>::max())
      r.fail(fit.get("start"), "start must be a non-negative integer", "fit.start");
    c.start_index = int(start);
  }
  const auto& stab = r.table(root, "stabilise", "");
  r.only_keys(stab, {"markers"}, "stabilise.");
  c.stable_markers = r.strings(stab, "markers", "stabilise.");
  if (const toml::node* notes = root.get("notes")) {
    if (!notes->is_table()) r.fail(notes, "'notes' must be a table", "notes");
    r.only_keys(*notes->as_table(), {"text"}, "notes.");
    c.notes = r.strings(*notes->as_table(), "text", "notes.");
  }

  const toml::node* markers = root.get("marker");
  if (!markers || !markers->is_array_of_tables()) r.fail(&root, "no [[marker]] entries", "marker");
  std::set<std::string> seen;
  for (const auto& node : *markers->as_array()) {
    const auto& t = *node.as_table();
    r.only_keys(t, {"label", "vertices", "barycentric", "neutral", "bound_point", "offset", "residual_mm"}, "marker.");
    MarkerCalibration m;
    m.label = r.string(t, "label", "marker.");
    if (m.label.empty()) r.fail(t.get("label"), "empty marker label", "marker.label");
    if (!seen.insert(m.label).second) r.fail(t.get("label"), fmt::format("marker '{}' appears twice", m.label), "marker.label");
    const toml::node& verts = r.need(t, "vertices", "marker.");
    const toml::array* va = verts.as_array();
    if (!va || va->size() != 3) r.fail(&verts, "vertices must be 3 integers", "marker.vertices");
    for (std::size_t i = 0; i < 3; ++i) {
      const toml::node* v = va->get(i);
      if (!v->is_integer() || v->as_integer()->get() < 0 || v->as_integer()->get() > std::numeric_limits<int>::max())
        r.fail(v, "vertices must be 3 non-negative integers (vertex indices)", "marker.vertices");
      m.binding.vertices[i] = int(v->as_integer()->get());
    }
    m.binding.label = m.label;
    m.binding.barycentric = r.vector3(t, "barycentric", "marker.");
    if (std::abs(m.binding.barycentric.sum() - 1.0) > 1e-6 || m.binding.barycentric.minCoeff() < -1e-9)
      r.fail(t.get("barycentric"), "barycentric coordinates must be non-negative and sum to 1", "marker.barycentric");
    m.neutral = r.vector3(t, "neutral", "marker.");
    m.bound_point = r.vector3(t, "bound_point", "marker.");
    m.residual_mm = r.number(t, "residual_mm", "marker.");
    // The neutral offset (the actor's marker from its bound point, rig units) is derived;
    // when present it must agree with the transform, neutral and bound_point.
    if (const toml::node* off = t.get("offset")) {
      const Eigen::Vector3d offset = r.vector3(*off, "marker.offset");
      const Eigen::Vector3d derived = c.take_to_rig.apply(m.neutral) - m.bound_point;
      if ((offset - derived).norm() > 1e-6 * (1.0 + derived.norm()))
        r.fail(off, fmt::format("offset of '{}' disagrees with transform(neutral) - bound_point", m.label), "marker.offset");
    }
    c.markers.push_back(std::move(m));
  }
  if (const toml::node* heads = root.get("head_marker")) {
    if (!heads->is_array_of_tables()) r.fail(heads, "'head_marker' must be [[head_marker]] tables", "head_marker");
    for (const auto& node : *heads->as_array()) {
      const auto& t = *node.as_table();
      r.only_keys(t, {"label", "neutral"}, "head_marker.");
      HeadMarkerCalibration h;
      h.label = r.string(t, "label", "head_marker.");
      if (h.label.empty()) r.fail(t.get("label"), "empty head marker label", "head_marker.label");
      if (!seen.insert(h.label).second)
        r.fail(t.get("label"), fmt::format("marker '{}' appears twice", h.label), "head_marker.label");
      h.neutral = r.vector3(t, "neutral", "head_marker.");
      c.head_markers.push_back(std::move(h));
    }
  }
  if (const toml::node* node = root.get("observability")) {
    if (!node->is_table()) r.fail(node, "'observability' must be a table", "observability");
    r.only_keys(*node->as_table(), {"threshold_mm", "distinct_mm"}, "observability.");
    c.observable_shape_mm = r.number(*node->as_table(), "threshold_mm", "observability.");
    if (node->as_table()->get("distinct_mm")) {
      c.distinct_shape_mm = r.number(*node->as_table(), "distinct_mm", "observability.");
      if (!(c.distinct_shape_mm > 0.0))
        r.fail(node->as_table()->get("distinct_mm"), "distinct_mm must be > 0", "observability.distinct_mm");
    }
    if (!(c.observable_shape_mm >= 0.0))
      r.fail(node->as_table()->get("threshold_mm"), "threshold_mm must be >= 0", "observability.threshold_mm");
    c.observability_known = true;
  }
  if (const toml::node* shapes = root.get("unobserved_shape")) {
    if (!c.observability_known) r.fail(shapes, "[[unobserved_shape]] needs an [observability] table", "unobserved_shape");
    if (!shapes->is_array_of_tables())
      r.fail(shapes, "'unobserved_shape' must be [[unobserved_shape]] tables", "unobserved_shape");
    std::set<std::string> names;
    for (const auto& node : *shapes->as_array()) {
      const auto& t = *node.as_table();
      r.only_keys(t, {"name", "max_displacement_mm", "same_as", "distinct_mm"}, "unobserved_shape.");
      UnobservedShape u;
      u.name = r.string(t, "name", "unobserved_shape.");
      if (!names.insert(u.name).second)
        r.fail(t.get("name"), fmt::format("shape '{}' appears twice", u.name), "unobserved_shape.name");
      u.max_displacement_mm = r.number(t, "max_displacement_mm", "unobserved_shape.");
      if (t.get("same_as")) {
        u.same_as = r.string(t, "same_as", "unobserved_shape.");
        u.distinct_mm = r.number(t, "distinct_mm", "unobserved_shape.");
      }
      c.unobserved_shapes.push_back(std::move(u));
    }
  }
  for (const auto& s : c.stable_markers)
    if (!c.neutral_of(s))
      r.fail(stab.get("markers"), fmt::format("stable marker '{}' has no [[marker]] or [[head_marker]] entry", s),
             "stabilise.markers");
  return c;
}

Calibration load_calibration_profile(const std::filesystem::path& path) {
  const auto bytes = read_file_bytes(path);
  return read_calibration_profile(std::string_view(bytes.data(), bytes.size()), path.string());
}

void check_profile_matches_rig(const Calibration& c, const Rig& rig, const std::string& profile_name) {
  if (c.rig_hash != rig.content_hash())
    throw Error(fmt::format("profile was calibrated on rig '{}' ({:016x}), not on '{}' ({:016x}): calibrate again for this rig",
                            c.rig_name, c.rig_hash, rig.name, rig.content_hash()),
                ErrorLocation{.file = profile_name, .key = "rig.content_hash"});
  for (const auto& m : c.markers)
    for (int v : m.binding.vertices)
      if (v >= rig.vertex_count())
        throw Error(fmt::format("marker '{}' binds vertex {}, the rig has {}", m.label, v, rig.vertex_count()),
                    ErrorLocation{.file = profile_name, .key = "marker.vertices"});
  for (const auto& u : c.unobserved_shapes)
    if (!rig.shape_index(u.name) || (!u.same_as.empty() && !rig.shape_index(u.same_as)))
      throw Error(fmt::format("unobserved shape '{}' (same as '{}') is not a shape of rig '{}'", u.name, u.same_as, rig.name),
                  ErrorLocation{.file = profile_name, .key = "unobserved_shape.name"});
}

}  // namespace facecap::align
