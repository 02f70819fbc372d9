#include "solver/gltf_rig.hpp"

#include <cstring>
#include <limits>
#include <optional>
#include <set>
#include <string_view>

#include <fmt/format.h>
#include <tiny_gltf.h>

#include "core/error.hpp"
#include "core/io.hpp"

namespace facecap {
namespace {

Error gltf_error(const std::string& file, const std::string& json_path, std::string what) {
  return Error(std::move(what), ErrorLocation{.file = file, .key = json_path});
}

// Where `count` elements of `element_bytes` each lie in a bufferView: the first at `offset`
// into the view, the next `stride` further on. Checked against the view and its buffer
// with overflow-safe arithmetic, since every number here comes from the file.
struct Elements {
  const unsigned char* first = nullptr;
  std::size_t stride = 0;
};
Elements view_elements(const tinygltf::Model& model, int view_index, std::size_t offset, std::size_t element_bytes,
                       std::size_t count, const std::string& file, const std::string& json_path) {
  if (view_index < 0 || std::size_t(view_index) >= model.bufferViews.size())
    throw gltf_error(file, json_path, fmt::format("bufferView {} does not exist", view_index));
  const auto& view = model.bufferViews[std::size_t(view_index)];
  if (view.buffer < 0 || std::size_t(view.buffer) >= model.buffers.size())
    throw gltf_error(file, json_path, fmt::format("buffer {} does not exist", view.buffer));
  const auto& buffer = model.buffers[std::size_t(view.buffer)].data;
  std::size_t view_end = 0;
  if (__builtin_add_overflow(view.byteOffset, view.byteLength, &view_end) || view_end > buffer.size())
    throw gltf_error(file, json_path, fmt::format("bufferView {} runs past the end of its buffer", view_index));
  const std::size_t stride = view.byteStride ? view.byteStride : element_bytes;
  std::size_t span = 0, end = 0;
  if (count > 0 && (__builtin_mul_overflow(count - 1, stride, &span) || __builtin_add_overflow(span, element_bytes, &span) ||
                    __builtin_add_overflow(span, offset, &end) || end > view.byteLength))
    throw gltf_error(file, json_path, fmt::format("{} elements of {} bytes do not fit in bufferView {} ({} bytes)", count,
                                                  element_bytes, view_index, view.byteLength));
  return {buffer.data() + view.byteOffset + offset, stride};
}

const tinygltf::Accessor& accessor(const tinygltf::Model& model, int index, const std::string& file,
                                   const std::string& json_path) {
  if (index < 0 || std::size_t(index) >= model.accessors.size())
    throw gltf_error(file, json_path, fmt::format("accessor {} does not exist", index));
  return model.accessors[std::size_t(index)];
}

// Reads a float VEC3 accessor (dense and/or sparse) into 3 x count. Without dense data
// the count is not backed by the file, so it must equal `expected_count` (a morph target
// has its primitive's vertex count); a POSITION accessor passes none and needs dense data.
Eigen::Matrix3Xd read_vec3(const tinygltf::Model& model, int accessor_index, std::optional<std::size_t> expected_count,
                           const std::string& file, const std::string& json_path) {
  const auto& acc = accessor(model, accessor_index, file, json_path);
  if (acc.type != TINYGLTF_TYPE_VEC3 || acc.componentType != TINYGLTF_COMPONENT_TYPE_FLOAT)
    throw gltf_error(file, json_path, "positions must be float VEC3");
  if (expected_count && acc.count != *expected_count)
    throw gltf_error(file, json_path, fmt::format("{} positions, the primitive has {} vertices", acc.count, *expected_count));
  Elements dense;
  if (acc.bufferView >= 0) dense = view_elements(model, acc.bufferView, acc.byteOffset, 12, acc.count, file, json_path);
  else if (!expected_count) throw gltf_error(file, json_path, "POSITION has no bufferView");
  Eigen::Matrix3Xd out = Eigen::Matrix3Xd::Zero(3, Eigen::Index(acc.count));
  auto store = [&](std::size_t column, const unsigned char* p) {
    float v[3];
    std::memcpy(v, p, 12);
    out.col(Eigen::Index(column)) << v[0], v[1], v[2];
  };
  if (dense.first) {
    for (std::size_t i = 0; i < acc.count; ++i) store(i, dense.first + i * dense.stride);
  }
  if (acc.sparse.isSparse) {
    const int index_type = acc.sparse.indices.componentType;
    const std::size_t index_bytes = index_type == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE    ? 1
                                    : index_type == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT ? 2
                                    : index_type == TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT   ? 4
                                                                                           : 0;
    if (index_bytes == 0) throw gltf_error(file, json_path, "sparse indices must be unsigned integers");
    if (acc.sparse.count < 0 || std::size_t(acc.sparse.count) > acc.count)
      throw gltf_error(file, json_path, fmt::format("sparse count {} is not within 0..{}", acc.sparse.count, acc.count));
    const auto n = std::size_t(acc.sparse.count);
    const Elements indices = view_elements(model, acc.sparse.indices.bufferView,
                                           std::size_t(acc.sparse.indices.byteOffset), index_bytes, n, file,
                                           json_path + ".sparse.indices");
    const Elements values = view_elements(model, acc.sparse.values.bufferView, std::size_t(acc.sparse.values.byteOffset),
                                          12, n, file, json_path + ".sparse.values");
    for (std::size_t i = 0; i < n; ++i) {
      uint32_t index = 0;
      std::memcpy(&index, indices.first + i * indices.stride, index_bytes);  // little-endian host
      if (index >= acc.count) throw gltf_error(file, json_path, fmt::format("sparse index {} out of range", index));
      store(index, values.first + i * values.stride);
    }
  }
  if (!out.allFinite()) throw gltf_error(file, json_path, "positions must be finite numbers");
  return out;
}

std::vector<int> read_indices(const tinygltf::Model& model, const tinygltf::Primitive& prim, std::size_t vertex_count,
                              const std::string& file, const std::string& json_path) {
  std::vector<int> out;
  if (prim.indices < 0) {  // non-indexed triangles
    if (vertex_count % 3) throw gltf_error(file, json_path, "vertex count of non-indexed triangles is not a multiple of 3");
    for (std::size_t i = 0; i < vertex_count; ++i) out.push_back(int(i));
    return out;
  }
  const auto& acc = accessor(model, prim.indices, file, json_path);
  const std::size_t size = acc.componentType == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE    ? 1
                           : acc.componentType == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT ? 2
                           : acc.componentType == TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT   ? 4
                                                                                         : 0;
  if (!size || acc.type != TINYGLTF_TYPE_SCALAR) throw gltf_error(file, json_path, "indices must be unsigned scalars");
  if (acc.bufferView < 0) throw gltf_error(file, json_path, "indices have no bufferView");
  if (acc.count % 3) throw gltf_error(file, json_path, "index count is not a multiple of 3");
  const Elements indices = view_elements(model, acc.bufferView, acc.byteOffset, size, acc.count, file, json_path);
  out.reserve(acc.count);
  for (std::size_t i = 0; i < acc.count; ++i) {
    uint32_t index = 0;
    std::memcpy(&index, indices.first + i * indices.stride, size);
    if (index >= vertex_count)
      throw gltf_error(file, json_path, fmt::format("index {} out of range (primitive has {} vertices)", index, vertex_count));
    out.push_back(int(index));
  }
  return out;
}

// External buffers are read with read_file_bytes (tinygltf's own reader sizes a directory
// as 2^63 bytes), and only when the rig came from a file (from bytes, "found" so that the
// read says why not).
bool external_file_exists(const std::string& path, void* from_file) {
  return !from_file || tinygltf::FileExists(path, nullptr);
}
bool read_external_file(std::vector<unsigned char>* out, std::string* err, const std::string& path, void* from_file) {
  if (!from_file) {
    *err += fmt::format("external file '{}' not read: the glTF was given as bytes\n", path);
    return false;
  }
  try {
    const std::vector<char> bytes = read_file_bytes(path);
    out->assign(bytes.begin(), bytes.end());
    return true;
  } catch (const Error& e) {
    *err += std::string(e.what()) + "\n";
    return false;
  }
}

// Images are textures, which a rig does not use: never decoded.
bool skip_image(tinygltf::Image*, const int, std::string*, std::string*, int, int, const unsigned char*, int, void*) {
  return true;
}

}  // namespace

Rig load_gltf_rig(const std::string& path) {
  const std::vector<char> bytes = read_file_bytes(path);
  const bool binary = path.size() >= 4 && path.substr(path.size() - 4) == ".glb";
  const std::filesystem::path dir = std::filesystem::path(path).parent_path();
  return parse_gltf_rig(bytes, path, binary, dir.empty() ? std::filesystem::path(".") : dir);
}

Rig parse_gltf_rig(std::span<const char> bytes, const std::string& path, bool binary,
                   const std::filesystem::path& base_dir) {
  if (bytes.size() > std::numeric_limits<unsigned int>::max())
    throw file_error(path, fmt::format("{} bytes: larger than a glTF file can be", bytes.size()));
  tinygltf::TinyGLTF loader;
  static int from_file_tag = 0;
  loader.SetFsCallbacks({&external_file_exists, &tinygltf::ExpandFilePath, &read_external_file,
                         &tinygltf::WriteWholeFile, base_dir.empty() ? nullptr : &from_file_tag});
  loader.SetImageLoader(&skip_image, nullptr);
  tinygltf::Model model;
  std::string err, warn;
  const auto length = static_cast<unsigned int>(bytes.size());
  const bool ok = binary ? loader.LoadBinaryFromMemory(&model, &err, &warn,
                                                       reinterpret_cast<const unsigned char*>(bytes.data()), length,
                                                       base_dir.string())
                         : loader.LoadASCIIFromString(&model, &err, &warn, bytes.data(), length, base_dir.string());
  if (!ok) throw file_error(path, "not a readable glTF file: " + (err.empty() ? std::string("unknown error") : err));

  int mesh_index = -1;
  for (std::size_t m = 0; m < model.meshes.size() && mesh_index < 0; ++m)
    for (const auto& prim : model.meshes[m].primitives)
      if (!prim.targets.empty()) { mesh_index = int(m); break; }
  if (mesh_index < 0) throw file_error(path, "no mesh with morph targets");
  const auto& mesh = model.meshes[std::size_t(mesh_index)];
  const std::string mesh_path = fmt::format("meshes[{}]", mesh_index);

  std::size_t target_count = 0;
  for (std::size_t p = 0; p < mesh.primitives.size(); ++p) {
    const auto& prim = mesh.primitives[p];
    if (prim.mode != TINYGLTF_MODE_TRIANGLES && prim.mode != -1)
      throw gltf_error(path, fmt::format("{}.primitives[{}]", mesh_path, p), "only triangle primitives are supported");
    if (p == 0) target_count = prim.targets.size();
    else if (prim.targets.size() != target_count)
      throw gltf_error(path, fmt::format("{}.primitives[{}]", mesh_path, p), "primitives disagree on the number of morph targets");
  }
  std::vector<std::string> names;
  if (mesh.extras.Has("targetNames")) {
    const auto& list = mesh.extras.Get("targetNames");
    for (int i = 0; i < int(list.ArrayLen()); ++i) {
      const std::string name_path = fmt::format("{}.extras.targetNames[{}]", mesh_path, i);
      if (!list.Get(i).IsString()) throw gltf_error(path, name_path, "a shape name must be a string");
      names.push_back(list.Get(i).Get<std::string>());
      if (names.back().empty()) throw gltf_error(path, name_path, "empty shape name");
    }
  }
  if (names.size() != target_count) {
    names.clear();
    for (std::size_t i = 0; i < target_count; ++i) names.push_back(fmt::format("target_{}", i));
  }
  std::set<std::string_view> seen;
  for (const auto& name : names)
    if (!seen.insert(name).second)
      throw gltf_error(path, mesh_path + ".extras.targetNames", fmt::format("duplicate shape name '{}'", name));

  // Pass 1: positions and triangles, so that the deltas can be sized (and bounded) once.
  std::vector<Eigen::Matrix3Xd> positions;
  std::vector<int> tris;
  std::size_t total = 0;
  for (std::size_t p = 0; p < mesh.primitives.size(); ++p) {
    const auto& prim = mesh.primitives[p];
    const std::string prim_path = fmt::format("{}.primitives[{}]", mesh_path, p);
    const auto it = prim.attributes.find("POSITION");
    if (it == prim.attributes.end()) throw gltf_error(path, prim_path, "no POSITION attribute");
    Eigen::Matrix3Xd pos = read_vec3(model, it->second, std::nullopt, path, prim_path + ".attributes.POSITION");
    if (total + std::size_t(pos.cols()) > std::size_t(std::numeric_limits<int>::max()))
      throw gltf_error(path, prim_path, "more vertices than a mesh can index");
    for (int index : read_indices(model, prim, std::size_t(pos.cols()), path, prim_path + ".indices"))
      tris.push_back(index + int(total));
    total += std::size_t(pos.cols());
    positions.push_back(std::move(pos));
  }
  if (tris.empty()) throw file_error(path, "mesh has no triangles");
  // Sparse targets describe a whole column of deltas in a few bytes: the dense 3N x M
  // matrix may take at most kMaxExpansion times the bytes read (plus a floor for rigs of
  // tiny files), so a hostile target count cannot claim unbounded memory.
  constexpr std::size_t kMaxExpansion = 64, kFloorBytes = std::size_t(256) << 20;
  std::size_t input_bytes = bytes.size();
  for (const auto& buffer : model.buffers) input_bytes += buffer.data.size();
  const double delta_bytes = 3.0 * double(total) * double(target_count) * sizeof(double);
  if (delta_bytes > double(kMaxExpansion * input_bytes + kFloorBytes))
    throw gltf_error(path, mesh_path,
                     fmt::format("{} morph targets of {} vertices would take {:.0f} MB, more than {} bytes of glTF "
                                 "can describe",
                                 target_count, total, delta_bytes / 1e6, input_bytes));

  Rig rig;
  rig.name = std::filesystem::path(path).stem().string();
  rig.neutral.resize(3, Eigen::Index(total));
  rig.deltas.resize(3 * Eigen::Index(total), Eigen::Index(target_count));
  Eigen::Index offset = 0;
  for (std::size_t p = 0; p < mesh.primitives.size(); ++p) {
    const auto& prim = mesh.primitives[p];
    const Eigen::Index count = positions[p].cols();
    rig.neutral.middleCols(offset, count) = positions[p];
    for (std::size_t t = 0; t < target_count; ++t) {
      const auto tit = prim.targets[t].find("POSITION");
      auto column = rig.deltas.col(Eigen::Index(t)).segment(3 * offset, 3 * count);
      if (tit == prim.targets[t].end()) {
        column.setZero();
        continue;
      }
      const Eigen::Matrix3Xd d = read_vec3(model, tit->second, std::size_t(count), path,
                                           fmt::format("{}.primitives[{}].targets[{}].POSITION", mesh_path, p, t));
      column = Eigen::Map<const Eigen::VectorXd>(d.data(), d.size());
    }
    offset += count;
  }
  rig.triangles = Eigen::Map<const Eigen::Matrix3Xi>(tris.data(), 3, Eigen::Index(tris.size() / 3));
  rig.shape_names = std::move(names);
  return rig;
}

void save_gltf_rig(const Rig& rig, const std::string& path) {
  tinygltf::Model model;
  model.asset.version = "2.0";
  model.asset.generator = "facecap";
  tinygltf::Buffer buffer;
  // One buffer view and accessor over bytes appended to the single buffer.
  auto add_accessor = [&](const void* data, std::size_t bytes, int target, int component, int type,
                          std::size_t count) {
    tinygltf::BufferView view;
    view.buffer = 0;
    view.byteOffset = buffer.data.size();
    view.byteLength = bytes;
    view.target = target;
    const auto* p = static_cast<const unsigned char*>(data);
    buffer.data.insert(buffer.data.end(), p, p + bytes);
    model.bufferViews.push_back(view);
    tinygltf::Accessor acc;
    acc.bufferView = int(model.bufferViews.size() - 1);
    acc.componentType = component;
    acc.type = type;
    acc.count = count;
    model.accessors.push_back(acc);
    return int(model.accessors.size() - 1);
  };
  // Float positions with the min/max bounds glTF requires of POSITION accessors.
  auto add_vec3 = [&](const Eigen::Matrix3Xd& m) {
    const Eigen::Matrix3Xf f = m.cast<float>();
    const int index = add_accessor(f.data(), sizeof(float) * std::size_t(f.size()), TINYGLTF_TARGET_ARRAY_BUFFER,
                                   TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, std::size_t(f.cols()));
    if (f.cols()) {
      const Eigen::Vector3f lo = f.rowwise().minCoeff(), hi = f.rowwise().maxCoeff();
      model.accessors.back().minValues = {lo.x(), lo.y(), lo.z()};
      model.accessors.back().maxValues = {hi.x(), hi.y(), hi.z()};
    }
    return index;
  };
  tinygltf::Primitive prim;
  prim.mode = TINYGLTF_MODE_TRIANGLES;
  prim.attributes["POSITION"] = add_vec3(rig.neutral);
  const Eigen::Matrix<uint32_t, 3, Eigen::Dynamic> indices = rig.triangles.cast<uint32_t>();
  prim.indices = add_accessor(indices.data(), sizeof(uint32_t) * std::size_t(indices.size()),
                              TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER, TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT,
                              TINYGLTF_TYPE_SCALAR, std::size_t(indices.size()));
  tinygltf::Value::Array names;
  for (Eigen::Index s = 0; s < rig.shape_count(); ++s) {
    const Eigen::Map<const Eigen::Matrix3Xd> d(rig.deltas.col(s).data(), 3, rig.vertex_count());
    prim.targets.push_back({{"POSITION", add_vec3(d)}});
    names.emplace_back(rig.shape_names[std::size_t(s)]);
  }
  tinygltf::Mesh mesh;
  mesh.name = rig.name;
  mesh.primitives.push_back(prim);
  tinygltf::Value::Object extras;
  extras["targetNames"] = tinygltf::Value(names);
  mesh.extras = tinygltf::Value(extras);
  model.meshes.push_back(mesh);
  model.buffers.push_back(buffer);
  tinygltf::Node node;
  node.mesh = 0;
  model.nodes.push_back(node);
  tinygltf::Scene scene;
  scene.nodes.push_back(0);
  model.scenes.push_back(scene);
  model.defaultScene = 0;
  tinygltf::TinyGLTF writer;
  const bool binary = path.size() >= 4 && path.substr(path.size() - 4) == ".glb";
  if (!writer.WriteGltfSceneToFile(&model, path, true, true, true, binary))
    throw file_error(path, "cannot write glTF");
}

}  // namespace facecap
