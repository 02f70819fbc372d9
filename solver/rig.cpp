#include "solver/rig.hpp"

#include <algorithm>
#include <cctype>
#include <chrono>
#include <set>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "core/error.hpp"
#include "core/io.hpp"
#include "core/toml_reader.hpp"
#include "core/units.hpp"
#include "solver/builtin_face.hpp"
#include "solver/fbx_rig.hpp"
#include "solver/gltf_rig.hpp"
#include "solver/obj_mesh.hpp"
#include "solver/rig_cache.hpp"

namespace facecap {
namespace fs = std::filesystem;

std::optional<Eigen::Index> Rig::shape_index(const std::string& shape_name) const {
  const auto it = std::find(shape_names.begin(), shape_names.end(), shape_name);
  if (it == shape_names.end()) return std::nullopt;
  return Eigen::Index(it - shape_names.begin());
}

Eigen::Matrix3Xd Rig::linear_blend(const Eigen::VectorXd& weights) const {
  Eigen::Matrix3Xd out = neutral;
  Eigen::Map<Eigen::VectorXd>(out.data(), out.size()) += deltas * weights;
  return out;
}

Eigen::Matrix3Xd Rig::shape_positions(Eigen::Index shape) const {
  Eigen::Matrix3Xd out = neutral;
  Eigen::Map<Eigen::VectorXd>(out.data(), out.size()) += deltas.col(shape);
  return out;
}

uint64_t Rig::content_hash() const {
  Fnv1a64 h;
  h.add(neutral.data(), sizeof(double) * std::size_t(neutral.size()));
  h.add(triangles.data(), sizeof(int) * std::size_t(triangles.size()));
  for (const auto& n : shape_names) h.add_string(n);
  h.add(deltas.data(), sizeof(double) * std::size_t(deltas.size()));
  return h.digest();
}

BoundingBox bounding_box(const Eigen::Matrix3Xd& points) {
  if (points.cols() == 0) return {};
  return {points.rowwise().minCoeff(), points.rowwise().maxCoeff()};
}

std::string guess_face_units(const BoundingBox& box) {
  const double extent = box.size().maxCoeff();  // a face or head: roughly 0.1 to 0.4 m
  if (extent >= 0.05 && extent <= 0.6) return "m";
  if (extent >= 5.0 && extent <= 60.0) return "cm";
  if (extent >= 50.0 && extent <= 600.0) return "mm";
  return "unknown";
}

double rig_units_per_mm(const Rig& rig) {
  const double mm = millimetres_per_unit(guess_face_units(bounding_box(rig.neutral))).value_or(0.0);
  return mm > 0.0 ? 1.0 / mm : 0.1;
}

Eigen::VectorXd max_shape_displacement(const Rig& rig) {
  Eigen::VectorXd out(rig.shape_count());
  for (Eigen::Index s = 0; s < rig.shape_count(); ++s) {
    const Eigen::Map<const Eigen::Matrix3Xd> d(rig.deltas.col(s).data(), 3, rig.vertex_count());
    out[s] = d.cols() ? d.colwise().norm().maxCoeff() : 0.0;
  }
  return out;
}

RigManifest parse_rig_manifest(std::string_view text, const fs::path& manifest) {
  const std::string file = manifest.string();
  const toml::table table = parse_toml(text, file);
  auto fail = [&](const toml::node& node, std::string what, std::string key) -> Error {
    const auto& b = node.source().begin;
    return Error(std::move(what), ErrorLocation{.file = file, .line = b.line, .column = b.column, .key = std::move(key)});
  };
  for (const auto& [key, value] : table) {
    if (key != "name" && key != "hinged" && key != "neutral" && key != "shapes")
      throw fail(value, fmt::format("unknown key '{}' (a manifest has name, hinged, neutral and [shapes])", key.str()),
                 std::string(key.str()));
  }
  const fs::path dir = manifest.parent_path();
  RigManifest out;
  out.name = dir.filename().string();
  if (const toml::node* name = table.get("name")) {
    if (!name->is_string()) throw fail(*name, "name must be a string", "name");
    out.name = name->as_string()->get();
  }
  if (const toml::node* hinged = table.get("hinged")) {
    if (!hinged->is_boolean()) throw fail(*hinged, "hinged must be true or false", "hinged");
    out.hinged = hinged->as_boolean()->get();
  }
  const toml::node* neutral = table.get("neutral");
  if (!neutral) throw Error("missing 'neutral = \"file.obj\"'", ErrorLocation{.file = file, .key = "neutral"});
  if (!neutral->is_string() || neutral->as_string()->get().empty())
    throw fail(*neutral, "neutral must name an OBJ file", "neutral");
  out.neutral = dir / neutral->as_string()->get();
  const toml::table* shapes = table["shapes"].as_table();
  if (!shapes || shapes->empty())
    throw Error("missing [shapes] table naming at least one shape", ErrorLocation{.file = file, .key = "shapes"});
  for (const auto& [key, value] : *shapes) {
    const std::string shape_key = "shapes." + std::string(key.str());
    if (key.str().empty()) throw fail(value, "a shape needs a name", shape_key);
    if (!value.is_string() || value.as_string()->get().empty())
      throw fail(value, "shape file must be a non-empty string", shape_key);
    out.shapes.push_back({std::string(key.str()), dir / value.as_string()->get()});
  }
  return out;
}

namespace {

// A manifest, or what a directory without one implies.
struct RigFiles : RigManifest {
  std::vector<fs::path> inputs;  // files beside the OBJs the rig depends on (for the cache key)
};

constexpr const char* kIctNeutral = "generic_neutral_mesh.obj";
constexpr const char* kManifestName = "rig.toml";

RigFiles read_manifest(const fs::path& manifest) {
  const std::vector<char> bytes = read_file_bytes(manifest);
  return RigFiles{parse_rig_manifest(std::string_view(bytes.data(), bytes.size()), manifest), {manifest}};
}

RigFiles scan_obj_directory(const fs::path& dir) {
  if (fs::exists(dir / kManifestName)) return read_manifest(dir / kManifestName);
  RigFiles files;
  files.name = fs::path(dir).filename().string();
  if (files.name.empty()) files.name = dir.parent_path().filename().string();
  for (const char* candidate : {kIctNeutral, "neutral.obj"})
    if (fs::exists(dir / candidate)) { files.neutral = dir / candidate; break; }
  if (files.neutral.empty())
    throw file_error(dir.string(), fmt::format("no neutral mesh: expected {} or neutral.obj (or a {} manifest)",
                                               kIctNeutral, kManifestName));
  for (const auto& entry : fs::directory_iterator(dir)) {
    if (!entry.is_regular_file() || entry.path().extension() != ".obj" || entry.path() == files.neutral) continue;
    files.shapes.push_back({entry.path().stem().string(), entry.path()});
  }
  std::sort(files.shapes.begin(), files.shapes.end(),
            [](const RigShapeFile& a, const RigShapeFile& b) { return a.name < b.name; });
  if (files.shapes.empty()) throw file_error(dir.string(), "no blendshape OBJ files beside the neutral mesh");
  return files;
}

Rig load_obj_rig(const RigFiles& files) {
  std::set<std::string> seen;
  for (const auto& s : files.shapes)
    if (!seen.insert(s.name).second)
      throw file_error(s.path.string(), fmt::format("duplicate shape name '{}'", s.name));

  const ObjMesh neutral = read_obj(files.neutral.string());
  if (neutral.vertices.cols() == 0) throw file_error(files.neutral.string(), "neutral mesh has no vertices");
  if (neutral.triangles.cols() == 0) throw file_error(files.neutral.string(), "neutral mesh has no faces");
  const std::string neutral_name = files.neutral.filename().string();
  Rig rig;
  rig.name = files.name;
  rig.hinged = files.hinged;
  rig.neutral = neutral.vertices;
  rig.triangles = neutral.triangles;
  // Gathered as the shapes are read rather than sized 3N x M up front: N and M come from
  // different files, and only shapes that parsed may claim memory.
  const auto column = std::size_t(neutral.vertices.size());
  std::vector<double> deltas;
  for (const auto& s : files.shapes) {
    const std::string path = s.path.string();
    const ObjMesh shape = read_obj(path);
    check_shape_matches_neutral(shape, path, neutral, neutral_name);
    rig.shape_names.push_back(s.name);
    deltas.resize(deltas.size() + column);
    Eigen::Map<Eigen::VectorXd>(deltas.data() + deltas.size() - column, Eigen::Index(column)) =
        Eigen::Map<const Eigen::VectorXd>(shape.vertices.data(), shape.vertices.size()) -
        Eigen::Map<const Eigen::VectorXd>(neutral.vertices.data(), neutral.vertices.size());
  }
  rig.deltas = Eigen::Map<const Eigen::MatrixXd>(deltas.data(), Eigen::Index(column), Eigen::Index(files.shapes.size()));
  return rig;
}

// Everything a file-based rig is loaded from, plus how: the cache key's input.
std::vector<fs::path> rig_inputs(const RigFiles& files) {
  std::vector<fs::path> inputs = files.inputs;
  inputs.push_back(files.neutral);
  for (const auto& s : files.shapes) inputs.push_back(s.path);
  return inputs;
}

}  // namespace

Rig load_rig(const std::string& spec, const RigLoadOptions& options, RigLoadReport* report) {
  const auto start = std::chrono::steady_clock::now();
  RigLoadReport local;
  RigLoadReport& rep = report ? *report : local;
  rep = {};
  auto finish = [&](Rig rig) {
    rep.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return rig;
  };

  if (spec == "builtin") {
    Rig rig = BuiltinFace::instance().rig();
    return finish(std::move(rig));
  }
  const fs::path path(spec);
  if (!fs::exists(path)) throw file_error(spec, "no such file or directory");

  const std::string ext = path.extension().string();
  const bool fbx = is_fbx_path(path);
  if (ext == ".gltf" || ext == ".glb" || fbx) {
    const RigCacheKey key = make_rig_cache_key(fbx ? "fbx" : "gltf", {path});
    if (options.use_cache) {
      if (auto cached = read_rig_cache(key, options.cache_dir, &rep.cache_file)) {
        rep.from_cache = true;
        return finish(std::move(*cached));
      }
    }
    Rig rig = fbx ? load_fbx_rig(path.string()) : load_gltf_rig(path.string());
    rig.source = fs::absolute(path).string();
    if (options.use_cache) rep.cache_file = write_rig_cache(key, rig, options.cache_dir);
    return finish(std::move(rig));
  }

  RigFiles files;
  if (fs::is_directory(path)) files = scan_obj_directory(path);
  else if (ext == ".toml") files = read_manifest(path);
  else if (ext == ".obj") throw file_error(spec, "a single OBJ is not a rig: give its directory (neutral plus one OBJ per shape)");
  else throw file_error(spec, "unknown rig format: expected a directory of OBJ files, a .toml manifest, .gltf, .glb or .fbx");

  const RigCacheKey key = make_rig_cache_key("obj", rig_inputs(files));
  if (options.use_cache) {
    if (auto cached = read_rig_cache(key, options.cache_dir, &rep.cache_file)) {
      rep.from_cache = true;
      return finish(std::move(*cached));
    }
  }
  Rig rig = load_obj_rig(files);
  rig.source = fs::absolute(path).string();
  if (options.use_cache) rep.cache_file = write_rig_cache(key, rig, options.cache_dir);
  return finish(std::move(rig));
}

}  // namespace facecap
