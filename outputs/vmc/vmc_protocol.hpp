#pragma once
// OSC with the VMC protocol (docs/outputs.md) as a network output's protocol: per frame one
// OSC bundle (time tag "immediately") of `/VMC/Ext/Blend/Val ,sf name value` for each
// shape, then `/VMC/Ext/Blend/Apply`, and `/VMC/Ext/Root/Pos` with the head pose when
// asked. The bundle is encoded once; each frame only overwrites its float values.
#include <cstddef>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

#include "outputs/net/net_sink.hpp"

namespace facecap::outputs {

// One name sent, and the rig weights whose mean is its value.
struct VmcShape {
  std::string name;
  std::vector<std::size_t> rig_shapes;
};

// The shapes to send for a rig ([outputs.vmc] names): the 52 ARKit names in Epic's order
// ("perfect sync"; a shape the rig lacks is sent as 0)...
std::vector<VmcShape> arkit_vmc_shapes(std::span<const std::string> rig_shape_names);
// ... the rig's own names ...
std::vector<VmcShape> rig_vmc_shapes(std::span<const std::string> rig_shape_names);
// ... or the names a TOML map file's [names] table gives rig shapes (jawOpen = "A"); shapes
// it leaves out are not sent. Throws Error naming the file, line and key of a problem.
std::vector<VmcShape> mapped_vmc_shapes(std::span<const std::string> rig_shape_names, const std::filesystem::path& map_file);

struct VmcRootPose {
  bool enabled = false;
  double scale = 0.01;  // metres per rig unit
};

class VmcProtocol final : public NetProtocol {
 public:
  // Not RT-safe; throws Error when the bundle would not fit one datagram.
  VmcProtocol(std::vector<VmcShape> shapes, VmcRootPose root);

  std::string_view name() const noexcept override { return "vmc"; }
  std::string description() const override;
  bool send_frame(const SolvedFrame& frame, UdpSender& out) override;

  // The bundle as last sent (tests).
  const std::vector<char>& bundle() const noexcept { return bundle_; }

 private:
  std::vector<VmcShape> shapes_;
  VmcRootPose root_;
  std::vector<char> bundle_;
  std::vector<std::size_t> value_offsets_;  // per shape
  std::size_t root_offset_ = 0;             // of the first of the 7 root floats
};

}  // namespace facecap::outputs
