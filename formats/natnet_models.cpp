// NAT_MODELDEF, bitstreams 3.0 to 4.x, read and written by one layout (natnet_layout.hpp).
// As the NatNet SDK 4.3 PacketClient.cpp UnpackDescription and NatNetClient.py
// __unpack_data_descriptions: `i32 count`, then per description `i32 type`, [4.1+: `i32
// size`], the body. Skeleton bones are full rigid-body descriptions (markers included), as
// in both SDK samples.
#include "formats/natnet_layout.hpp"

namespace facecap::formats::natnet::detail {
namespace {

// Smallest encoded sizes, to bound counts before allocating.
constexpr std::size_t kNameBytes = 1;
constexpr std::size_t kRigidBodyMarkerBytes = 12 + 4;  // offset, active label (+ name from 4.0)
constexpr std::size_t kMarkerDescriptionBytes = 1 + 4 + 12 + 4 + 2;

std::size_t rigid_body_description_bytes(const Layout& layout) {
  return kNameBytes + 4 + 4 + 12 + (layout.rigid_body_rotation ? 16 : 0) + 4;
}

template <typename IO, typename Names>
void names_layout(IO& io, Names& names, std::string_view what) {
  list_layout(io, names, kNameBytes, false, what, [&](auto& name) { io.cstring(name, what); });
}

template <typename IO, typename Body>
void rigid_body_layout(IO& io, Body& body, const Layout& layout) {
  io.cstring(body.name, "rigid body name");
  io.value(body.id, "rigid body id");
  io.value(body.parent_id, "rigid body parent id");
  io.value(body.offset, "rigid body offset");
  if (layout.rigid_body_rotation) io.value(body.rotation, "rigid body rotation");
  // Three parallel arrays: offsets, active labels, then (4.0+) names.
  io.count(body.markers, kRigidBodyMarkerBytes + (layout.rigid_body_marker_names ? kNameBytes : 0),
           "rigid body marker");
  for (auto& marker : body.markers) io.value(marker.offset, "rigid body marker offset");
  for (auto& marker : body.markers) io.value(marker.active_label, "rigid body marker active label");
  if (layout.rigid_body_marker_names) {
    for (auto& marker : body.markers) io.cstring(marker.name, "rigid body marker name");
  }
}

template <typename IO, typename Description>
void description_layout(IO& io, Description& d, const Layout& layout) {
  using T = std::remove_const_t<Description>;
  if constexpr (std::is_same_v<T, MarkerSetDescription>) {
    io.cstring(d.name, "marker set name");
    names_layout(io, d.marker_names, "marker set marker name");
  } else if constexpr (std::is_same_v<T, RigidBodyDescription>) {
    rigid_body_layout(io, d, layout);
  } else if constexpr (std::is_same_v<T, SkeletonDescription>) {
    io.cstring(d.name, "skeleton name");
    io.value(d.id, "skeleton id");
    list_layout(io, d.bones, rigid_body_description_bytes(layout), false, "skeleton bone",
                [&](auto& bone) { rigid_body_layout(io, bone, layout); });
  } else if constexpr (std::is_same_v<T, ForcePlateDescription>) {
    io.value(d.id, "force plate id");
    io.cstring(d.serial_number, "force plate serial number");
    io.value(d.width, "force plate width");
    io.value(d.length, "force plate length");
    io.value(d.origin, "force plate origin");
    io.value(d.calibration, "force plate calibration matrix");
    io.value(d.corners, "force plate corners");
    io.value(d.plate_type, "force plate type");
    io.value(d.channel_data_type, "force plate channel data type");
    names_layout(io, d.channel_names, "force plate channel name");
  } else if constexpr (std::is_same_v<T, DeviceDescription>) {
    io.value(d.id, "device id");
    io.cstring(d.name, "device name");
    io.cstring(d.serial_number, "device serial number");
    io.value(d.device_type, "device type");
    io.value(d.channel_data_type, "device channel data type");
    names_layout(io, d.channel_names, "device channel name");
  } else if constexpr (std::is_same_v<T, CameraDescription>) {
    io.cstring(d.name, "camera name");
    io.value(d.position, "camera position");
    io.value(d.orientation, "camera orientation");
  } else if constexpr (std::is_same_v<T, AssetDescription>) {
    io.cstring(d.name, "asset name");
    io.value(d.type, "asset type");
    io.value(d.id, "asset id");
    list_layout(io, d.rigid_bodies, rigid_body_description_bytes(layout), false, "asset rigid body",
                [&](auto& body) { rigid_body_layout(io, body, layout); });
    list_layout(io, d.markers, kMarkerDescriptionBytes, false, "asset marker", [&](auto& marker) {
      io.cstring(marker.name, "asset marker name");
      io.value(marker.id, "asset marker id");
      io.value(marker.position, "asset marker position");
      io.value(marker.size, "asset marker size");
      io.value(marker.params, "asset marker params");
    });
  } else {
    static_assert(std::is_same_v<T, UnknownDescription>);  // handled by model_layout
  }
}

ModelDescription blank_description(int32_t type) {
  switch (type) {
    case 0: return MarkerSetDescription{};
    case 1: return RigidBodyDescription{};
    case 2: return SkeletonDescription{};
    case 3: return ForcePlateDescription{};
    case 4: return DeviceDescription{};
    case 5: return CameraDescription{};
    case 6: return AssetDescription{};
    default: return UnknownDescription{type};
  }
}

template <typename IO, typename Model>
void model_layout(IO& io, Model& model, const Layout& layout) {
  int32_t type = 0;
  if constexpr (!IO::kReading) {
    const auto* unknown = std::get_if<UnknownDescription>(&model);
    type = unknown ? unknown->type : int32_t(model.index());
    if (unknown && !std::holds_alternative<UnknownDescription>(blank_description(type))) {
      throw Error(fmt::format("NatNet unknown description of type {}: that type has a layout", type));
    }
  }
  const std::size_t type_offset = [&] {
    if constexpr (IO::kReading) return io.reader().offset();
    return std::size_t(0);
  }();
  io.value(type, "description type");
  if constexpr (IO::kReading) model = blank_description(type);

  if (std::holds_alternative<UnknownDescription>(model)) {
    auto& unknown = std::get<UnknownDescription>(model);
    if (!layout.byte_counts) {
      const auto message = fmt::format(
          "unknown model description type {}: before bitstream 4.1 descriptions carry no size to step over it", type);
      if constexpr (IO::kReading) io.reader().fail_at(type_offset, message);
      throw Error("NatNet " + message);
    }
    int32_t size = int32_t(unknown.bytes.size());
    io.value(size, "description size");
    if constexpr (IO::kReading) {
      if (size < 0) io.reader().fail_at(io.reader().offset() - 4, fmt::format("description size {} is negative", size));
    }
    io.bytes(unknown.bytes, std::size_t(size), "unknown description");
    return;
  }
  io.byte_counted(layout.byte_counts, "description",
                  [&] { std::visit([&](auto& description) { description_layout(io, description, layout); }, model); });
}

template <typename IO, typename Models>
void model_definitions_layout(IO& io, const Layout& layout, Models& models) {
  list_layout(io, models.models, 4 + (layout.byte_counts ? 4 : 0), false, "model description",
              [&](auto& model) { model_layout(io, model, layout); });
}

}  // namespace

void read_model_definitions(ByteReader& in, const Layout& layout, ModelDefinitions& models) {
  Reading io(in);
  model_definitions_layout(io, layout, models);
}

void write_model_definitions(ByteWriter& out, const Layout& layout, const ModelDefinitions& models) {
  Writing io(out);
  model_definitions_layout(io, layout, models);
}

}  // namespace facecap::formats::natnet::detail
