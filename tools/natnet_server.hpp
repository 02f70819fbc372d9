#pragma once
// `facecap natnet-serve`: a NatNet server that streams a marker take as Motive does, for
// tests, for renderers and for the box without Motive. What it sends is built with the
// formats writer (formats/natnet.hpp): NAT_SERVERINFO, NAT_MODELDEF (each marker set with
// a model of its name owning its labelled markers: a rigid body before bitstream 4.1, a
// trained-marker-set asset from 4.1), and NAT_FRAMEOFDATA at a fixed rate with marker set
// data, labelled markers (occluded ones at their last position, flagged), timecode and the
// three high-resolution stamps (the clock is CLOCK_MONOTONIC, 1 GHz).
//
// Streaming: multicast to a group out of one interface; or unicast to each connected
// client, either to the address its NAT_CONNECT came from (4.x servers; clients keep
// themselves alive) or to its host's data port (3.x style). Requests answered: NAT_CONNECT,
// NAT_DISCOVERY, NAT_REQUEST_MODELDEF, NAT_REQUEST_FRAMEOFDATA, NAT_ECHOREQUEST,
// NAT_KEEPALIVE, NAT_DISCONNECT, and the NAT_REQUEST texts of formats/natnet_request.hpp
// ("FrameRate", "Bitstream", "Bitstream,M.m" (unicast only: a multicast stream is one for
// all)); anything else gets NAT_UNRECOGNIZED_REQUEST or nothing. For robustness tests it
// can fall silent for a while and restart (frame numbers from 1, clients forgotten, models
// changed). Nothing here is real-time code.
#include <cstdint>
#include <map>
#include <optional>
#include <random>
#include <span>
#include <string>
#include <vector>

#include "drivers/natnet/udp_socket.hpp"
#include "formats/natnet.hpp"
#include "formats/take.hpp"

namespace facecap::tools {

enum class ServeMode : uint8_t { kMulticast, kUnicast, kUnicastDataPort };
inline constexpr EnumTable kServeModes{std::array{
    EnumEntry{ServeMode::kMulticast, "multicast", "frames to the multicast group"},
    EnumEntry{ServeMode::kUnicast, "unicast", "frames to each client's command socket (NatNet 4.x servers)"},
    EnumEntry{ServeMode::kUnicastDataPort, "unicast-data-port",
              "frames to each client's host at the data port (NatNet 3.x style)"},
}};

// A marker set of the stream: the take's labels beginning with `prefix`, named without it.
struct ServedMarkerSet {
  std::string name;
  std::string prefix;  // "": every label
};

struct ServeOptions {
  double rate_hz = 0.0;  // 0: the take's rate
  bool loop = false;
  std::string address = "0.0.0.0";  // the command socket's
  uint16_t command_port = formats::natnet::kCommandPort;
  uint16_t data_port = formats::natnet::kDataPort;
  ServeMode mode = ServeMode::kMulticast;
  std::string multicast_group = "239.255.42.99";
  std::string interface;  // multicast goes out of it ("": the system's choice)
  int ttl = 1;
  formats::natnet::Version bitstream = formats::natnet::kBitstream41;
  std::vector<ServedMarkerSet> marker_sets;  // empty: one set, named "Face", of every label
  bool unlabelled = false;           // every marker as an unlabelled point (no marker sets)
  double exposure_latency_ms = 0.0;  // mid-exposure stamped this long before a frame is due
  double seconds = 0.0;              // stop after this long; 0: at the take's end (or never, looping)
  double silence_at_s = 0.0, silence_for_s = 0.0;  // send and answer nothing in [at, at + for) (at 0: on SIGUSR2)
  double restart_at_s = 0.0;         // restart at this time (0: never)
  int32_t first_frame = 1;           // the first frame number (Motive's count from its start)
  double garbage_rate = 0.0;         // bad datagrams a second, sent where the frames go (robustness tests)
};

// One datagram to send.
struct Outgoing {
  drivers::natnet::Endpoint to;
  std::vector<char> bytes;
};

struct ServeCounts {
  uint64_t frames = 0;         // frame numbers streamed
  uint64_t packets = 0;        // frame datagrams sent (one per client when unicast)
  uint64_t requests = 0;       // datagrams answered
  uint64_t bad_requests = 0;   // datagrams that did not parse
  uint64_t late_frames = 0;    // frame times skipped to get back on schedule
  uint64_t garbage = 0;        // bad datagrams sent (garbage_rate)
};

class NatNetServer {
 public:
  static constexpr std::size_t kMaxClients = 64;
  static constexpr int64_t kClientTimeoutNs = 5'000'000'000;  // unicast clients must keep alive

  // Checks the options against the take (units, marker sets, bitstream). Throws Error.
  NatNetServer(ServeOptions options, formats::MarkerTake take);

  // The replies to one datagram from `from` at now_ns (CLOCK_MONOTONIC), and what it does
  // to the client list. Never throws: a datagram that does not parse is counted.
  std::vector<Outgoing> answer(std::span<const char> datagram, const drivers::natnet::Endpoint& from, int64_t now_ns);
  // The datagrams of the next frame, due at due_ns, sent at now_ns.
  std::vector<Outgoing> next_frame(int64_t due_ns, int64_t now_ns);
  // Restart: frame numbers from 1, clients forgotten, "models changed" on the next frames.
  void restart();
  // `count` bad datagrams to where frames go, in turn: random bytes, a frame cut short of
  // what its header says, a packet with bytes beyond what its header says, and a frame
  // whose header is right but whose first count is not.
  std::vector<Outgoing> garbage(std::size_t count);

  // Streams until the take ends (not looping), options.seconds pass, or SIGINT/SIGTERM;
  // SIGUSR1 restarts it now and SIGUSR2 silences it now for options.silence_for_s (tests
  // time these after their client is running). Prints what it does to stdout. Returns the exit status. Throws Error for socket setup.
  int run();

  const ServeCounts& counts() const noexcept { return counts_; }
  double rate_hz() const noexcept { return rate_hz_; }
  std::size_t clients() const noexcept { return clients_.size(); }
  const std::vector<std::string>& set_names() const noexcept { return set_names_; }
  formats::natnet::ModelDefinitions models(formats::natnet::Version bitstream) const;
  formats::natnet::ServerInfo server_info() const;

 private:
  struct Client {
    formats::natnet::Version bitstream;
    int64_t last_seen_ns = 0;
  };
  formats::natnet::FrameOfData frame_of_data(formats::natnet::Version bitstream, int64_t due_ns, int64_t now_ns) const;
  formats::natnet::Version bitstream_of(const drivers::natnet::Endpoint& client) const;
  void reply(std::vector<Outgoing>& out, const drivers::natnet::Endpoint& to, formats::natnet::MessageId id,
             formats::natnet::MessageBody body, formats::natnet::Version bitstream) const;

  ServeOptions options_;
  formats::MarkerTake take_;
  double rate_hz_ = 0.0;
  double metres_per_unit_ = 0.001;
  uint32_t group_ = 0;
  std::vector<std::string> set_names_;
  std::vector<std::vector<std::size_t>> set_slots_;      // per set: take slots, in marker order
  std::vector<std::vector<std::string>> set_markers_;    // per set: marker names
  std::vector<Eigen::Vector3d> last_seen_;               // per take slot, metres (occluded markers stay there)
  std::map<std::pair<uint32_t, uint16_t>, Client> clients_;
  std::size_t next_index_ = 0;    // take frame streamed next
  int32_t frame_number_ = 1;  // of the next frame
  int models_changed_frames_ = 0;
  std::mt19937 garbage_rng_{17};
  ServeCounts counts_;
};

}  // namespace facecap::tools
