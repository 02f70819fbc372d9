#include "solver/gltf_rig.hpp"

#include <cstring>

#include <fmt/format.h>
#include <tiny_gltf.h>

#include "core/error.hpp"

namespace facecap {
namespace {

Error gltf_error(const std::string& file, const std::string& json_path, std::string what) {
  return Error(std::move(what), ErrorLocation{.file = file, .key = json_path});
}

// Reads a float VEC3 accessor (dense and/or sparse) into 3 x count.
Eigen::Matrix3Xd read_vec3(const tinygltf::Model& model, int accessor_index, const std::string& file,
                           const std::string& json_path) {
  if (accessor_index < 0 || accessor_index >= int(model.accessors.size()))
    throw gltf_error(file, json_path, fmt::format("accessor {} does not exist", accessor_index));
  const auto& acc = model.accessors[std::size_t(accessor_index)];
  if (acc.type != TINYGLTF_TYPE_VEC3 || acc.componentType != TINYGLTF_COMPONENT_TYPE_FLOAT)
    throw gltf_error(file, json_path, "positions must be float VEC3");
  Eigen::Matrix3Xd out = Eigen::Matrix3Xd::Zero(3, Eigen::Index(acc.count));
  auto view_bytes = [&](int view_index, std::size_t offset, std::size_t elem_size, std::size_t count,
                        const std::string& what) -> std::pair<const unsigned char*, std::size_t> {
    if (view_index < 0 || view_index >= int(model.bufferViews.size()))
      throw gltf_error(file, json_path, fmt::format("{}: bufferView {} does not exist", what, view_index));
    const auto& view = model.bufferViews[std::size_t(view_index)];
    if (view.buffer < 0 || view.buffer >= int(model.buffers.size()))
      throw gltf_error(file, json_path, fmt::format("{}: buffer {} does not exist", what, view.buffer));
    const auto& buffer = model.buffers[std::size_t(view.buffer)].data;
    const std::size_t stride = view.byteStride ? view.byteStride : elem_size;
    const std::size_t begin = view.byteOffset + offset;
    if (count && (begin + (count - 1) * stride + elem_size > buffer.size() || begin + (count - 1) * stride + elem_size > view.byteOffset + view.byteLength))
      throw gltf_error(file, json_path, fmt::format("{}: data runs past the end of its buffer", what));
    return {buffer.data() + begin, stride};
  };
  if (acc.bufferView >= 0) {
    const auto [p, stride] = view_bytes(acc.bufferView, acc.byteOffset, 12, acc.count, "accessor");
    for (std::size_t i = 0; i < acc.count; ++i) {
      float v[3];
      std::memcpy(v, p + i * stride, 12);
      out.col(Eigen::Index(i)) << v[0], v[1], v[2];
    }
  }
  if (acc.sparse.isSparse) {
    const std::size_t n = std::size_t(acc.sparse.count);
    const int index_type = acc.sparse.indices.componentType;
    const std::size_t index_size = index_type == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE ? 1
                                   : index_type == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT ? 2 : 4;
    const auto [ip, istride] = view_bytes(acc.sparse.indices.bufferView, acc.sparse.indices.byteOffset, index_size, n, "sparse indices");
    const auto [vp, vstride] = view_bytes(acc.sparse.values.bufferView, acc.sparse.values.byteOffset, 12, n, "sparse values");
    for (std::size_t i = 0; i < n; ++i) {
      uint32_t index = 0;
      std::memcpy(&index, ip + i * istride, index_size);  // little-endian host
      if (index >= acc.count) throw gltf_error(file, json_path, fmt::format("sparse index {} out of range", index));
      float v[3];
      std::memcpy(v, vp + i * vstride, 12);
      out.col(Eigen::Index(index)) << v[0], v[1], v[2];
    }
  }
  return out;
}

std::vector<int> read_indices(const tinygltf::Model& model, const tinygltf::Primitive& prim, std::size_t vertex_count,
                              const std::string& file, const std::string& json_path) {
  std::vector<int> out;
  if (prim.indices < 0) {  // non-indexed triangles
    for (std::size_t i = 0; i < vertex_count; ++i) out.push_back(int(i));
    return out;
  }
  if (prim.indices >= int(model.accessors.size())) throw gltf_error(file, json_path, "indices accessor does not exist");
  const auto& acc = model.accessors[std::size_t(prim.indices)];
  const std::size_t size = acc.componentType == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE ? 1
                           : acc.componentType == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT ? 2
                           : acc.componentType == TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT ? 4 : 0;
  if (!size || acc.type != TINYGLTF_TYPE_SCALAR) throw gltf_error(file, json_path, "indices must be unsigned scalars");
  if (acc.bufferView < 0 || acc.bufferView >= int(model.bufferViews.size()))
    throw gltf_error(file, json_path, "indices have no bufferView");
  const auto& view = model.bufferViews[std::size_t(acc.bufferView)];
  if (view.buffer < 0 || view.buffer >= int(model.buffers.size())) throw gltf_error(file, json_path, "indices buffer does not exist");
  const auto& buffer = model.buffers[std::size_t(view.buffer)].data;
  const std::size_t stride = view.byteStride ? view.byteStride : size;
  const std::size_t begin = view.byteOffset + acc.byteOffset;
  if (acc.count && begin + (acc.count - 1) * stride + size > buffer.size())
    throw gltf_error(file, json_path, "indices run past the end of their buffer");
  for (std::size_t i = 0; i < acc.count; ++i) {
    uint32_t index = 0;
    std::memcpy(&index, buffer.data() + begin + i * stride, size);
    if (index >= vertex_count)
      throw gltf_error(file, json_path, fmt::format("index {} out of range (primitive has {} vertices)", index, vertex_count));
    out.push_back(int(index));
  }
  if (out.size() % 3) throw gltf_error(file, json_path, "index count is not a multiple of 3");
  return out;
}

}  // namespace

Rig load_gltf_rig(const std::string& path) {
  tinygltf::TinyGLTF loader;
  tinygltf::Model model;
  std::string err, warn;
  const bool binary = path.size() >= 4 && path.substr(path.size() - 4) == ".glb";
  const bool ok = binary ? loader.LoadBinaryFromFile(&model, &err, &warn, path)
                         : loader.LoadASCIIFromFile(&model, &err, &warn, path);
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
    for (int i = 0; i < int(list.ArrayLen()); ++i) names.push_back(list.Get(i).Get<std::string>());
  }
  if (names.size() != target_count) {
    names.clear();
    for (std::size_t i = 0; i < target_count; ++i) names.push_back(fmt::format("target_{}", i));
  }
  for (std::size_t i = 0; i < names.size(); ++i)
    for (std::size_t j = 0; j < i; ++j)
      if (names[i] == names[j]) throw gltf_error(path, mesh_path + ".extras.targetNames", fmt::format("duplicate shape name '{}'", names[i]));

  std::vector<Eigen::Matrix3Xd> positions, deltas(target_count);
  std::vector<int> tris;
  Eigen::Index total = 0;
  for (std::size_t p = 0; p < mesh.primitives.size(); ++p) {
    const auto& prim = mesh.primitives[p];
    const std::string prim_path = fmt::format("{}.primitives[{}]", mesh_path, p);
    const auto it = prim.attributes.find("POSITION");
    if (it == prim.attributes.end()) throw gltf_error(path, prim_path, "no POSITION attribute");
    Eigen::Matrix3Xd pos = read_vec3(model, it->second, path, prim_path + ".attributes.POSITION");
    for (int index : read_indices(model, prim, std::size_t(pos.cols()), path, prim_path + ".indices"))
      tris.push_back(index + int(total));
    for (std::size_t t = 0; t < target_count; ++t) {
      const std::string target_path = fmt::format("{}.targets[{}].POSITION", prim_path, t);
      const auto tit = prim.targets[t].find("POSITION");
      Eigen::Matrix3Xd d = Eigen::Matrix3Xd::Zero(3, pos.cols());
      if (tit != prim.targets[t].end()) {
        d = read_vec3(model, tit->second, path, target_path);
        if (d.cols() != pos.cols()) throw gltf_error(path, target_path, "vertex count differs from POSITION");
      }
      deltas[t].conservativeResize(3, total + pos.cols());
      deltas[t].rightCols(pos.cols()) = d;
    }
    positions.push_back(std::move(pos));
    total += positions.back().cols();
  }
  Rig rig;
  rig.name = std::filesystem::path(path).stem().string();
  rig.neutral.resize(3, total);
  Eigen::Index offset = 0;
  for (const auto& pos : positions) { rig.neutral.middleCols(offset, pos.cols()) = pos; offset += pos.cols(); }
  rig.triangles = Eigen::Map<const Eigen::Matrix3Xi>(tris.data(), 3, Eigen::Index(tris.size() / 3));
  rig.shape_names = names;
  rig.deltas.resize(3 * total, Eigen::Index(target_count));
  for (std::size_t t = 0; t < target_count; ++t)
    rig.deltas.col(Eigen::Index(t)) = Eigen::Map<const Eigen::VectorXd>(deltas[t].data(), deltas[t].size());
  if (rig.triangles.cols() == 0) throw file_error(path, "mesh has no triangles");
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
