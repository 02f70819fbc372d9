#pragma once
// facecap inspect on a pcap/pcapng capture of NatNet traffic (docs/natnet.md).
#include <filesystem>

#include <nlohmann/json.hpp>

#include "formats/natnet_capture.hpp"

namespace facecap::tools {

// {"frames", "natnet_version", "rate_hz"} and, with_frames, "frame_list": per frame of
// data its number, timecode, timestamp, labelled markers, rigid bodies and marker sets.
nlohmann::json capture_json(const formats::natnet::NatNetCapture& capture, bool with_frames);

// Messages by kind, frames, rate, bitstream and where it came from, model names, and
// what was skipped, for a person.
void print_capture(const std::filesystem::path& path, const formats::natnet::NatNetCapture& capture);

}  // namespace facecap::tools
