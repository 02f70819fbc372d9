#pragma once
// NatNet messages out of a packet capture's UDP datagrams (pcap.hpp), each parsed by
// natnet.hpp. Which layout the frames have comes from the session in the capture: a
// client's CONNECT asking for a bitstream, else the server's SERVERINFO, else the option
// (3.0, what Motive 2.x streams); a "Bitstream,M.m" NAT_REQUEST switches it from there on.
// The file is read by drivers/capture (libpcap); for tools and replays, not real-time safe.
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "core/enum_table.hpp"
#include "formats/natnet.hpp"
#include "formats/pcap.hpp"

namespace facecap::formats::natnet {

struct CapturedMessage {
  int64_t capture_time_ns = 0;
  IpAddress source, destination;
  uint16_t source_port = 0, destination_port = 0;
  Message message;
};

struct CaptureOptions {
  // The layout when the capture holds no CONNECT or SERVERINFO.
  Version default_bitstream = kBitstream30;
  // Try every UDP datagram as NatNet, not only those to or from ports 1510 and 1511.
  bool any_port = false;
};

enum class BitstreamSource : uint8_t { kOption, kServerInfo, kClientRequest };
inline constexpr EnumTable kBitstreamSources{std::array{
    EnumEntry<BitstreamSource>{BitstreamSource::kOption, "option",
                               "no session start in the capture: the default or --natnet-version"},
    EnumEntry<BitstreamSource>{BitstreamSource::kServerInfo, "server info",
                               "the NatNet version in the server's NAT_SERVERINFO"},
    EnumEntry<BitstreamSource>{BitstreamSource::kClientRequest, "client request",
                               "the bitstream a client's NAT_CONNECT asked for"},
}};

struct NatNetCapture {
  static constexpr std::size_t kMaxErrors = 10;

  std::vector<CapturedMessage> messages;  // in capture order
  Version bitstream;                      // the layout the session started with
  BitstreamSource bitstream_source = BitstreamSource::kOption;
  std::optional<ServerInfo> server_info;  // the first in the capture
  std::string file_format;                // "pcap", "pcapng"
  std::string link_type;                  // libpcap's name: "EN10MB", ...
  CaptureCounts records;                  // what the framing made of the capture's records
  std::size_t other_ports = 0;            // UDP datagrams neither to nor from 1510 or 1511
  std::size_t undecodable = 0;            // datagrams that did not parse as NatNet
  std::vector<std::string> errors;        // the first kMaxErrors parse errors, with record and byte
  // Set when the capture ends in a damaged record; what came before it is kept.
  std::optional<std::string> damage;
};

// True for datagrams to or from NatNet's command or data port (1510, 1511).
bool on_natnet_port(const UdpDatagram& datagram) noexcept;

// Parses `datagrams` (a capture's, in capture order) into capture.messages, choosing the
// session's bitstream; what does not parse is counted in capture.undecodable. `name`
// (the capture's) goes into the errors. The caller fills the facts of the file.
void decode_datagrams(const std::vector<UdpDatagram>& datagrams, const std::string& name, const CaptureOptions& options,
                      NatNetCapture& capture);

// Frames per second from the first and last frames' numbers and timestamps (dropped
// frames do not lower it); 0 with fewer than two frames or no time between them.
double frame_rate_hz(const NatNetCapture& capture);

}  // namespace facecap::formats::natnet
