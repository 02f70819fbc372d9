#include "drivers/natnet/natnet_source.hpp"

#include <cmath>
#include <cstring>

#include <fmt/format.h>

#include "core/error.hpp"
#include "core/log.hpp"
#include "core/printable.hpp"
#include "core/time.hpp"
#include "formats/natnet_request.hpp"

namespace facecap::drivers {
namespace nn = formats::natnet;
namespace {

constexpr int64_t kRetryNs = 250 * kNsPerMs;           // open(): requests re-sent this often
constexpr int64_t kFrameRateWaitNs = 500 * kNsPerMs;   // open(): "FrameRate" is optional
constexpr int64_t kKeepAliveNs = kNsPerSecond;         // unicast: the server drops silent clients
constexpr int64_t kEchoNs = kNsPerSecond;              // clock synchronisation
constexpr int64_t kReconnectNs = kNsPerSecond;         // while the server is silent
constexpr int64_t kModelsRequestNs = 500 * kNsPerMs;   // "models changed" is set on many frames
constexpr int64_t kPollSliceNs = 50 * kNsPerMs;
constexpr int64_t kErrorLogNs = 10 * kNsPerSecond;     // bad datagrams: a summary at most this often
constexpr uint64_t kErrorsLoggedEach = 5;              // the first ones are logged one by one
constexpr std::size_t kDrainBatch = 256;               // datagrams per socket between periodic work
// Frame numbers that go back by more than this mean a restarted server; by less, a
// repeated or reordered datagram.
constexpr int32_t kRestartFrames = 16;
constexpr int kReceiveBufferBytes = 4 << 20;
constexpr nn::Version kOurNatNetVersion{4, 1, 0, 0};

// The end of the warning for one more dropped datagram of a kind whose warnings so far
// are `logged`, or nullptr past the first kErrorsLoggedEach (only counted, then summed up).
const char* drop_warning_tail(uint64_t& logged) noexcept {
  if (logged >= kErrorsLoggedEach) return nullptr;
  return ++logged == kErrorsLoggedEach ? " (further ones are counted, and summed up every 10 s)" : "";
}

std::optional<nn::Version> asked_bitstream(NatNetBitstream b) {
  switch (b) {
    case NatNetBitstream::kServer: return std::nullopt;
    case NatNetBitstream::k30: return nn::kBitstream30;
    case NatNetBitstream::k31: return nn::kBitstream31;
    case NatNetBitstream::k40: return nn::kBitstream40;
    case NatNetBitstream::k41: return nn::kBitstream41;
    case NatNetBitstream::k42: return nn::kBitstream42;
  }
  return std::nullopt;
}

double seconds(int64_t ns) { return double(ns) / kNsPerSecond; }

nn::Message message(nn::MessageId id, nn::MessageBody body = nn::RawPayload{}) { return {id, std::move(body)}; }

}  // namespace

NatNetSource::NatNetSource(NatNetOptions options) : options_(std::move(options)) {}

NatNetSource::~NatNetSource() { stop(); }

void NatNetSource::send(const nn::Message& m) {
  if (!command_->send_to(nn::encode_message(m, bitstream_), server_))
    spdlog::debug("natnet: sending {} to {} failed: {}", nn::kMessageIds.name(m.id), server_.to_string(),
                  std::strerror(errno));
}

void NatNetSource::send_connect() {
  nn::Connect connect;
  connect.sender.name = nn::NameField::from_text("facecapd");
  connect.sender.app_version = {0, 1, 0, 0};
  connect.sender.natnet_version = kOurNatNetVersion;
  connect.options = nn::ConnectOptions{false, asked_bitstream(options_.bitstream).value_or(nn::Version{})};
  send(message(discovering_ ? nn::MessageId::kDiscovery : nn::MessageId::kConnect, std::move(connect)));
}

void NatNetSource::send_request(nn::RequestKind kind) {
  pending_request_ = kind;
  send(message(nn::MessageId::kRequest, nn::Text{nn::request_text({kind, bitstream_})}));
}

bool NatNetSource::await(Wanted wanted, int64_t deadline_ns) {
  const auto satisfied = [&] {
    switch (wanted) {
      case Wanted::kServerInfo: return server_info_.has_value();
      case Wanted::kModels: return opening_models_.has_value();
      case Wanted::kReply: return !pending_request_.has_value();
    }
    return true;
  };
  int64_t next_send_ns = 0;
  for (;;) {
    if (satisfied()) return true;
    const int64_t now = monotonic_now_ns();
    if (now >= deadline_ns) return false;
    if (now >= next_send_ns) {
      switch (wanted) {
        case Wanted::kServerInfo: send_connect(); break;
        case Wanted::kModels: send(message(nn::MessageId::kRequestModelDef)); break;
        case Wanted::kReply: send_request(*pending_request_); break;
      }
      next_send_ns = now + kRetryNs;
    }
    const int ready =
        natnet::wait_readable(*command_, data_ ? &*data_ : nullptr, std::min(deadline_ns, next_send_ns) - now);
    if (ready & 1) drain(*command_);
    if (ready & 2) drain(*data_);
  }
}

void NatNetSource::open() {
  const int64_t deadline_ns = monotonic_now_ns() + int64_t(options_.connect_timeout_s * kNsPerSecond);
  const auto asked = asked_bitstream(options_.bitstream);
  bitstream_ = asked.value_or(nn::kBitstream30);  // until the server says
  interface_ = natnet::resolve_interface(options_.local_interface);
  buffer_.resize(nn::kHeaderBytes + nn::kMaxPayloadBytes + 1);  // a larger datagram shows as cut
  command_.emplace(interface_.address, 0, false, "NatNet command socket");
  command_->set_receive_buffer(kReceiveBufferBytes);
  discovering_ = options_.server_address.empty();
  if (discovering_) {
    command_->enable_broadcast();
    server_ = {natnet::parse_ipv4(options_.discovery_address, "source.natnet.discovery_address"),
               uint16_t(options_.command_port)};
  } else {
    server_ = {natnet::parse_ipv4(options_.server_address, "source.natnet.server_address"),
               uint16_t(options_.command_port)};
  }
  server_name_ = server_.address_string();
  const std::string timeout = fmt::format("{:g} s (source.natnet.connect_timeout_s)", options_.connect_timeout_s);
  if (!await(Wanted::kServerInfo, deadline_ns)) {
    throw Error(discovering_ ? fmt::format("no NatNet server answered the discovery broadcast to {} within {}: is "
                                           "Motive streaming on this network? (or set source.natnet.server_address)",
                                           server_.to_string(), timeout)
                             : fmt::format("the NatNet server {} did not answer NAT_CONNECT within {}: is Motive "
                                           "streaming, and are the address and command port right?",
                                           server_.to_string(), timeout));
  }
  if (!nn::is_supported_bitstream(bitstream_)) {
    throw Error(fmt::format("NatNet server {} ({} {}) streams NatNet {}: facecap reads 3.x and 4.x", server_name_,
                            server_info_->sender.name.text(), server_info_->sender.app_version.to_string(),
                            server_info_->sender.natnet_version.to_string()));
  }

  const bool server_multicast = !server_info_->connection || server_info_->connection->multicast;
  multicast_ = options_.transport == NatNetTransport::kAuto ? server_multicast
                                                            : options_.transport == NatNetTransport::kMulticast;
  if (multicast_ != server_multicast) {
    throw Error(fmt::format("NatNet server {} streams {}, but source.natnet.transport is \"{}\"", server_name_,
                            server_multicast ? "multicast" : "unicast", kNatNetTransports.name(options_.transport)));
  }
  if (server_info_->connection && server_info_->connection->data_port != options_.data_port) {
    spdlog::warn("natnet: {} says its data port is {}; listening on {} (source.natnet.data_port)", server_name_,
                 server_info_->connection->data_port, options_.data_port);
  }
  const auto& announced = server_info_->connection ? server_info_->connection->multicast_group
                                                   : nn::kDefaultMulticastGroup;
  group_ = !options_.multicast_group.empty()
               ? natnet::parse_ipv4(options_.multicast_group, "source.natnet.multicast_group")
               : uint32_t(announced[0]) << 24 | uint32_t(announced[1]) << 16 | uint32_t(announced[2]) << 8 | announced[3];

  // A 4.x server streaming unicast sends each client the layout it asks for.
  if (asked && server_info_->sender.natnet_version.major >= 4 && !multicast_ &&
      nn::Version{server_info_->sender.natnet_version.major, server_info_->sender.natnet_version.minor} != *asked) {
    pending_request_ = nn::RequestKind::kSetBitstream;
    if (!await(Wanted::kReply, deadline_ns))
      throw Error(fmt::format("NatNet server {} did not answer \"{}\" within {}", server_name_,
                              nn::request_text({nn::RequestKind::kSetBitstream, *asked}), timeout));
    if (bitstream_refused_)
      throw Error(fmt::format("NatNet server {} refused to stream bitstream {} (source.natnet.bitstream)", server_name_,
                              asked->major_minor()));
  }

  data_.emplace(0, uint16_t(options_.data_port), true, "NatNet data socket");
  data_->set_receive_buffer(kReceiveBufferBytes);
  if (multicast_) data_->join_multicast(group_, interface_);

  pending_request_ = nn::RequestKind::kFrameRate;
  await(Wanted::kReply, std::min(deadline_ns, monotonic_now_ns() + kFrameRateWaitNs));
  pending_request_.reset();

  if (!options_.marker_set.empty() && !await(Wanted::kModels, deadline_ns)) {
    throw Error(fmt::format("NatNet server {} sent no model definitions within {}: they name marker set '{}'s markers",
                            server_name_, timeout, options_.marker_set));
  }
  converter_.emplace(nn::MarkerSelection{options_.marker_set, std::size_t(options_.unlabelled_markers),
                                         uint16_t(options_.timecode_rate_hz)},
                     opening_models_.value_or(nn::ModelDefinitions{}), server_name_);
  opening_models_.reset();

  info_.labels = converter_->labels();
  info_.units = std::string(nn::kPositionUnits);
  info_.nominal_rate_hz = frame_rate_ > 0.0f && std::isfinite(frame_rate_) ? double(frame_rate_) : 0.0;
  info_.own_clock = true;
  info_.unlabelled = converter_->set_slots() == 0 && options_.unlabelled_markers > 0;  // only a cloud
  configure_mailbox(info_.labels);
}

void NatNetSource::start(const SourceStart& start) {
  const int64_t now = monotonic_now_ns();
  last_frame_ns_.store(now, std::memory_order_relaxed);
  next_keepalive_ns_ = next_echo_ns_ = next_reconnect_ns_ = now;
  next_error_log_ns_ = now + kErrorLogNs;
  running_.store(true, std::memory_order_release);
  thread_ = start_driver_thread(start, [this] { run(); });
}

void NatNetSource::stop() noexcept {
  if (!running_.exchange(false, std::memory_order_acq_rel)) return;
  if (thread_.joinable()) thread_.join();
  if (command_ && !multicast_) {
    try {
      send(message(nn::MessageId::kDisconnect));  // a unicast server stops sending at once
    } catch (const std::exception&) {
    }
  }
}

void NatNetSource::run() {
  while (running_.load(std::memory_order_acquire)) {
    periodic(monotonic_now_ns());
    const int ready = natnet::wait_readable(*command_, &*data_, kPollSliceNs);
    if (ready & 1) drain(*command_);
    if (ready & 2) drain(*data_);
  }
}

void NatNetSource::drain(natnet::UdpSocket& socket) {
  for (std::size_t n = 0; n < kDrainBatch; ++n) {
    const auto datagram = socket.receive(buffer_);
    if (!datagram) return;
    handle(std::span<const char>(buffer_.data(), datagram->size), datagram->truncated, datagram->from,
           monotonic_now_ns());
  }
}

template <typename Describe>
void NatNetSource::count_bad(std::atomic<uint64_t>& counter, Describe&& describe) {
  counter.fetch_add(1, std::memory_order_relaxed);
  errors_.fetch_add(1, std::memory_order_relaxed);
  if (const char* tail = drop_warning_tail(errors_logged_)) spdlog::warn("natnet: dropped {}{}", describe(), tail);
}

bool NatNetSource::from_server(std::span<const char> datagram, const natnet::Endpoint& from) const noexcept {
  if (discovering_) return true;  // no server chosen yet: the first NAT_SERVERINFO chooses it
  if (from.address != server_.address) return false;
  if (from.port == server_.port) return true;
  // Motive answers on its command port; frames come from its data socket, whose port NatNet does not fix.
  if (datagram.size() < 2) return false;
  uint16_t id = 0;
  std::memcpy(&id, datagram.data(), 2);
  return id == uint16_t(nn::MessageId::kFrameOfData);
}

void NatNetSource::handle(std::span<const char> datagram, bool truncated, const natnet::Endpoint& from,
                          int64_t received_ns) {
  if (!from_server(datagram, from)) {
    foreign_.fetch_add(1, std::memory_order_relaxed);
    if (const char* tail = drop_warning_tail(foreign_logged_))
      spdlog::warn("natnet: dropped a datagram from {}, which is not the server {}{}", from.to_string(), server_.to_string(),
                   tail);
    return;
  }
  if (truncated || datagram.size() > nn::kHeaderBytes + nn::kMaxPayloadBytes) {
    count_bad(oversize_, [&] { return fmt::format("a datagram from {} larger than any NatNet packet", from.to_string()); });
    return;
  }
  if (datagram.size() < nn::kHeaderBytes) {
    count_bad(truncated_, [&] {
      return fmt::format("a {}-byte datagram from {}: shorter than a NatNet header", datagram.size(), from.to_string());
    });
    return;
  }
  uint16_t declared = 0;
  std::memcpy(&declared, datagram.data() + 2, 2);
  if (nn::kHeaderBytes + declared != datagram.size()) {
    const bool cut = nn::kHeaderBytes + declared > datagram.size();
    count_bad(cut ? truncated_ : oversize_, [&] {
      return fmt::format("a datagram from {} of {} bytes whose header says {}", from.to_string(), datagram.size(),
                         nn::kHeaderBytes + declared);
    });
    return;
  }
  nn::Message m;
  try {
    m = nn::parse_message(datagram, bitstream_, from.to_string());
  } catch (const Error& e) {
    count_bad(malformed_, [&] { return fmt::format("a malformed datagram: {}", e.what()); });
    return;
  }
  switch (m.id) {
    case nn::MessageId::kServerInfo: on_server_info(std::get<nn::ServerInfo>(m.body), from); break;
    case nn::MessageId::kModelDef: on_models(std::get<nn::ModelDefinitions>(m.body)); break;
    case nn::MessageId::kFrameOfData: on_frame(std::get<nn::FrameOfData>(m.body), received_ns); break;
    case nn::MessageId::kEchoResponse: {
      const auto& echo = std::get<nn::EchoResponse>(m.body);
      clock_.add_echo(int64_t(echo.client_time), echo.server_time, received_ns);
      break;
    }
    case nn::MessageId::kResponse: {
      const auto& reply = std::get<nn::RawPayload>(m.body);
      if (pending_request_ == nn::RequestKind::kSetBitstream) {
        bitstream_refused_ = reply.as_int32() && *reply.as_int32() != nn::kRequestDone;
        if (!bitstream_refused_) bitstream_ = *asked_bitstream(options_.bitstream);
      } else if (pending_request_ == nn::RequestKind::kFrameRate) {
        frame_rate_ = reply.as_float().value_or(0.0f);
      }
      pending_request_.reset();
      break;
    }
    case nn::MessageId::kUnrecognizedRequest:
      if (pending_request_) spdlog::info("natnet: {} does not know \"{}\"", server_name_,
                                         nn::request_text({*pending_request_, bitstream_}));
      if (pending_request_ == nn::RequestKind::kSetBitstream) bitstream_refused_ = true;
      pending_request_.reset();
      break;
    case nn::MessageId::kDisconnectByTimeout:
      spdlog::warn("natnet: {} dropped this client for silence; connecting again", server_name_);
      send_connect();
      break;
    case nn::MessageId::kMessageString:
      spdlog::info("natnet: message from {}: {}", server_name_, std::get<nn::Text>(m.body).text);  // escaped by the log format
      break;
    default: break;  // requests of other clients (multicast), keep-alives, echo requests
  }
}

void NatNetSource::on_server_info(const nn::ServerInfo& info, const natnet::Endpoint& from) {
  if (discovering_) {  // the first server to answer is the one
    discovering_ = false;
    server_ = {from.address, uint16_t(options_.command_port)};
    server_name_ = server_.address_string();
    spdlog::info("natnet: discovered {} ({}) at {}", info.sender.name.text(), info.sender.app_version.to_string(),
                 server_name_);
    send_connect();  // now a NAT_CONNECT: a unicast server streams to connected clients only
  }
  const bool first = !server_info_;
  server_info_ = info;
  server_software_ = fmt::format("{} {}, NatNet {}", printable(info.sender.name.text()),  // shown in /status
                                 info.sender.app_version.to_string(), info.sender.natnet_version.major_minor());
  clock_.set_rate(info.connection ? info.connection->high_res_clock_hz : 0);
  const auto asked = asked_bitstream(options_.bitstream);
  const nn::Version streamed = asked.value_or(nn::Version{info.sender.natnet_version.major, info.sender.natnet_version.minor});
  if (!first && streamed != bitstream_)
    spdlog::warn("natnet: {} now streams bitstream {} (was {})", server_name_, streamed.major_minor(),
                 bitstream_.major_minor());
  bitstream_ = streamed;
}

void NatNetSource::on_models(const nn::ModelDefinitions& models) {
  if (!converter_) {
    opening_models_ = models;
    return;
  }
  model_updates_.fetch_add(1, std::memory_order_relaxed);
  std::string note = printable(converter_->follow(models));  // marker names from the server, shown in STATUS
  if (!note.empty()) spdlog::warn("natnet: new model definitions from {}: {}", server_name_, note);
  else spdlog::info("natnet: new model definitions from {} followed", server_name_);
  note_ = std::move(note);
  publish_state(monotonic_now_ns());
}

void NatNetSource::publish_state(int64_t now_ns) {
  std::string text;
  if (silent_)
    text = fmt::format("no frames from {} for {:.1f} s", server_name_,
                       seconds(now_ns - last_frame_ns_.load(std::memory_order_relaxed)));
  if (!note_.empty()) text += (text.empty() ? "" : "; ") + note_;
  state_.set(text);
}

void NatNetSource::on_frame(const nn::FrameOfData& frame, int64_t received_ns) {
  if (!converter_ || !mailbox_) return;  // still opening
  if (silent_) {
    silent_ = false;
    spdlog::info("natnet: frames from {} again after {:.1f} s", server_name_,
                 seconds(received_ns - last_frame_ns_.load(std::memory_order_relaxed)));
    last_frame_ns_.store(received_ns, std::memory_order_relaxed);
    publish_state(received_ns);
  }
  last_frame_ns_.store(received_ns, std::memory_order_relaxed);
  if (have_frame_ && frame.frame_number <= last_frame_number_) {
    if (int64_t(last_frame_number_) - frame.frame_number <= kRestartFrames) {
      stale_.fetch_add(1, std::memory_order_relaxed);
      return;
    }
    restarts_.fetch_add(1, std::memory_order_relaxed);
    spdlog::warn("natnet: {} restarted (frame numbers went back from {} to {}): connecting again and asking for its "
                 "model definitions", server_name_, last_frame_number_, frame.frame_number);
    send_connect();
    send(message(nn::MessageId::kRequestModelDef));
  }
  have_frame_ = true;
  last_frame_number_ = frame.frame_number;
  if (frame.models_changed() && received_ns >= next_models_request_ns_) {
    send(message(nn::MessageId::kRequestModelDef));
    next_models_request_ns_ = received_ns + kModelsRequestNs;
  }
  MarkerFrame& out = mailbox_->write_buffer();
  const nn::ConversionCounts counts = converter_->convert(frame, out);
  out.receive_time_ns = received_ns;
  out.exposure_time_ns = frame.camera_mid_exposure != 0 ? clock_.to_local_ns(frame.camera_mid_exposure) : 0;
  mailbox_->publish();
  frames_.fetch_add(1, std::memory_order_relaxed);
  if (counts.unlabelled_dropped > 0) unlabelled_dropped_.fetch_add(counts.unlabelled_dropped, std::memory_order_relaxed);
}

void NatNetSource::periodic(int64_t now_ns) {
  if (!multicast_ && now_ns >= next_keepalive_ns_) {
    send(message(nn::MessageId::kKeepAlive));
    next_keepalive_ns_ = now_ns + kKeepAliveNs;
  }
  if (now_ns >= next_echo_ns_) {
    send(message(nn::MessageId::kEchoRequest, nn::EchoRequest{uint64_t(now_ns)}));
    next_echo_ns_ = now_ns + kEchoNs;
  }
  const int64_t silent_for = now_ns - last_frame_ns_.load(std::memory_order_relaxed);
  if (silent_for > int64_t(options_.silence_timeout_s * kNsPerSecond)) {
    if (!silent_) {
      silent_ = true;
      silences_.fetch_add(1, std::memory_order_relaxed);
      spdlog::warn("natnet: no frames from {} for {:.1f} s: connecting again every second", server_name_,
                   seconds(silent_for));
    }
    publish_state(now_ns);  // the silence's length, every poll slice
    if (now_ns >= next_reconnect_ns_) {
      send_connect();
      send(message(nn::MessageId::kRequestModelDef));
      next_reconnect_ns_ = now_ns + kReconnectNs;
    }
  }
  const uint64_t errors = errors_.load(std::memory_order_relaxed), foreign = foreign_.load(std::memory_order_relaxed);
  if (now_ns >= next_error_log_ns_) {
    if (errors > errors_at_last_log_) {
      const NatNetCounts c = counts();
      spdlog::warn("natnet: {} bad datagrams dropped in the last {:.0f} s (since start: malformed {}, truncated {}, "
                   "oversize {})", errors - errors_at_last_log_, seconds(kErrorLogNs), c.malformed, c.truncated,
                   c.oversize);
    }
    if (foreign > foreign_at_last_log_)
      spdlog::warn("natnet: {} datagrams from senders other than the server {} dropped in the last {:.0f} s ({} since "
                   "start)", foreign - foreign_at_last_log_, server_.to_string(), seconds(kErrorLogNs), foreign);
    errors_at_last_log_ = errors;
    foreign_at_last_log_ = foreign;
    next_error_log_ns_ = now_ns + kErrorLogNs;
  }
}

NatNetCounts NatNetSource::counts() const noexcept {
  NatNetCounts c;
  c.frames = frames_.load(std::memory_order_relaxed);
  c.malformed = malformed_.load(std::memory_order_relaxed);
  c.truncated = truncated_.load(std::memory_order_relaxed);
  c.oversize = oversize_.load(std::memory_order_relaxed);
  c.stale = stale_.load(std::memory_order_relaxed);
  c.restarts = restarts_.load(std::memory_order_relaxed);
  c.silences = silences_.load(std::memory_order_relaxed);
  c.model_updates = model_updates_.load(std::memory_order_relaxed);
  c.unlabelled_dropped = unlabelled_dropped_.load(std::memory_order_relaxed);
  c.foreign = foreign_.load(std::memory_order_relaxed);
  return c;
}

std::string NatNetSource::description() const {
  std::string text = fmt::format("natnet: {}", server_name_);
  if (!server_software_.empty()) text += fmt::format(" ({})", server_software_);
  text += fmt::format(", bitstream {}, ", bitstream_.major_minor());
  text += multicast_ ? fmt::format("multicast {}:{}", natnet::ipv4_string(group_), options_.data_port)
                     : fmt::format("unicast to port {} and {}", options_.data_port,
                                   command_ ? command_->local().port : 0);
  if (!interface_.name.empty()) text += fmt::format(" on {}", interface_.name);
  if (converter_) {
    if (converter_->set_slots() > 0)
      text += fmt::format(", marker set '{}' ({} markers)", options_.marker_set, converter_->set_slots());
    if (options_.unlabelled_markers > 0)
      text += fmt::format("{} {} unlabelled slots", converter_->set_slots() > 0 ? " +" : ",", options_.unlabelled_markers);
  }
  if (info_.nominal_rate_hz > 0) text += fmt::format(", {:g} Hz", info_.nominal_rate_hz);
  return text;
}

}  // namespace facecap::drivers
