// NAT_FRAMEOFDATA, bitstreams 3.0 to 4.x, read and written by one layout (natnet_layout.hpp).
// Order and version conditions as in the NatNet SDK 4.3 PacketClient.cpp UnpackFrameData;
// the 3.0 layout also matches real Motive 2.1 frames byte for byte.
#include "formats/natnet_layout.hpp"

namespace facecap::formats::natnet::detail {
namespace {

// Smallest encoded size of each item, to bound counts before allocating.
constexpr std::size_t kPositionBytes = 12;
constexpr std::size_t kMarkerSetBytes = 1 + 4;  // empty name, no markers
constexpr std::size_t kRigidBodyBytes = 4 + 12 + 16 + 4 + 2;
constexpr std::size_t kSkeletonBytes = 4 + 4;
constexpr std::size_t kAssetBytes = 4 + 4 + 4;
constexpr std::size_t kLabelledMarkerBytes = 4 + 12 + 4 + 2 + 4;
constexpr std::size_t kAnalogBytes = 4 + 4;  // id, no channels
constexpr std::size_t kChannelBytes = 4;     // no samples
constexpr std::size_t kSampleBytes = 4;

template <typename IO, typename RigidBody>
void rigid_body_layout(IO& io, RigidBody& body) {
  io.value(body.id, "rigid body id");
  io.value(body.position, "rigid body position");
  io.value(body.rotation, "rigid body rotation");
  io.value(body.mean_error, "rigid body mean error");
  io.value(body.params, "rigid body params");
}

template <typename IO, typename Marker>
void labelled_marker_layout(IO& io, Marker& marker) {
  io.value(marker.id, "labelled marker id");
  io.value(marker.position, "labelled marker position");
  io.value(marker.size, "labelled marker size");
  io.value(marker.params, "labelled marker params");
  io.value(marker.residual, "labelled marker residual");
}

template <typename IO, typename Analog>
void analog_layout(IO& io, Analog& analog, std::string_view what) {
  io.value(analog.id, what);
  list_layout(io, analog.channels, kChannelBytes, false, what, [&](auto& samples) {
    list_layout(io, samples, kSampleBytes, false, what, [&](auto& sample) { io.value(sample, what); });
  });
}

template <typename IO, typename Frame>
void frame_layout(IO& io, const Layout& layout, Frame& frame) {
  const bool counted = layout.byte_counts;
  io.value(frame.frame_number, "frame number");
  list_layout(io, frame.marker_sets, kMarkerSetBytes, counted, "marker set", [&](auto& set) {
    io.cstring(set.name, "marker set name");
    list_layout(io, set.markers, kPositionBytes, false, "marker set marker",
                [&](auto& position) { io.value(position, "marker set marker position"); });
  });
  list_layout(io, frame.other_markers, kPositionBytes, counted, "other marker",
              [&](auto& position) { io.value(position, "other marker position"); });
  list_layout(io, frame.rigid_bodies, kRigidBodyBytes, counted, "rigid body",
              [&](auto& body) { rigid_body_layout(io, body); });
  list_layout(io, frame.skeletons, kSkeletonBytes, counted, "skeleton", [&](auto& skeleton) {
    io.value(skeleton.id, "skeleton id");
    list_layout(io, skeleton.bones, kRigidBodyBytes, false, "skeleton bone",
                [&](auto& bone) { rigid_body_layout(io, bone); });
  });
  if (layout.assets) {
    list_layout(io, frame.assets, kAssetBytes, counted, "asset", [&](auto& asset) {
      io.value(asset.id, "asset id");
      list_layout(io, asset.rigid_bodies, kRigidBodyBytes, false, "asset rigid body",
                  [&](auto& body) { rigid_body_layout(io, body); });
      list_layout(io, asset.markers, kLabelledMarkerBytes, false, "asset marker",
                  [&](auto& marker) { labelled_marker_layout(io, marker); });
    });
  }
  list_layout(io, frame.labelled_markers, kLabelledMarkerBytes, counted, "labelled marker",
              [&](auto& marker) { labelled_marker_layout(io, marker); });
  list_layout(io, frame.force_plates, kAnalogBytes, counted, "force plate",
              [&](auto& plate) { analog_layout(io, plate, "force plate"); });
  list_layout(io, frame.devices, kAnalogBytes, counted, "device",
              [&](auto& device) { analog_layout(io, device, "device"); });
  io.value(frame.timecode, "timecode");
  io.value(frame.timecode_subframe, "timecode subframe");
  io.value(frame.timestamp_s, "timestamp");
  io.value(frame.camera_mid_exposure, "camera mid-exposure timestamp");
  io.value(frame.camera_data_received, "camera data-received timestamp");
  io.value(frame.transmit, "transmit timestamp");
  if (layout.precision_timestamp) {
    io.value(frame.precision_timestamp_s, "precision timestamp seconds");
    io.value(frame.precision_timestamp_frac, "precision timestamp fraction");
  }
  io.value(frame.params, "frame params");
  int32_t end_of_data = 0;  // always 0 from Motive; its value is not checked
  io.value(end_of_data, "end-of-data tag");
}

}  // namespace

void read_frame_of_data(ByteReader& in, const Layout& layout, FrameOfData& frame) {
  frame = FrameOfData{};
  Reading io(in);
  frame_layout(io, layout, frame);
}

void write_frame_of_data(ByteWriter& out, const Layout& layout, const FrameOfData& frame) {
  Writing io(out);
  frame_layout(io, layout, frame);
}

}  // namespace facecap::formats::natnet::detail
