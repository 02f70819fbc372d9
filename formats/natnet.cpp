// NatNet packets: header, session messages, and the dispatch to the frame and model layouts.
#include "formats/natnet.hpp"

#include <charconv>
#include <cstring>

#include "formats/natnet_layout.hpp"

namespace facecap::formats::natnet {

using detail::Layout;
using detail::Reading;
using detail::Writing;

std::string Version::to_string() const { return fmt::format("{}.{}.{}.{}", major, minor, build, revision); }

std::string Version::major_minor() const { return fmt::format("{}.{}", major, minor); }

std::optional<Version> parse_version(std::string_view text) {
  std::array<uint8_t, 4> parts{};
  std::size_t count = 0;
  while (true) {
    unsigned value = 0;
    const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
    if (error != std::errc{} || end == text.data() || value > 255 || count == parts.size()) return std::nullopt;
    parts[count++] = uint8_t(value);
    text.remove_prefix(std::size_t(end - text.data()));
    if (text.empty()) break;
    if (text.front() != '.' || text.size() == 1) return std::nullopt;
    text.remove_prefix(1);
  }
  return Version{parts[0], parts[1], parts[2], parts[3]};
}

bool is_supported_bitstream(Version bitstream) noexcept { return bitstream.major == 3 || bitstream.major == 4; }

std::string_view NameField::text() const noexcept {
  return std::string_view(bytes.data(), strnlen(bytes.data(), bytes.size()));
}

NameField NameField::from_text(std::string_view text) {
  if (text.size() >= kBytes || text.find('\0') != std::string_view::npos) {
    throw Error(fmt::format("NatNet name '{}' must be under {} bytes without NULs", text.substr(0, 64), kBytes));
  }
  NameField field;
  std::copy(text.begin(), text.end(), field.bytes.begin());
  return field;
}

std::optional<int32_t> RawPayload::as_int32() const noexcept {
  if (bytes.size() != 4) return std::nullopt;
  int32_t value;
  std::memcpy(&value, bytes.data(), 4);  // little-endian host, as byte_io.hpp asserts
  return value;
}

std::optional<float> RawPayload::as_float() const noexcept {
  if (bytes.size() != 4) return std::nullopt;
  float value;
  std::memcpy(&value, bytes.data(), 4);
  return value;
}

std::string_view RawPayload::as_text() const noexcept {
  return std::string_view(bytes.data(), strnlen(bytes.data(), bytes.size()));
}

std::string_view description_kind(const ModelDescription& description) noexcept {
  constexpr std::array<std::string_view, std::variant_size_v<ModelDescription>> kinds{
      "marker set", "rigid body", "skeleton", "force plate", "device", "camera", "asset", "unknown"};
  return kinds[description.index()];
}

std::string_view description_name(const ModelDescription& description) noexcept {
  if (const auto* plate = std::get_if<ForcePlateDescription>(&description)) return plate->serial_number;
  return std::visit(
      [](const auto& d) -> std::string_view {
        if constexpr (requires { d.name; }) return d.name;
        return {};
      },
      description);
}

Timecode decode_timecode(uint32_t timecode, uint32_t subframe) noexcept {
  return {int((timecode >> 24) & 0xffu), int((timecode >> 16) & 0xffu), int((timecode >> 8) & 0xffu),
          int(timecode & 0xffu), subframe};
}

uint32_t encode_timecode(const Timecode& t) noexcept {
  return (uint32_t(t.hours) & 0xffu) << 24 | (uint32_t(t.minutes) & 0xffu) << 16 | (uint32_t(t.seconds) & 0xffu) << 8 |
         (uint32_t(t.frames) & 0xffu);
}

std::string format_timecode(uint32_t timecode, uint32_t subframe) {
  const Timecode t = decode_timecode(timecode, subframe);
  return fmt::format("{:02}:{:02}:{:02}:{:02}.{}", t.hours, t.minutes, t.seconds, t.frames, t.subframe);
}

namespace {

// The one place that says which body a message id carries.
MessageBody blank_body(MessageId id) {
  switch (id) {
    case MessageId::kConnect:
    case MessageId::kDiscovery: return Connect{};
    case MessageId::kServerInfo: return ServerInfo{};
    case MessageId::kRequest:
    case MessageId::kMessageString: return Text{};
    case MessageId::kEchoRequest: return EchoRequest{};
    case MessageId::kEchoResponse: return EchoResponse{};
    case MessageId::kModelDef: return ModelDefinitions{};
    case MessageId::kFrameOfData: return FrameOfData{};
    default: return RawPayload{};
  }
}

constexpr std::size_t kConnectOptionsBytes = 1 + 4;

template <typename IO, typename V>
void version_layout(IO& io, V& version, std::string_view what) {
  io.value(version.major, what);
  io.value(version.minor, what);
  io.value(version.build, what);
  io.value(version.revision, what);
}

template <typename IO, typename S>
void sender_layout(IO& io, S& sender) {
  io.value(sender.name.bytes, "name");
  version_layout(io, sender.app_version, "application version");
  version_layout(io, sender.natnet_version, "NatNet version");
}

// The bytes left in the payload (reading) or to be written (writing) decide what follows
// the fixed part of CONNECT and SERVERINFO.
template <typename IO, typename Body>
void body_layout(IO& io, Body& body, Version bitstream) {
  using T = std::remove_const_t<Body>;
  if constexpr (std::is_same_v<T, RawPayload>) {
    std::size_t size = body.bytes.size();
    if constexpr (IO::kReading) size = io.reader().remaining();
    io.bytes(body.bytes, size, "payload");
  } else if constexpr (std::is_same_v<T, Connect>) {
    sender_layout(io, body.sender);
    if constexpr (IO::kReading) {
      if (io.reader().remaining() >= kConnectOptionsBytes) body.options.emplace();
    }
    if (body.options) {
      io.value(body.options->subscribed_data_only, "subscribed-data-only flag");
      version_layout(io, body.options->bitstream, "requested bitstream version");
    }
    std::size_t trailing = body.trailing_bytes.size();
    if constexpr (IO::kReading) trailing = io.reader().remaining();
    io.bytes(body.trailing_bytes, trailing, "trailing bytes");
  } else if constexpr (std::is_same_v<T, ServerInfo>) {
    sender_layout(io, body.sender);
    if constexpr (IO::kReading) {
      if (io.reader().remaining() > 0) body.connection.emplace();
    }
    if (body.connection) {
      io.value(body.connection->high_res_clock_hz, "high-resolution clock frequency");
      io.value(body.connection->data_port, "data port");
      io.value(body.connection->multicast, "multicast flag");
      io.value(body.connection->multicast_group, "multicast group");
    }
  } else if constexpr (std::is_same_v<T, Text>) {
    io.cstring(body.text, "text");
  } else if constexpr (std::is_same_v<T, EchoRequest>) {
    io.value(body.client_time, "client time");
  } else if constexpr (std::is_same_v<T, EchoResponse>) {
    io.value(body.client_time, "client time");
    io.value(body.server_time, "server time");
  } else {
    static_assert(std::is_same_v<T, ModelDefinitions> || std::is_same_v<T, FrameOfData>);
    const Layout layout(bitstream);
    if constexpr (std::is_same_v<T, FrameOfData>) {
      if constexpr (IO::kReading)
        detail::read_frame_of_data(io.reader(), layout, body);
      else
        detail::write_frame_of_data(io.writer(), layout, body);
    } else {
      if constexpr (IO::kReading)
        detail::read_model_definitions(io.reader(), layout, body);
      else
        detail::write_model_definitions(io.writer(), layout, body);
    }
  }
}

bool layout_depends_on_bitstream(MessageId id) noexcept {
  return id == MessageId::kFrameOfData || id == MessageId::kModelDef;
}

void require_supported(MessageId id, Version bitstream) {
  if (layout_depends_on_bitstream(id) && !is_supported_bitstream(bitstream)) {
    throw Error(fmt::format("NatNet {}: bitstream {} is not supported (3.x and 4.x are)", kMessageIds.name(id),
                            bitstream.major_minor()));
  }
}

}  // namespace

std::size_t body_index(MessageId id) noexcept { return blank_body(id).index(); }

MessageId peek_message_id(std::span<const char> datagram, const std::string& name) {
  ByteReader header(datagram, name);
  const uint16_t raw = header.u16("message id");
  const auto id = MessageId(raw);
  if (kMessageIds.name(id) == "?") header.fail_at(0, fmt::format("unknown NatNet message id {}", raw));
  return id;
}

Message parse_message(std::span<const char> datagram, Version bitstream, const std::string& name) {
  Message message;
  message.id = peek_message_id(datagram, name);
  ByteReader header(datagram, name);
  header.seek(2);
  const uint16_t payload_bytes = header.u16("payload size");
  if (payload_bytes > header.remaining()) {
    header.fail_at(2, fmt::format("{} header declares {} payload bytes, the datagram holds {}",
                                  kMessageIds.name(message.id), payload_bytes, header.remaining()));
  }
  require_supported(message.id, bitstream);
  ByteReader in(datagram.first(kHeaderBytes + payload_bytes), name);
  in.seek(kHeaderBytes);
  Reading io(in);
  message.body = blank_body(message.id);
  try {
    std::visit([&](auto& body) { body_layout(io, body, bitstream); }, message.body);
    if (in.remaining() != 0) {
      in.fail(fmt::format("{} bytes left in the {} payload after its last field", in.remaining(),
                          kMessageIds.name(message.id)));
    }
  } catch (const Error& e) {
    if (!layout_depends_on_bitstream(message.id)) throw;
    // Most such errors mean the wrong layout: say which one was used.
    throw Error(fmt::format("{} (read as bitstream {})", e.message(), bitstream.major_minor()), e.where());
  }
  return message;
}

std::vector<char> encode_message(const Message& message, Version bitstream) {
  if (message.body.index() != body_index(message.id)) {
    throw Error(fmt::format("NatNet {} cannot carry this kind of body", kMessageIds.name(message.id)));
  }
  require_supported(message.id, bitstream);
  std::vector<char> out;
  ByteWriter writer(out);
  writer.u16(uint16_t(message.id));
  writer.u16(0);  // payload size, patched below
  Writing io(writer);
  std::visit([&](const auto& body) { body_layout(io, body, bitstream); }, message.body);
  const std::size_t payload_bytes = out.size() - kHeaderBytes;
  if (payload_bytes > kMaxPayloadBytes) {
    throw Error(fmt::format("NatNet {} payload of {} bytes exceeds a packet's {}", kMessageIds.name(message.id),
                            payload_bytes, kMaxPayloadBytes));
  }
  writer.patch(2, uint16_t(payload_bytes));
  return out;
}

}  // namespace facecap::formats::natnet
