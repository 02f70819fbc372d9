#include "outputs/vmc/vmc_protocol.hpp"

#include <algorithm>
#include <set>

#include <fmt/format.h>

#include "core/error.hpp"
#include "core/toml_reader.hpp"
#include "formats/arkit.hpp"
#include "formats/osc.hpp"

namespace facecap::outputs {
namespace {

// UDP's largest payload over IPv4.
constexpr std::size_t kMaxBundleBytes = 65507;

}  // namespace

std::vector<VmcShape> mapped_vmc_shapes(std::span<const std::string> rig_shape_names, const std::filesystem::path& file) {
  const toml::table doc = parse_toml_file(file);
  const toml::table* names = doc["names"].as_table();
  if (!names) throw file_error(file.string(), "no [names] table (rig shape = \"name to send\")");
  std::vector<VmcShape> out;
  std::set<std::string> sent;
  for (const auto& [key, value] : *names) {
    const std::string rig(key.str());
    const auto problem = [&](const std::string& what) {
      return line_error(file.string(), int64_t(key.source().begin.line), fmt::format("names.{}: {}", rig, what));
    };
    const auto* text = value.as_string();
    if (!text || text->get().empty()) throw problem("the name to send must be a non-empty string");
    const auto found = std::find(rig_shape_names.begin(), rig_shape_names.end(), rig);
    if (found == rig_shape_names.end()) throw problem("the rig has no shape of that name");
    if (!sent.insert(text->get()).second) throw problem(fmt::format("\"{}\" is given to two shapes", text->get()));
    out.push_back({text->get(), {std::size_t(found - rig_shape_names.begin())}});
  }
  return out;
}

std::vector<VmcShape> arkit_vmc_shapes(std::span<const std::string> rig_shape_names) {
  const auto binding = formats::match_arkit_to_rig(rig_shape_names);
  std::vector<VmcShape> out;
  for (std::size_t a = 0; a < formats::kArkitShapeCount; ++a)
    out.push_back({std::string(formats::kArkitShapes[a].arkit), binding[a]});
  return out;
}

std::vector<VmcShape> rig_vmc_shapes(std::span<const std::string> rig_shape_names) {
  std::vector<VmcShape> out;
  for (std::size_t i = 0; i < rig_shape_names.size(); ++i) out.push_back({rig_shape_names[i], {i}});
  return out;
}

VmcProtocol::VmcProtocol(std::vector<VmcShape> shapes, VmcRootPose root) : shapes_(std::move(shapes)), root_(root) {
  formats::osc::OscWriter osc(bundle_);
  osc.begin_bundle();
  for (const VmcShape& shape : shapes_) {
    osc.begin_message("/VMC/Ext/Blend/Val", "sf");
    osc.string(shape.name);
    value_offsets_.push_back(osc.float32(0.0f));
    osc.end_message();
  }
  osc.begin_message("/VMC/Ext/Blend/Apply", "");
  osc.end_message();
  if (root_.enabled) {
    osc.begin_message("/VMC/Ext/Root/Pos", "sfffffff");
    osc.string("root");
    root_offset_ = osc.float32(0.0f);
    for (int i = 0; i < 6; ++i) osc.float32(i == 5 ? 1.0f : 0.0f);
    osc.end_message();
  }
  osc.end_bundle();
  if (bundle_.size() > kMaxBundleBytes)
    throw Error(fmt::format("a VMC bundle of {} shapes takes {} bytes, more than one datagram carries ({})",
                            shapes_.size(), bundle_.size(), kMaxBundleBytes));
}

std::string VmcProtocol::description() const {
  return fmt::format("VMC (OSC) {} shapes{}, {} bytes a frame", shapes_.size(), root_.enabled ? " and the root pose" : "",
                     bundle_.size());
}

bool VmcProtocol::send_frame(const SolvedFrame& frame, UdpSender& out) {
  const std::span<const float> weights(frame.weights.data(), std::size_t(frame.weights.size()));
  for (std::size_t s = 0; s < shapes_.size(); ++s)
    formats::osc::patch_float32(bundle_, value_offsets_[s], formats::mean_weight(shapes_[s].rig_shapes, weights));
  if (root_.enabled) {
    // Unity is left-handed with Y up: mirroring the rig's right-handed frame in X negates
    // x of a position and y, z of a rotation's axis.
    const Eigen::Vector3d p = frame.head_translation * root_.scale;
    const Eigen::Quaterniond& q = frame.head_rotation;
    const float values[7] = {float(-p.x()), float(p.y()), float(p.z()), float(q.x()), float(-q.y()), float(-q.z()), float(q.w())};
    for (int i = 0; i < 7; ++i) formats::osc::patch_float32(bundle_, root_offset_ + 4 * std::size_t(i), values[i]);
  }
  return out.send(std::span<const char>(bundle_));
}

}  // namespace facecap::outputs
