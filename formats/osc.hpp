#pragma once
// OSC 1.0 (Open Sound Control) packets as bytes: messages whose arguments are int32,
// float32 and strings, and bundles of them. Everything big-endian, every string and
// every part a multiple of 4 bytes long (OSC-strings end in 1 to 4 NULs). The VMC
// protocol (docs/outputs.md) is OSC over UDP.
#include <cstddef>
#include <cstdint>
#include <string_view>
#include <vector>

#include "formats/byte_io.hpp"

namespace facecap::formats::osc {

// The OSC time tag 1: "immediately" (NTP seconds 0, fraction 1).
inline constexpr uint64_t kImmediately = 1;

// Appends one OSC packet to a byte buffer: a message, or a bundle of messages written
// between begin_bundle() and end_bundle(). Each argument call must follow the type tags
// given to begin_message() ('i', 'f', 's'); a mismatch, a string holding a NUL or an
// unfinished message throw Error. Not RT-safe (appends).
//
//   OscWriter osc(bytes);
//   osc.begin_bundle();
//   osc.begin_message("/VMC/Ext/Blend/Val", "sf");
//   osc.string("JawOpen");
//   const std::size_t at = osc.float32(0.5f);  // patch_float32(bytes, at, w) later
//   osc.end_message();
//   osc.end_bundle();
class OscWriter {
 public:
  explicit OscWriter(std::vector<char>& out) : out_(out), writer_(out, ByteOrder::kBig) {}

  void begin_bundle(uint64_t timetag = kImmediately);
  void end_bundle();
  // `types` without the leading comma: "sf" for a string and a float.
  void begin_message(std::string_view address, std::string_view types);
  // Each returns the offset of the argument's value in the buffer.
  std::size_t int32(int32_t value);
  std::size_t float32(float value);
  std::size_t string(std::string_view value);
  void end_message();

 private:
  void next_argument(char type);
  void put_string(std::string_view value);

  std::vector<char>& out_;
  ByteWriter writer_;
  std::string_view types_;      // of the open message
  std::size_t next_type_ = 0;   // index into types_ of the next argument
  bool in_message_ = false;
  bool in_bundle_ = false;
  std::size_t element_start_ = 0;  // of the open bundle element's size field
};

// Overwrites a float32 argument written earlier at `offset` (OscWriter's return value):
// a packet encoded once and refreshed per frame. RT-safe.
void patch_float32(std::vector<char>& packet, std::size_t offset, float value) noexcept;

// Bytes an OSC-string of `text` takes: the text, a NUL, padding to a multiple of 4.
constexpr std::size_t string_size(std::string_view text) noexcept { return (text.size() / 4 + 1) * 4; }

}  // namespace facecap::formats::osc
