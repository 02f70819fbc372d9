#include "formats/natnet_capture.hpp"

#include <fmt/format.h>

#include "core/error.hpp"
#include "formats/natnet_request.hpp"

namespace facecap::formats::natnet {

bool on_natnet_port(const UdpDatagram& d) noexcept {
  for (const uint16_t port : {d.source_port, d.destination_port}) {
    if (port == kCommandPort || port == kDataPort) return true;
  }
  return false;
}

namespace {

std::string record_label(const std::string& name, const UdpDatagram& d) {
  return fmt::format("{} record {}", name, d.record + 1);
}

// The session's starting bitstream: a client's explicit request wins over the server's
// version, which wins over the option.
void choose_bitstream(const std::vector<UdpDatagram>& datagrams, const std::string& name, const CaptureOptions& options,
                      NatNetCapture& capture) {
  std::optional<Version> requested;
  for (const UdpDatagram& d : datagrams) {
    try {
      const MessageId id = peek_message_id(d.payload, name);
      if (id == MessageId::kConnect && !requested) {
        const auto connect = std::get<Connect>(parse_message(d.payload, options.default_bitstream, name).body);
        if (connect.options && connect.options->bitstream != Version{}) requested = connect.options->bitstream;
      } else if (id == MessageId::kServerInfo && !capture.server_info) {
        capture.server_info = std::get<ServerInfo>(parse_message(d.payload, options.default_bitstream, name).body);
      }
    } catch (const Error&) {
      // Counted when the datagram is parsed for real.
    }
  }
  if (requested) {
    capture.bitstream = *requested;
    capture.bitstream_source = BitstreamSource::kClientRequest;
  } else if (capture.server_info) {
    capture.bitstream = capture.server_info->sender.natnet_version;
    capture.bitstream_source = BitstreamSource::kServerInfo;
  } else {
    capture.bitstream = options.default_bitstream;
    capture.bitstream_source = BitstreamSource::kOption;
  }
}

// "Bitstream,3.1" asks a 4.x server for another layout.
std::optional<Version> requested_bitstream(const Message& message) {
  const auto* text = std::get_if<Text>(&message.body);
  if (message.id != MessageId::kRequest || !text) return std::nullopt;
  const auto request = parse_request(text->text);
  if (!request || request->kind != RequestKind::kSetBitstream || !is_supported_bitstream(request->bitstream))
    return std::nullopt;
  return request->bitstream;
}

}  // namespace

void decode_datagrams(const std::vector<UdpDatagram>& datagrams, const std::string& name, const CaptureOptions& options,
                      NatNetCapture& capture) {
  choose_bitstream(datagrams, name, options, capture);
  Version bitstream = capture.bitstream;
  capture.messages.reserve(datagrams.size());
  for (const UdpDatagram& d : datagrams) {
    try {
      Message message = parse_message(d.payload, bitstream, record_label(name, d));
      if (const auto version = requested_bitstream(message)) bitstream = *version;
      capture.messages.push_back(CapturedMessage{d.capture_time_ns, d.source, d.destination, d.source_port,
                                                 d.destination_port, std::move(message)});
    } catch (const Error& e) {
      ++capture.undecodable;
      if (capture.errors.size() < NatNetCapture::kMaxErrors) capture.errors.emplace_back(e.what());
    }
  }
}

double frame_rate_hz(const NatNetCapture& capture) {
  const FrameOfData* first = nullptr;
  const FrameOfData* last = nullptr;
  for (const CapturedMessage& m : capture.messages) {
    if (const auto* frame = std::get_if<FrameOfData>(&m.message.body)) {
      if (!first) first = frame;
      last = frame;
    }
  }
  if (!first) return 0.0;
  const double frames = double(last->frame_number) - double(first->frame_number);
  const double seconds = last->timestamp_s - first->timestamp_s;
  return frames > 0 && seconds > 0 ? frames / seconds : 0.0;
}

}  // namespace facecap::formats::natnet
