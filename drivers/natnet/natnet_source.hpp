#pragma once
// The NatNet client: frames from OptiTrack Motive (or `facecap natnet-serve`) over UDP.
//
// open() connects: NAT_CONNECT (or a NAT_DISCOVERY broadcast to find the server) until
// NAT_SERVERINFO answers, the bitstream (the server's, or one asked for with
// "Bitstream,M.m" from a 4.x unicast server), the data socket (the multicast group joined
// on the configured interface), then NAT_MODELDEF, which names the marker set's markers:
// the source's labels are known when open() returns, or it throws an Error naming the
// server and what did not answer.
//
// start() runs the receive thread: it reads the data socket (multicast frames, or
// unicast from 3.x-style servers) and the command socket (replies, and frames from 4.x
// unicast servers), parses each datagram (formats/natnet.hpp), converts frames
// (formats/natnet_markers.hpp) into the latest-value mailbox, asks again for the model
// definitions when they change, sends keep-alives (unicast) and echoes (the server's clock
// on ours, for latency), follows a restarted server, and when the server falls silent says
// so in its state line (SourceHealth::state) and reconnects every second until frames come again. Malformed,
// truncated and oversize datagrams are counted (NatNetCounts, SourceHealth::errors) and
// dropped. Once the server is chosen (server_address, or the first to answer discovery),
// datagrams from any other sender are dropped unread and counted (SourceHealth::foreign):
// every datagram must come from the server's address, and all but frames of data from its
// command port. Text from the server is logged and shown escaped (core/printable.hpp).
#include <atomic>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "drivers/api/marker_source.hpp"
#include "drivers/api/source_config.hpp"
#include "drivers/natnet/server_clock.hpp"
#include "drivers/natnet/udp_socket.hpp"
#include "formats/natnet.hpp"
#include "formats/natnet_markers.hpp"
#include "formats/natnet_request.hpp"

namespace facecap::drivers {

// Since open(). Safe from any thread.
struct NatNetCounts {
  uint64_t frames = 0;            // frames of data parsed and converted
  uint64_t malformed = 0;         // did not parse (unknown id, fields that contradict their sizes)
  uint64_t truncated = 0;         // shorter than their header says
  uint64_t oversize = 0;          // longer than their header says, or than any NatNet packet
  uint64_t stale = 0;             // frames older than one already delivered (repeats, reordering)
  uint64_t restarts = 0;          // times the server's frame numbers went back: it restarted
  uint64_t silences = 0;          // times the server fell silent for silence_timeout_s
  uint64_t model_updates = 0;     // model definitions received after open()
  uint64_t unlabelled_dropped = 0;  // unlabelled points beyond the slots
  uint64_t foreign = 0;           // from a sender other than the server: dropped unread
  uint64_t errors() const noexcept { return malformed + truncated + oversize; }
};

class NatNetSource final : public MailboxSource {
 public:
  explicit NatNetSource(NatNetOptions options);
  ~NatNetSource() override;

  // Sockets and the handshake, within connect_timeout_s. Throws Error. Not RT-safe.
  void open() override;
  const SourceInfo& info() const noexcept override { return info_; }
  // Starts the receive thread. Not RT-safe.
  void start(const SourceStart& start) override;
  void stop() noexcept override;
  std::string description() const override;

  NatNetCounts counts() const noexcept;
  // The bitstream frames are read as. Valid after open().
  formats::natnet::Version bitstream() const noexcept { return bitstream_; }
  bool multicast() const noexcept { return multicast_; }

 private:
  enum class Wanted : uint8_t { kServerInfo, kModels, kReply };
  void send(const formats::natnet::Message& message);
  void send_connect();  // or NAT_DISCOVERY while the server is not known
  void send_request(formats::natnet::RequestKind kind);
  // Reads datagrams until `wanted` arrived or the deadline passed; re-sends its request
  // every kRetryNs. Not on the receive thread (open() only).
  bool await(Wanted wanted, int64_t deadline_ns);
  void run();
  void drain(natnet::UdpSocket& socket);
  // Whether the datagram comes from the chosen server (any sender while discovering).
  bool from_server(std::span<const char> datagram, const natnet::Endpoint& from) const noexcept;
  void handle(std::span<const char> datagram, bool truncated, const natnet::Endpoint& from, int64_t received_ns);
  void on_server_info(const formats::natnet::ServerInfo& info, const natnet::Endpoint& from);
  void on_frame(const formats::natnet::FrameOfData& frame, int64_t received_ns);
  void on_models(const formats::natnet::ModelDefinitions& models);
  void periodic(int64_t now_ns);
  // Writes the state line from the silence and note_. Receive thread only.
  void publish_state(int64_t now_ns);
  // Counts a dropped datagram; `describe()` makes its text only for the few that are
  // logged one by one, so a flood costs no formatting.
  template <typename Describe>
  void count_bad(std::atomic<uint64_t>& counter, Describe&& describe);

  NatNetOptions options_;
  SourceInfo info_;
  natnet::LocalInterface interface_;
  natnet::Endpoint server_;
  std::string server_name_;  // "10.0.0.5", for messages
  std::string server_software_;  // "Motive 2.1.0.0, NatNet 3.0", from NAT_SERVERINFO, escaped
  std::optional<natnet::UdpSocket> command_, data_;
  std::optional<formats::natnet::ServerInfo> server_info_;
  std::optional<formats::natnet::FrameConverter> converter_;
  formats::natnet::Version bitstream_;
  bool discovering_ = false;
  // A NAT_REQUEST whose NAT_RESPONSE has not come yet (replies do not say what they answer).
  std::optional<formats::natnet::RequestKind> pending_request_;
  bool bitstream_refused_ = false;
  std::optional<formats::natnet::ModelDefinitions> opening_models_;  // open(): before the converter exists
  bool multicast_ = true;
  uint32_t group_ = 0;
  float frame_rate_ = 0.0f;
  std::vector<char> buffer_;

  // Receive thread (and open() before it).
  natnet::ServerClock clock_;
  bool have_frame_ = false;
  int32_t last_frame_number_ = 0;
  int64_t next_keepalive_ns_ = 0, next_echo_ns_ = 0, next_reconnect_ns_ = 0, next_models_request_ns_ = 0;
  int64_t next_error_log_ns_ = 0;
  uint64_t errors_logged_ = 0, errors_at_last_log_ = 0, foreign_logged_ = 0, foreign_at_last_log_ = 0;
  bool silent_ = false;

  std::atomic<int64_t> last_frame_ns_{0};
  std::atomic<bool> running_{false};
  std::thread thread_;
  std::atomic<uint64_t> frames_{0}, malformed_{0}, truncated_{0}, oversize_{0}, stale_{0}, restarts_{0}, silences_{0},
      model_updates_{0}, unlabelled_dropped_{0};
  std::string note_;  // what the last model definitions changed; receive thread only
};

}  // namespace facecap::drivers
