#pragma once
// OptiTrack NatNet messages (Motive's streaming protocol) as pure bytes <-> types: one UDP
// payload in, one typed message out, and back. No sockets here; the NatNet driver and
// `facecap natnet-serve` do the I/O, the capture reader (natnet_capture.hpp) feeds replays.
//
// A packet is `u16 message id | u16 payload bytes | payload`, little-endian and packed.
// Most payloads have one layout; MODELDEF and FRAMEOFDATA change with the bitstream
// version, which the caller passes in: the server's NatNet version from SERVERINFO, or
// the version a client asked for. Layouts checked against the NatNet SDK's PacketClient.cpp
// (3.1, 4.3) and NatNetClient.py (3.1, 4.3), and against real Motive 2.1 traffic.
// docs/natnet.md describes what is read, for users.
//
// Parsing never trusts a count: each is bounded by the bytes left before anything is
// allocated, and every failure is an Error naming the byte offset (from the start of the
// packet, header included) and the field. Nothing here is real-time safe (allocation).
#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

#include "core/enum_table.hpp"

namespace facecap::formats::natnet {

inline constexpr uint16_t kCommandPort = 1510;  // server side: requests and replies
inline constexpr uint16_t kDataPort = 1511;     // frames (multicast, or 3.x-style unicast)
inline constexpr std::array<uint8_t, 4> kDefaultMulticastGroup{239, 255, 42, 99};
inline constexpr std::size_t kHeaderBytes = 4;
inline constexpr std::size_t kMaxPayloadBytes = 65535;  // the u16 size field

enum class MessageId : uint16_t {
  kConnect = 0,
  kServerInfo = 1,
  kRequest = 2,
  kResponse = 3,
  kRequestModelDef = 4,
  kModelDef = 5,
  kRequestFrameOfData = 6,
  kFrameOfData = 7,
  kMessageString = 8,
  kDisconnect = 9,
  kKeepAlive = 10,
  kDisconnectByTimeout = 11,
  kEchoRequest = 12,
  kEchoResponse = 13,
  kDiscovery = 14,
  kUnrecognizedRequest = 100,  // decimal, as NatNetTypes.h and real Motive traffic have it
};

// Names as in the SDK's NatNetTypes.h. (Rows name their type: clang 14, which builds the
// fuzz targets, cannot deduce it for aggregates.)
inline constexpr EnumTable kMessageIds{std::array{
    EnumEntry<MessageId>{MessageId::kConnect, "NAT_CONNECT", "client asks a server for its SERVERINFO"},
    EnumEntry<MessageId>{MessageId::kServerInfo, "NAT_SERVERINFO",
                         "server name, versions, clock rate, data port, multicast group"},
    EnumEntry<MessageId>{MessageId::kRequest, "NAT_REQUEST",
                         "text command to the server (\"FrameRate\", \"Bitstream,3.1\")"},
    EnumEntry<MessageId>{MessageId::kResponse, "NAT_RESPONSE", "reply to a NAT_REQUEST: a 4-byte value or text"},
    EnumEntry<MessageId>{MessageId::kRequestModelDef, "NAT_REQUEST_MODELDEF", "client asks for the model definitions"},
    EnumEntry<MessageId>{MessageId::kModelDef, "NAT_MODELDEF",
                         "marker sets, rigid bodies, skeletons, force plates, devices, cameras, assets"},
    EnumEntry<MessageId>{MessageId::kRequestFrameOfData, "NAT_REQUEST_FRAMEOFDATA",
                         "client asks for the current frame"},
    EnumEntry<MessageId>{MessageId::kFrameOfData, "NAT_FRAMEOFDATA", "one frame of motion-capture data"},
    EnumEntry<MessageId>{MessageId::kMessageString, "NAT_MESSAGESTRING", "text message"},
    EnumEntry<MessageId>{MessageId::kDisconnect, "NAT_DISCONNECT", "client leaves"},
    EnumEntry<MessageId>{MessageId::kKeepAlive, "NAT_KEEPALIVE", "unicast client is still listening"},
    EnumEntry<MessageId>{MessageId::kDisconnectByTimeout, "NAT_DISCONNECTBYTIMEOUT", "server dropped a silent client"},
    EnumEntry<MessageId>{MessageId::kEchoRequest, "NAT_ECHOREQUEST", "clock synchronisation: client time"},
    EnumEntry<MessageId>{MessageId::kEchoResponse, "NAT_ECHORESPONSE",
                         "clock synchronisation: client time echoed, server time"},
    EnumEntry<MessageId>{MessageId::kDiscovery, "NAT_DISCOVERY", "broadcast search for servers"},
    EnumEntry<MessageId>{MessageId::kUnrecognizedRequest, "NAT_UNRECOGNIZED_REQUEST",
                         "server did not understand a request"},
}};

// major.minor.build.revision, one byte each as on the wire.
struct Version {
  uint8_t major = 0, minor = 0, build = 0, revision = 0;
  friend constexpr auto operator<=>(const Version&, const Version&) = default;
  std::string to_string() const;    // "2.1.0.0"
  std::string major_minor() const;  // "3.0"
};
inline constexpr Version kBitstream30{3, 0};
inline constexpr Version kBitstream31{3, 1};
inline constexpr Version kBitstream40{4, 0};
inline constexpr Version kBitstream41{4, 1};
inline constexpr Version kBitstream42{4, 2};

// "3.0", "4.1", "2.1.0.0" (1 to 4 numbers of 0..255); nullopt otherwise.
std::optional<Version> parse_version(std::string_view text);
// Bitstreams whose MODELDEF and FRAMEOFDATA layouts this code reads and writes: 3.x and 4.x.
bool is_supported_bitstream(Version bitstream) noexcept;

using Position = std::array<float, 3>;    // x y z, metres in Motive's streaming frame
using Quaternion = std::array<float, 4>;  // qx qy qz qw

// A fixed 256-byte, NUL-terminated name field (CONNECT, SERVERINFO). Motive sends stale
// memory after the NUL; the whole field is kept so that messages re-encode byte for byte.
struct NameField {
  static constexpr std::size_t kBytes = 256;
  std::array<char, kBytes> bytes{};
  // Up to the first NUL.
  std::string_view text() const noexcept;
  // Zero-padded; throws Error when the text has 256 bytes or more, or a NUL.
  static NameField from_text(std::string_view text);
  bool operator==(const NameField&) const = default;
};

// -- Session messages ---------------------------------------------------------------

struct Sender {
  NameField name;
  Version app_version;
  Version natnet_version;
  bool operator==(const Sender&) const = default;
};

// What a 4.x client appends to its NAT_CONNECT.
struct ConnectOptions {
  bool subscribed_data_only = false;
  Version bitstream;  // 0.0.0.0: the server's newest
  bool operator==(const ConnectOptions&) const = default;
};

// NAT_CONNECT and NAT_DISCOVERY. The SDK's Python client pads its CONNECT beyond the
// options (kept in trailing_bytes so the packet re-encodes as received).
struct Connect {
  Sender sender;
  std::optional<ConnectOptions> options;
  std::string trailing_bytes;
  bool operator==(const Connect&) const = default;
};

// The part of NAT_SERVERINFO that exists from NatNet 3.0.
struct ServerConnection {
  uint64_t high_res_clock_hz = 0;  // ticks per second of the frames' camera and transmit stamps
  uint16_t data_port = kDataPort;
  bool multicast = false;
  std::array<uint8_t, 4> multicast_group{};
  bool operator==(const ServerConnection&) const = default;
};

// NAT_SERVERINFO.
struct ServerInfo {
  Sender sender;
  std::optional<ServerConnection> connection;
  bool operator==(const ServerInfo&) const = default;
};

// NAT_REQUEST and NAT_MESSAGESTRING: NUL-terminated text filling the payload.
struct Text {
  std::string text;
  bool operator==(const Text&) const = default;
};

// NAT_RESPONSE (4 bytes for numeric replies, else text), NAT_UNRECOGNIZED_REQUEST, and the
// payloads of messages that carry none (NAT_REQUEST_MODELDEF, NAT_KEEPALIVE, ...; empty).
struct RawPayload {
  std::string bytes;
  // The reply as the 4-byte little-endian integer (status codes, "AnalogSamplesPerMocapFrame").
  std::optional<int32_t> as_int32() const noexcept;
  // The reply as a 4-byte float ("FrameRate").
  std::optional<float> as_float() const noexcept;
  // Up to the first NUL.
  std::string_view as_text() const noexcept;
  bool operator==(const RawPayload&) const = default;
};

// NAT_ECHOREQUEST / NAT_ECHORESPONSE, for clock synchronisation.
struct EchoRequest {
  uint64_t client_time = 0;
  bool operator==(const EchoRequest&) const = default;
};
struct EchoResponse {
  uint64_t client_time = 0;  // as the request sent it
  uint64_t server_time = 0;  // server high-resolution clock ticks
  bool operator==(const EchoResponse&) const = default;
};

// -- NAT_MODELDEF -------------------------------------------------------------------

struct MarkerSetDescription {
  std::string name;
  std::vector<std::string> marker_names;
  bool operator==(const MarkerSetDescription&) const = default;
};

struct RigidBodyMarkerDescription {
  Position offset{};         // from the rigid body's origin
  int32_t active_label = 0;  // required active-marker label, 0 for passive markers
  std::string name;          // bitstream 4.0+
  bool operator==(const RigidBodyMarkerDescription&) const = default;
};

struct RigidBodyDescription {
  std::string name;
  int32_t id = 0;
  int32_t parent_id = -1;
  Position offset{};                // from the parent
  Quaternion rotation{0, 0, 0, 1};  // from the parent; bitstream 4.2+
  std::vector<RigidBodyMarkerDescription> markers;
  bool operator==(const RigidBodyDescription&) const = default;
};

struct SkeletonDescription {
  std::string name;
  int32_t id = 0;
  std::vector<RigidBodyDescription> bones;
  bool operator==(const SkeletonDescription&) const = default;
};

struct ForcePlateDescription {
  int32_t id = 0;
  std::string serial_number;
  float width = 0, length = 0;
  Position origin{};
  std::array<float, 144> calibration{};  // 12 x 12, row-major
  std::array<float, 12> corners{};       // 4 corners x (x y z)
  int32_t plate_type = 0;
  int32_t channel_data_type = 0;
  std::vector<std::string> channel_names;
  bool operator==(const ForcePlateDescription&) const = default;
};

struct DeviceDescription {
  int32_t id = 0;
  std::string name;
  std::string serial_number;
  int32_t device_type = 0;
  int32_t channel_data_type = 0;
  std::vector<std::string> channel_names;
  bool operator==(const DeviceDescription&) const = default;
};

struct CameraDescription {
  std::string name;
  Position position{};
  Quaternion orientation{0, 0, 0, 1};
  bool operator==(const CameraDescription&) const = default;
};

struct MarkerDescription {  // a marker of an asset
  std::string name;
  int32_t id = 0;
  Position position{};
  float size = 0;
  int16_t params = 0;
  bool operator==(const MarkerDescription&) const = default;
};

struct AssetDescription {  // bitstream 4.1+ (Motive 3.1 trained marker sets)
  std::string name;
  int32_t type = 0;  // 1: trained marker set
  int32_t id = 0;
  std::vector<RigidBodyDescription> rigid_bodies;
  std::vector<MarkerDescription> markers;
  bool operator==(const AssetDescription&) const = default;
};

// A description of a type this code does not know. Only bitstream 4.1+ states each
// description's size, so only there can one be stepped over (and re-encoded as received).
struct UnknownDescription {
  int32_t type = 0;
  std::string bytes;
  bool operator==(const UnknownDescription&) const = default;
};

// The variant's index is the wire's description type (0..6) for all but UnknownDescription.
using ModelDescription =
    std::variant<MarkerSetDescription, RigidBodyDescription, SkeletonDescription, ForcePlateDescription,
                 DeviceDescription, CameraDescription, AssetDescription, UnknownDescription>;
// "marker set", "rigid body", ..., "unknown".
std::string_view description_kind(const ModelDescription& description) noexcept;
// The name a description carries (force plates: their serial number), "" for unknown ones.
std::string_view description_name(const ModelDescription& description) noexcept;

struct ModelDefinitions {
  std::vector<ModelDescription> models;
  bool operator==(const ModelDefinitions&) const = default;
};

// -- NAT_FRAMEOFDATA ----------------------------------------------------------------

struct MarkerSetData {
  std::string name;
  std::vector<Position> markers;
  bool operator==(const MarkerSetData&) const = default;
};

struct RigidBodyData {
  int32_t id = 0;
  Position position{};
  Quaternion rotation{0, 0, 0, 1};
  float mean_error = 0;  // mean marker error, metres
  int16_t params = 0;
  bool tracking_valid() const noexcept { return (params & 0x01) != 0; }
  bool operator==(const RigidBodyData&) const = default;
};

struct SkeletonData {
  int32_t id = 0;
  std::vector<RigidBodyData> bones;  // bone ids are skeleton id << 16 | bone id
  bool operator==(const SkeletonData&) const = default;
};

// Labelled markers (and asset markers) flags, as the SDK names them.
enum class LabelledMarkerFlag : int16_t {
  kOccluded = 0x01,          // not seen this frame
  kPointCloudSolved = 0x02,  // position from the point cloud
  kModelSolved = 0x04,       // position from the model (asset) solve
  kHasModel = 0x08,          // belongs to an asset in the stream
  kUnlabelled = 0x10,        // no asset, but a point-cloud id
  kActive = 0x20,            // an actively labelled LED marker
};

struct LabelledMarker {
  int32_t id = 0;  // model id << 16 | marker id (passive markers of an asset), else point-cloud or active id
  Position position{};
  float size = 0;      // metres
  int16_t params = 0;  // LabelledMarkerFlag bits
  float residual = 0;  // metres (the SDK prints it x 1000 as mm)
  uint16_t model_id() const noexcept { return uint16_t(uint32_t(id) >> 16); }
  uint16_t marker_id() const noexcept { return uint16_t(uint32_t(id) & 0xffffu); }
  bool has(LabelledMarkerFlag flag) const noexcept { return (params & int16_t(flag)) != 0; }
  bool operator==(const LabelledMarker&) const = default;
};

struct AssetData {  // bitstream 4.1+
  int32_t id = 0;
  std::vector<RigidBodyData> rigid_bodies;
  std::vector<LabelledMarker> markers;
  bool operator==(const AssetData&) const = default;
};

// Force plates and other devices (analog channels) share one layout: per channel, the
// samples taken during this mocap frame.
struct AnalogData {
  int32_t id = 0;
  std::vector<std::vector<float>> channels;
  bool operator==(const AnalogData&) const = default;
};

struct FrameOfData {
  int32_t frame_number = 0;
  std::vector<MarkerSetData> marker_sets;
  std::vector<Position> other_markers;  // legacy unlabelled ("other") markers
  std::vector<RigidBodyData> rigid_bodies;
  std::vector<SkeletonData> skeletons;
  std::vector<AssetData> assets;  // bitstream 4.1+
  std::vector<LabelledMarker> labelled_markers;
  std::vector<AnalogData> force_plates;
  std::vector<AnalogData> devices;
  uint32_t timecode = 0;  // SMPTE: hours << 24 | minutes << 16 | seconds << 8 | frames
  uint32_t timecode_subframe = 0;
  double timestamp_s = 0;  // server time since Motive started
  // High-resolution clock ticks (ServerConnection::high_res_clock_hz per second).
  uint64_t camera_mid_exposure = 0;
  uint64_t camera_data_received = 0;
  uint64_t transmit = 0;
  uint32_t precision_timestamp_s = 0;     // bitstream 4.1+, e.g. PTP time
  uint32_t precision_timestamp_frac = 0;  // bitstream 4.1+, fractional part
  int16_t params = 0;                     // 0x01 recording, 0x02 tracked models changed
  bool recording() const noexcept { return (params & 0x01) != 0; }
  bool models_changed() const noexcept { return (params & 0x02) != 0; }
  bool operator==(const FrameOfData&) const = default;
};

struct Timecode {
  int hours = 0, minutes = 0, seconds = 0, frames = 0;
  uint32_t subframe = 0;
};
Timecode decode_timecode(uint32_t timecode, uint32_t subframe) noexcept;
// The packed SMPTE field of `t` (each part kept to its byte); its subframe travels apart.
uint32_t encode_timecode(const Timecode& t) noexcept;
// "HH:MM:SS:FF.S", as the SDK samples print it.
std::string format_timecode(uint32_t timecode, uint32_t subframe);

// -- Messages -----------------------------------------------------------------------

using MessageBody =
    std::variant<RawPayload, Connect, ServerInfo, Text, EchoRequest, EchoResponse, ModelDefinitions, FrameOfData>;

struct Message {
  MessageId id = MessageId::kKeepAlive;
  MessageBody body;
  bool operator==(const Message&) const = default;
};

// The body type each message id carries (NAT_CONNECT -> Connect, ...); a Message whose body
// is of another type does not encode.
std::size_t body_index(MessageId id) noexcept;

// The message id of a datagram, without parsing the payload; throws Error when the
// datagram is shorter than a header or the id is not one of MessageId's.
MessageId peek_message_id(std::span<const char> datagram, const std::string& name);

// Parses one UDP payload. `bitstream` (is_supported_bitstream) selects the NAT_MODELDEF and
// NAT_FRAMEOFDATA layouts. Bytes after the declared payload are ignored (the SDK's Python
// client appends a NUL to empty requests); bytes left inside it after the message are an
// error, as they mean a wrong bitstream version. `name` labels errors.
Message parse_message(std::span<const char> datagram, Version bitstream, const std::string& name);

// One packet, header included. Fields the bitstream lacks are not written (a 4.1 frame's
// assets at 3.0, rigid-body marker names before 4.0, ...). Throws Error when the message
// does not fit a packet (payload over 65535 bytes, a count over 2^31, a name with a NUL).
std::vector<char> encode_message(const Message& message, Version bitstream);

}  // namespace facecap::formats::natnet
