#include "tools/export_gltf.hpp"

#include <cstring>
#include <sstream>

#include <fmt/format.h>
#include <tiny_gltf.h>

#include "core/error.hpp"
#include "core/io.hpp"

namespace facecap::tools {
namespace {

// Appends accessors to one buffer: each its own view, 4-byte aligned (every element here
// is a float or a uint32).
class GltfBuilder {
 public:
  explicit GltfBuilder(tinygltf::Model& model) : model_(model) {}

  int add(const void* data, std::size_t bytes, int target, int component, int type, std::size_t count) {
    tinygltf::BufferView view;
    view.buffer = 0;
    view.byteOffset = buffer_.size();
    view.byteLength = bytes;
    view.target = target;
    const auto* p = static_cast<const unsigned char*>(data);
    buffer_.insert(buffer_.end(), p, p + bytes);
    model_.bufferViews.push_back(view);
    tinygltf::Accessor accessor;
    accessor.bufferView = int(model_.bufferViews.size() - 1);
    accessor.componentType = component;
    accessor.type = type;
    accessor.count = count;
    model_.accessors.push_back(accessor);
    return int(model_.accessors.size() - 1);
  }
  // Float positions with the bounds glTF requires of POSITION accessors.
  int add_positions(const Eigen::Matrix3Xf& points) {
    const int index = add(points.data(), sizeof(float) * std::size_t(points.size()), TINYGLTF_TARGET_ARRAY_BUFFER,
                          TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, std::size_t(points.cols()));
    const Eigen::Vector3f lo = points.rowwise().minCoeff(), hi = points.rowwise().maxCoeff();
    model_.accessors.back().minValues = {lo.x(), lo.y(), lo.z()};
    model_.accessors.back().maxValues = {hi.x(), hi.y(), hi.z()};
    return index;
  }
  int add_floats(const std::vector<float>& values, int type, std::size_t count) {
    return add(values.data(), sizeof(float) * values.size(), 0, TINYGLTF_COMPONENT_TYPE_FLOAT, type, count);
  }
  void finish() {
    tinygltf::Buffer buffer;
    buffer.data = std::move(buffer_);
    model_.buffers.push_back(std::move(buffer));
  }

 private:
  tinygltf::Model& model_;
  std::vector<unsigned char> buffer_;
};

}  // namespace

void write_gltf_take(const std::filesystem::path& path, const GltfTake& take, const Rig* rig, double metres_per_unit) {
  const std::string file = path.string();
  const std::size_t frames = take.times_s.size();
  const std::size_t shapes = take.shape_names.size();
  if (frames == 0) throw file_error(file, "no frames to export");
  if (shapes == 0) throw file_error(file, "the take has no shapes to animate");
  if (take.weights.size() != frames * shapes || take.head_rotation.size() != frames ||
      take.head_translation.size() != frames)
    throw file_error(file, "the take's weights and head poses do not cover every frame");
  if (rig && rig->shape_names != take.shape_names)
    throw file_error(file, "the rig's shapes are not the take's shapes");

  tinygltf::Model model;
  model.asset.version = "2.0";
  model.asset.generator = "facecap export";
  GltfBuilder builder(model);

  tinygltf::Primitive primitive;
  tinygltf::Value::Array names;
  for (const auto& name : take.shape_names) names.emplace_back(name);
  if (rig) {
    primitive.mode = TINYGLTF_MODE_TRIANGLES;
    primitive.attributes["POSITION"] = builder.add_positions((rig->neutral * metres_per_unit).cast<float>());
    const Eigen::Matrix<uint32_t, 3, Eigen::Dynamic> indices = rig->triangles.cast<uint32_t>();
    primitive.indices = builder.add(indices.data(), sizeof(uint32_t) * std::size_t(indices.size()),
                                    TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER, TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT,
                                    TINYGLTF_TYPE_SCALAR, std::size_t(indices.size()));
    for (Eigen::Index s = 0; s < rig->shape_count(); ++s) {
      const Eigen::Map<const Eigen::Matrix3Xd> delta(rig->deltas.col(s).data(), 3, rig->vertex_count());
      primitive.targets.push_back({{"POSITION", builder.add_positions((delta * metres_per_unit).cast<float>())}});
    }
  } else {
    primitive.mode = TINYGLTF_MODE_POINTS;
    const Eigen::Matrix3Xf point = Eigen::Matrix3Xf::Zero(3, 1);
    primitive.attributes["POSITION"] = builder.add_positions(point);
    const int zero_target = builder.add_positions(point);
    for (std::size_t s = 0; s < shapes; ++s) primitive.targets.push_back({{"POSITION", zero_target}});
  }
  tinygltf::Mesh mesh;
  mesh.name = rig ? rig->name : "weights";
  mesh.primitives.push_back(primitive);
  mesh.weights.assign(shapes, 0.0);
  mesh.extras = tinygltf::Value(tinygltf::Value::Object{{"targetNames", tinygltf::Value(names)}});
  model.meshes.push_back(mesh);

  tinygltf::Node head;
  head.name = "head";
  head.mesh = 0;
  model.nodes.push_back(head);
  tinygltf::Scene scene;
  scene.nodes.push_back(0);
  model.scenes.push_back(scene);
  model.defaultScene = 0;

  // The animation: times (with the bounds glTF requires of sampler inputs), then one
  // sampler per animated property, all keyed on those times.
  const int times = builder.add_floats(take.times_s, TINYGLTF_TYPE_SCALAR, frames);
  model.accessors[std::size_t(times)].minValues = {take.times_s.front()};
  model.accessors[std::size_t(times)].maxValues = {take.times_s.back()};
  std::vector<float> rotations, translations;
  rotations.reserve(4 * frames);
  translations.reserve(3 * frames);
  for (std::size_t f = 0; f < frames; ++f) {
    const Eigen::Quaternionf q = take.head_rotation[f].normalized();
    rotations.insert(rotations.end(), {q.x(), q.y(), q.z(), q.w()});
    const Eigen::Vector3f t = take.head_translation[f] * float(metres_per_unit);
    translations.insert(translations.end(), {t.x(), t.y(), t.z()});
  }
  tinygltf::Animation animation;
  auto animate = [&](int output, const char* property) {
    tinygltf::AnimationSampler sampler;
    sampler.input = times;
    sampler.output = output;
    sampler.interpolation = "LINEAR";
    animation.samplers.push_back(sampler);
    tinygltf::AnimationChannel channel;
    channel.sampler = int(animation.samplers.size() - 1);
    channel.target_node = 0;
    channel.target_path = property;
    animation.channels.push_back(channel);
  };
  animate(builder.add_floats(take.weights, TINYGLTF_TYPE_SCALAR, frames * shapes), "weights");
  animate(builder.add_floats(rotations, TINYGLTF_TYPE_VEC4, frames), "rotation");
  animate(builder.add_floats(translations, TINYGLTF_TYPE_VEC3, frames), "translation");
  tinygltf::Value::Object extras;
  for (const auto& [key, value] : take.extras)
    if (!value.empty()) extras[key] = tinygltf::Value(value);
  for (const auto& [key, value] : take.extras)
    if (key == "take" && !value.empty()) animation.name = value;
  if (animation.name.empty()) animation.name = path.stem().string();
  animation.extras = tinygltf::Value(extras);
  model.animations.push_back(animation);
  builder.finish();

  std::ostringstream out;
  tinygltf::TinyGLTF writer;
  if (!writer.WriteGltfSceneToStream(&model, out, /*prettyPrint=*/false, /*writeBinary=*/path.extension() == ".glb"))
    throw file_error(file, "cannot encode the glTF");
  const std::string bytes = std::move(out).str();
  write_file_atomically(path, std::span<const char>(bytes.data(), bytes.size()));
}

}  // namespace facecap::tools
