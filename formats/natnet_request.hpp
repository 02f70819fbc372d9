#pragma once
// The text commands of NAT_REQUEST ("FrameRate", "Bitstream", "Bitstream,3.1", ...) as
// types: what `facecap natnet-serve` answers, what the driver asks, and what the capture
// reader follows. Motive's command names are matched without regard to case or the spaces
// around them, as NatNet clients write them in several spellings. Pure text; no I/O.
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include "core/enum_table.hpp"
#include "formats/natnet.hpp"

namespace facecap::formats::natnet {

enum class RequestKind : uint8_t {
  kFrameRate,                   // "FrameRate": NAT_RESPONSE with the rate as a 4-byte float
  kBitstreamQuery,              // "Bitstream": NAT_RESPONSE text "Bitstream,M.m"
  kSetBitstream,                // "Bitstream,M.m": stream that layout from now on (4.x servers)
  kAnalogSamplesPerMocapFrame,  // "AnalogSamplesPerMocapFrame": NAT_RESPONSE with a 4-byte integer
};
inline constexpr EnumTable kRequestKinds{std::array{
    EnumEntry<RequestKind>{RequestKind::kFrameRate, "FrameRate", "the frame rate, as a float"},
    EnumEntry<RequestKind>{RequestKind::kBitstreamQuery, "Bitstream", "the bitstream streamed now, as text"},
    EnumEntry<RequestKind>{RequestKind::kSetBitstream, "Bitstream,M.m", "stream another bitstream"},
    EnumEntry<RequestKind>{RequestKind::kAnalogSamplesPerMocapFrame, "AnalogSamplesPerMocapFrame",
                           "analog samples per frame, as an integer"},
}};

struct Request {
  RequestKind kind = RequestKind::kFrameRate;
  Version bitstream;  // kSetBitstream: the major.minor asked for (any; is_supported_bitstream says if it can be)
  bool operator==(const Request&) const = default;
};

// A request this code knows, or nullopt (the server answers NAT_UNRECOGNIZED_REQUEST).
// "Bitstream,x" with x not a version is unknown, not an error.
std::optional<Request> parse_request(std::string_view text);
// The request's text as a client sends it: "FrameRate", "Bitstream,3.1".
std::string request_text(const Request& request);

// The reply to "Bitstream": "Bitstream,4.1" (major.minor); and back, nullopt unless the
// text is such a reply.
std::string bitstream_reply(Version bitstream);
std::optional<Version> parse_bitstream_reply(std::string_view text);

// NAT_RESPONSE status codes for "Bitstream,M.m", as a 4-byte integer.
inline constexpr int32_t kRequestDone = 0;
inline constexpr int32_t kRequestRefused = 1;

}  // namespace facecap::formats::natnet
