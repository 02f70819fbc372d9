#include "solver/fbx_rig.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <map>
#include <set>
#include <string_view>
#include <vector>

#include <assimp/Importer.hpp>
#include <assimp/mesh.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <fmt/format.h>

#include "core/error.hpp"
#include "core/io.hpp"
#include "core/printable.hpp"

namespace facecap {
namespace {

// A mesh node's transform to the scene root: where the artist placed the mesh.
bool find_mesh_transform(const aiNode& node, unsigned mesh, const aiMatrix4x4& parent, aiMatrix4x4& out) {
  const aiMatrix4x4 here = parent * node.mTransformation;
  for (unsigned i = 0; i < node.mNumMeshes; ++i)
    if (node.mMeshes[i] == mesh) {
      out = here;
      return true;
    }
  for (unsigned c = 0; c < node.mNumChildren; ++c)
    if (node.mChildren[c] && find_mesh_transform(*node.mChildren[c], mesh, here, out)) return true;
  return false;
}

Rig rig_from_scene(const aiScene& scene, const std::string& name, FbxContents* contents) {
  FbxContents found;
  const aiMesh* rig_mesh = nullptr;
  for (unsigned m = 0; m < scene.mNumMeshes; ++m) {
    const aiMesh* mesh = scene.mMeshes[m];
    if (!mesh) continue;
    found.meshes.push_back({mesh->mName.C_Str(), mesh->mNumVertices, mesh->mNumFaces, mesh->mNumAnimMeshes});
    if (!rig_mesh && mesh->mNumAnimMeshes > 0 && mesh->mNumVertices > 0) {
      rig_mesh = mesh;
      found.rig_mesh = found.meshes.size() - 1;
    }
  }
  if (!rig_mesh)
    throw file_error(name, scene.mNumMeshes == 0 ? "no mesh" : fmt::format("none of its {} meshes has blendshape channels",
                                                                             scene.mNumMeshes));
  const aiMesh& mesh = *rig_mesh;
  // Names from the file, shown in messages: made safe for a terminal and a log first.
  const std::string mesh_name = fmt::format("mesh '{}'", printable(mesh.mName.C_Str()));
  aiMatrix4x4 to_scene;
  if (scene.mRootNode) find_mesh_transform(*scene.mRootNode, unsigned(found.rig_mesh), aiMatrix4x4(), to_scene);

  const std::size_t corners = mesh.mNumVertices;
  const std::size_t shape_count = mesh.mNumAnimMeshes;
  std::vector<std::string> names;
  std::set<std::string> seen;
  for (std::size_t s = 0; s < shape_count; ++s) {
    const aiAnimMesh* shape = mesh.mAnimMeshes[s];
    if (!shape || !shape->mVertices || shape->mNumVertices != corners)
      throw file_error(name, fmt::format("{}: blendshape channel {} has {} vertices, the mesh {}", mesh_name, s,
                                         shape ? shape->mNumVertices : 0, corners));
    std::string channel = shape->mName.C_Str();
    if (channel.empty()) channel = fmt::format("shape{}", s);
    if (!seen.insert(channel).second)
      throw file_error(name, fmt::format("{}: blendshape channel name '{}' appears twice", mesh_name, printable(channel)));
    names.push_back(std::move(channel));
  }

  // Weld: a corner joins the vertex of an earlier corner with the same position in the
  // neutral and in every shape (bit for bit: corners of one FBX control point carry the
  // same numbers), so distinct vertices that touch in the neutral stay apart.
  auto position = [&](std::size_t shape, std::size_t corner) -> const aiVector3D& {
    return shape == 0 ? mesh.mVertices[corner] : mesh.mAnimMeshes[shape - 1]->mVertices[corner];
  };
  auto key_of = [&](std::size_t corner) {
    std::vector<float> key(3 * (shape_count + 1));
    for (std::size_t s = 0; s <= shape_count; ++s) {
      const aiVector3D& p = position(s, corner);
      if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z))
        throw file_error(name, fmt::format("{}: vertex {} of {} is not a finite number", mesh_name, corner,
                                           s == 0 ? std::string("the neutral") : "channel '" + printable(names[s - 1]) + "'"));
      key[3 * s] = p.x + 0.0f;  // + 0: -0 and 0 are one position
      key[3 * s + 1] = p.y + 0.0f;
      key[3 * s + 2] = p.z + 0.0f;
    }
    return key;
  };
  std::map<std::vector<float>, int> vertex_of_key;
  Rig rig;
  rig.file_vertex_of.resize(corners);
  std::vector<std::size_t> first_corner;
  for (std::size_t c = 0; c < corners; ++c) {
    const auto [it, added] = vertex_of_key.emplace(key_of(c), int(first_corner.size()));
    if (added) first_corner.push_back(c);
    rig.file_vertex_of[c] = it->second;
  }
  const auto n = Eigen::Index(first_corner.size());
  auto to_rig = [&](const aiVector3D& p) {
    const aiVector3D q = to_scene * p;
    return Eigen::Vector3d(q.x, q.y, q.z);
  };
  rig.neutral.resize(3, n);
  rig.deltas.resize(3 * n, Eigen::Index(shape_count));
  for (Eigen::Index v = 0; v < n; ++v) {
    const std::size_t c = first_corner[std::size_t(v)];
    rig.neutral.col(v) = to_rig(mesh.mVertices[c]);
    for (std::size_t s = 0; s < shape_count; ++s)
      rig.deltas.col(Eigen::Index(s)).segment<3>(3 * v) = to_rig(mesh.mAnimMeshes[s]->mVertices[c]) - rig.neutral.col(v);
  }
  std::vector<int> triangles;
  for (unsigned f = 0; f < mesh.mNumFaces; ++f) {
    const aiFace& face = mesh.mFaces[f];
    if (face.mNumIndices < 3) continue;  // points and lines are not surface
    for (unsigned k = 0; k < face.mNumIndices; ++k)
      if (face.mIndices[k] >= corners)
        throw file_error(name, fmt::format("{}: face {} uses vertex {} of {}", mesh_name, f, face.mIndices[k], corners));
    for (unsigned k = 1; k + 1 < face.mNumIndices; ++k)
      for (unsigned corner : {face.mIndices[0], face.mIndices[k], face.mIndices[k + 1]})
        triangles.push_back(rig.file_vertex_of[corner]);
  }
  if (triangles.empty()) throw file_error(name, fmt::format("{} has no faces", mesh_name));
  rig.triangles = Eigen::Map<const Eigen::Matrix3Xi>(triangles.data(), 3, Eigen::Index(triangles.size() / 3));
  rig.shape_names = std::move(names);
  rig.name = mesh.mName.length > 0 ? mesh.mName.C_Str() : name;
  found.vertices_before_weld = corners;
  found.vertices_after_weld = std::size_t(n);
  if (contents) *contents = std::move(found);
  return rig;
}

// assimp would read any format it knows from these bytes; a rig.path ending in .fbx must
// be an FBX (binary, or ASCII with its header block).
constexpr std::string_view kBinaryMagic = "Kaydara FBX Binary";

bool looks_like_fbx(std::span<const char> bytes) {
  const std::string_view head(bytes.data(), std::min<std::size_t>(bytes.size(), 4096));
  return head.starts_with(kBinaryMagic) || head.find("FBXHeaderExtension") != std::string_view::npos;
}

// A binary FBX's records walked before assimp sees them (its reader allocates what an
// array's header claims: 13.8 KB of hostile file asked for 2.55 GB). Every record and
// property must lie inside its parent, and an array may hold no more than its stored
// bytes can: as many (raw) or 1032 times as many (zlib's largest ratio). Layout: the
// 27-byte header (magic, 0x1A 0x00, version u32), then records of end offset, property
// count and property bytes (u64 each from version 7500, else u32), a name (u8 length),
// the properties, the nested records and a null record.
void check_binary_fbx_arrays(std::span<const char> bytes, const std::string& name) {
  constexpr std::size_t kHeader = 27;
  if (bytes.size() < kHeader) throw file_error(name, "a binary FBX shorter than its header");
  auto u32 = [&](std::size_t at) {
    uint32_t v;
    std::memcpy(&v, bytes.data() + at, 4);
    return uint64_t(v);
  };
  auto u64 = [&](std::size_t at) {
    uint64_t v;
    std::memcpy(&v, bytes.data() + at, 8);
    return v;
  };
  const bool wide = u32(23) >= 7500;
  const std::size_t word = wide ? 8 : 4;
  auto bad = [&](std::size_t at, std::string what) { return offset_error(name, int64_t(at), std::move(what)); };
  std::vector<uint64_t> ends{bytes.size()};  // the enclosing records' ends
  std::size_t at = kHeader;
  while (!ends.empty()) {
    if (at == ends.back()) {
      ends.pop_back();
      continue;
    }
    if (at + 3 * word + 1 > ends.back()) {
      if (ends.size() == 1) break;  // the file's footer
      throw bad(at, "an FBX record runs past the record holding it");
    }
    const uint64_t end = wide ? u64(at) : u32(at);
    const uint64_t properties = wide ? u64(at + 8) : u32(at + 4), property_bytes = wide ? u64(at + 16) : u32(at + 8);
    const std::size_t name_length = uint8_t(bytes[at + 3 * word]);
    if (end == 0) {  // a null record ends the list; after the top level's, the footer
      if (ends.size() == 1) break;
      at = ends.back();
      ends.pop_back();
      continue;
    }
    std::size_t p = at + 3 * word + 1 + name_length;
    if (end <= at || end > ends.back() || p > end || property_bytes > end - p)
      throw bad(at, "an FBX record's end or properties lie outside the record holding it");
    const std::size_t properties_end = p + std::size_t(property_bytes);
    for (uint64_t i = 0; i < properties; ++i) {
      if (p >= properties_end) throw bad(p, "an FBX record has fewer property bytes than its properties need");
      const char type = bytes[p++];
      std::size_t size = 0;
      switch (type) {
        case 'C': size = 1; break;
        case 'Y': size = 2; break;
        case 'I': case 'F': size = 4; break;
        case 'D': case 'L': size = 8; break;
        case 'S': case 'R':
          if (p + 4 > properties_end) throw bad(p, "an FBX string runs past its record");
          size = 4 + std::size_t(u32(p));
          break;
        case 'f': case 'i': case 'd': case 'l': case 'b': {
          if (p + 12 > properties_end) throw bad(p, "an FBX array header runs past its record");
          const uint64_t count = u32(p), encoding = u32(p + 4), stored = u32(p + 8);
          const uint64_t element = type == 'b' ? 1 : (type == 'd' || type == 'l') ? 8 : 4;
          if ((encoding == 0 && count * element != stored) || (encoding != 0 && count * element > 1032 * stored + 64))
            throw bad(p, fmt::format("an FBX array claims {} values in {} stored bytes", count, stored));
          size = 12 + std::size_t(stored);
          break;
        }
        default: throw bad(p - 1, fmt::format("an FBX property of unknown type {}", int(uint8_t(type))));
      }
      if (size > properties_end - p) throw bad(p, "an FBX property runs past its record");
      p += size;
    }
    ends.push_back(end);
    if (ends.size() > 64) throw bad(at, "FBX records nested deeper than 64");
    at = properties_end;
  }
}

}  // namespace

bool is_fbx_path(const std::filesystem::path& path) {
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return ext == ".fbx";
}

Rig load_fbx_rig(const std::string& path, FbxContents* contents) {
  const std::vector<char> bytes = read_file_bytes(path);
  return parse_fbx_rig(bytes, path, contents);
}

Rig parse_fbx_rig(std::span<const char> bytes, const std::string& name, FbxContents* contents) {
  if (bytes.empty()) throw file_error(name, "empty file");
  if (!looks_like_fbx(bytes))
    throw file_error(name, "not an FBX file (neither the binary 'Kaydara FBX Binary' header nor an ASCII FBXHeaderExtension)");
  if (std::string_view(bytes.data(), bytes.size()).starts_with(kBinaryMagic)) check_binary_fbx_arrays(bytes, name);
  Assimp::Importer importer;
  const aiScene* scene = importer.ReadFileFromMemory(bytes.data(), bytes.size(), aiProcess_ValidateDataStructure, "fbx");
  if (!scene) throw file_error(name, fmt::format("assimp cannot read it: {}", importer.GetErrorString()));
  return rig_from_scene(*scene, name, contents);
}

}  // namespace facecap
