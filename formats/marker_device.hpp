#pragma once
// The facecap marker-device protocol (docs/usb-hid-protocol.md) as pure bytes <-> types:
// the info block a device describes itself with, the control block that starts and stops
// streaming, the chunks (USB bulk packets, HID input reports) a frame is cut into, their
// reassembly, and the frame body with its CRC. No I/O here; the usb and hid drivers move
// the bytes, tests and fuzzers call these directly.
//
// Everything is little-endian. Sizes read from a device are bounded before use: a frame
// body can never grow past the assembler's capacity, a marker count must match the body's
// length exactly, and no call here allocates after construction except the encoders.
#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace facecap::formats::device {

inline constexpr uint8_t kVersionMajor = 1;  // a device of another major version is refused
inline constexpr uint8_t kVersionMinor = 0;

// How a device is recognised (besides vendor/product id and serial).
inline constexpr uint8_t kUsbInterfaceClass = 0xFF;     // vendor specific
inline constexpr uint8_t kUsbInterfaceSubclass = 0x46;  // 'F'
inline constexpr uint8_t kUsbInterfaceProtocol = 0x01;
inline constexpr uint16_t kHidUsagePage = 0xFF46;       // vendor defined
inline constexpr uint16_t kHidUsage = 0x0001;

// USB vendor requests to the interface (wIndex = interface number).
inline constexpr uint8_t kRequestGetInfo = 0x01;  // device to host, the 32-byte info block
inline constexpr uint8_t kRequestControl = 0x02;  // host to device, the 8-byte control block
// HID report ids: feature 1 = info block, feature 2 = control block, input 3 = one chunk.
inline constexpr uint8_t kHidInfoReport = 1;
inline constexpr uint8_t kHidControlReport = 2;
inline constexpr uint8_t kHidChunkReport = 3;

enum class Units : uint8_t { kMillimetres = 0, kCentimetres = 1, kMetres = 2 };
// "mm", "cm", "m"; "" for a value outside the enum.
std::string_view units_name(Units units) noexcept;

// -- Info block: what the device is -----------------------------------------------------

inline constexpr std::size_t kInfoBytes = 32;
inline constexpr std::array<char, 4> kInfoMagic{'F', 'C', 'M', 'D'};
inline constexpr uint8_t kCapabilityRateSettable = 1u << 0;

struct DeviceInfo {
  uint8_t version_major = kVersionMajor;
  uint8_t version_minor = kVersionMinor;
  uint16_t marker_capacity = 0;  // markers per frame at most (ids 0 .. capacity-1)
  uint32_t rate_mhz = 0;         // nominal frame rate, millihertz
  uint32_t max_rate_mhz = 0;     // highest rate a control block may ask for
  Units units = Units::kMillimetres;
  uint8_t capabilities = 0;      // kCapability* bits
  uint16_t max_chunk_bytes = 0;  // largest chunk it sends, header included
  uint32_t clock_hz = 0;         // device timestamp ticks per second
  bool operator==(const DeviceInfo&) const = default;
};

std::array<uint8_t, kInfoBytes> encode_info(const DeviceInfo& info) noexcept;
// Throws Error naming `source` and the byte offset (size, magic, a major version other
// than kVersionMajor, units, zero capacity or chunk size under the header's). Not RT-safe.
DeviceInfo parse_info(std::span<const uint8_t> bytes, const std::string& source);

// -- Control block: start, stop, rate ---------------------------------------------------

inline constexpr std::size_t kControlBytes = 8;
enum class Command : uint8_t { kStop = 0, kStart = 1 };

struct Control {
  Command command = Command::kStop;
  uint32_t rate_mhz = 0;  // 0: the device's nominal rate
  bool operator==(const Control&) const = default;
};

std::array<uint8_t, kControlBytes> encode_control(const Control& control) noexcept;
// Throws Error naming `source` and the byte offset. Not RT-safe.
Control parse_control(std::span<const uint8_t> bytes, const std::string& source);

// -- Chunks and frames ------------------------------------------------------------------

inline constexpr std::size_t kChunkHeaderBytes = 8;
inline constexpr uint8_t kChunkSync = 0xFC;
inline constexpr uint8_t kChunkFirst = 1u << 0;
inline constexpr uint8_t kChunkLast = 1u << 1;
inline constexpr std::size_t kMaxChunksPerFrame = 256;  // the u8 chunk index

inline constexpr std::size_t kFrameHeaderBytes = 16;  // frame_no, device time, count, flags
inline constexpr std::size_t kMarkerBytes = 16;       // id, flags, x, y, z
inline constexpr std::size_t kCrcBytes = 4;
inline constexpr std::size_t kMaxMarkers = 4096;

// Marker flags on the wire.
inline constexpr uint16_t kMarkerOccluded = 1u << 0;    // not seen this frame: position meaningless
inline constexpr uint16_t kMarkerUnlabelled = 1u << 1;  // the id is only this frame's index
inline constexpr uint16_t kMarkerPredicted = 1u << 2;   // filled in by the device, not measured

struct DeviceMarker {
  uint16_t id = 0;
  uint16_t flags = 0;
  std::array<float, 3> position{};  // in the info block's units
  bool operator==(const DeviceMarker&) const = default;
};

struct DeviceFrame {
  uint32_t frame_no = 0;
  uint64_t device_time = 0;  // ticks of the info block's clock_hz
  uint16_t flags = 0;        // reserved: 0
  std::vector<DeviceMarker> markers;
  bool operator==(const DeviceFrame&) const = default;
};

// Bytes of the body of a frame with `markers` markers (CRC included).
constexpr std::size_t frame_body_bytes(std::size_t markers) noexcept {
  return kFrameHeaderBytes + markers * kMarkerBytes + kCrcBytes;
}

// CRC-32 (ISO-HDLC, as zlib's crc32) of `bytes`. RT-safe.
uint32_t crc32(std::span<const uint8_t> bytes) noexcept;

// What went wrong with a chunk or a frame body, for counting on the receive path (no text,
// no allocation there) and describing later.
enum class DeviceError : uint8_t {
  kNone,
  kBadSync,          // a chunk shorter than its header or not starting with kChunkSync
  kChunkOverrun,     // a chunk's payload length runs past the bytes received
  kOutOfSequence,    // a chunk not following the one before (lost packet): the frame is dropped
  kFrameTooLarge,    // the chunks of one frame exceed the capacity
  kShortFrame,       // a body too short for its header and CRC
  kBadMarkerCount,   // the marker count disagrees with the body's length or the capacity
  kBadCrc,           // the CRC does not match: the frame is dropped
};
std::string_view device_error_name(DeviceError error) noexcept;

struct DeviceParseResult {
  DeviceError error = DeviceError::kNone;
  std::size_t offset = 0;  // byte of the chunk or body where it was found
  bool ok() const noexcept { return error == DeviceError::kNone; }
};
// "bad CRC at byte 784" and the like, for logs and test messages. Not RT-safe.
std::string describe(const DeviceParseResult& result);

// Parses a whole frame body (CRC checked) into `out`, whose markers vector keeps its
// capacity: no allocation when it was reserved for max_markers. A marker count above
// max_markers is an error. RT-safe.
DeviceParseResult parse_frame_body(std::span<const uint8_t> body, std::size_t max_markers, DeviceFrame& out) noexcept;

// The body of `frame` (CRC appended). Not RT-safe.
std::vector<uint8_t> encode_frame_body(const DeviceFrame& frame);
// `frame` cut into chunks of at most chunk_bytes (header included) each. Throws Error when
// chunk_bytes leaves no room for payload or the frame needs more than kMaxChunksPerFrame.
// Not RT-safe.
std::vector<std::vector<uint8_t>> encode_frame_chunks(const DeviceFrame& frame, std::size_t chunk_bytes);

// Reassembles frame bodies from chunks, in the order they arrive. Sized once; push() and
// body() never allocate.
class FrameAssembler {
 public:
  enum class Status : uint8_t { kPending, kComplete, kDropped };
  struct Result {
    Status status = Status::kPending;
    DeviceParseResult error;  // for kDropped: why
    std::size_t used = 0;     // bytes of the input this chunk took (header + payload)
    bool abandoned = false;   // a frame in progress lost its last chunk and was given up
  };

  // Frames of up to max_body_bytes. Not RT-safe.
  explicit FrameAssembler(std::size_t max_body_bytes);

  // Takes the chunk at the start of `bytes` (a bulk transfer may hold several back to back;
  // a HID report's padding after the payload is ignored by the caller). kComplete: body()
  // holds a whole frame until the next push. kDropped: this chunk and any frame in progress
  // are discarded; `used` is then what to skip (all of `bytes` when the header is unreadable).
  // RT-safe.
  Result push(std::span<const uint8_t> bytes) noexcept;
  std::span<const uint8_t> body() const noexcept { return {buffer_.data(), size_}; }
  // Forgets a frame in progress (a device that went away). RT-safe.
  void reset() noexcept {
    size_ = 0;
    in_frame_ = false;
  }

 private:
  std::vector<uint8_t> buffer_;
  std::size_t size_ = 0;
  bool in_frame_ = false;
  uint16_t frame_tag_ = 0;
  uint8_t next_index_ = 0;
};

}  // namespace facecap::formats::device
