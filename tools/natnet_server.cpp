#include "tools/natnet_server.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <csignal>
#include <cstring>
#include <random>

#include <fmt/format.h>

#include "core/error.hpp"
#include "core/time.hpp"
#include "core/units.hpp"
#include "formats/natnet_request.hpp"

namespace facecap::tools {
namespace nn = formats::natnet;
using drivers::natnet::Endpoint;

namespace {

constexpr int64_t kHighResClockHz = kNsPerSecond;  // the stamps are CLOCK_MONOTONIC nanoseconds
constexpr int kModelsChangedFrames = 10;            // frames flagged "models changed" after a restart
constexpr float kMarkerSize = 0.014f;               // metres: a 14 mm facial marker
constexpr int32_t kFirstPointId = 50000;            // unlabelled points' ids, as Motive numbers them
constexpr int64_t kGarbageSliceNs = kNsPerMs;       // bad datagrams go out at least this often
// Labelled marker flags as Motive 2.1 streams a seen marker of a model (real traffic: 0x0a).
constexpr int16_t kSeenFlags = int16_t(nn::LabelledMarkerFlag::kPointCloudSolved) | int16_t(nn::LabelledMarkerFlag::kHasModel);

std::atomic<bool> g_stop{false}, g_restart{false}, g_silence{false};
extern "C" void on_stop_signal(int) { g_stop.store(true); }
extern "C" void on_restart_signal(int) { g_restart.store(true); }
extern "C" void on_silence_signal(int) { g_silence.store(true); }

nn::Position position_of(const Eigen::Vector3d& metres) {
  return {float(metres.x()), float(metres.y()), float(metres.z())};
}

}  // namespace

NatNetServer::NatNetServer(ServeOptions options, formats::MarkerTake take)
    : options_(std::move(options)), take_(std::move(take)) {
  if (take_.frames.empty()) throw Error("natnet-serve: the take has no frames");
  frame_number_ = options_.first_frame;
  rate_hz_ = options_.rate_hz > 0 ? options_.rate_hz : take_.rate_hz;
  if (!(rate_hz_ > 0)) throw Error("natnet-serve: the take states no frame rate: give one with --rate");
  const auto mm = millimetres_per_unit(take_.units);
  if (!mm) throw Error(fmt::format("natnet-serve: the take's units \"{}\" are not mm, cm or m: NatNet sends metres", take_.units));
  metres_per_unit_ = *mm / 1000.0;
  if (!nn::is_supported_bitstream(options_.bitstream))
    throw Error(fmt::format("natnet-serve: bitstream {} is not one facecap writes (3.x, 4.x)", options_.bitstream.major_minor()));
  group_ = drivers::natnet::parse_ipv4(options_.multicast_group, "--multicast-group");

  if (!options_.unlabelled) {
    std::vector<ServedMarkerSet> sets = options_.marker_sets;
    if (sets.empty()) sets.push_back({"Face", ""});
    if (sets.size() > 1 && std::any_of(sets.begin(), sets.end(), [](const auto& s) { return s.prefix.empty(); }))
      throw Error("natnet-serve: several marker sets need a label prefix each (--marker-set NAME=PREFIX)");
    for (const ServedMarkerSet& set : sets) {
      std::vector<std::size_t> slots;
      std::vector<std::string> names;
      for (std::size_t k = 0; k < take_.labels.size(); ++k) {
        if (!take_.labels[k].starts_with(set.prefix) || take_.labels[k].size() == set.prefix.size()) continue;
        slots.push_back(k);
        names.push_back(take_.labels[k].substr(set.prefix.size()));
      }
      if (slots.empty())
        throw Error(fmt::format("natnet-serve: marker set '{}': no label of the take begins with \"{}\"", set.name,
                                set.prefix));
      set_names_.push_back(set.name);
      set_slots_.push_back(std::move(slots));
      set_markers_.push_back(std::move(names));
    }
  }
  last_seen_.assign(take_.labels.size(), Eigen::Vector3d::Zero());
}

nn::ServerInfo NatNetServer::server_info() const {
  nn::ServerInfo info;
  info.sender.name = nn::NameField::from_text("facecap natnet-serve");
  info.sender.app_version = {0, 1, 0, 0};
  info.sender.natnet_version = {options_.bitstream.major, options_.bitstream.minor, 0, 0};
  nn::ServerConnection connection;
  connection.high_res_clock_hz = kHighResClockHz;
  connection.data_port = options_.data_port;
  connection.multicast = options_.mode == ServeMode::kMulticast;
  connection.multicast_group = {uint8_t(group_ >> 24), uint8_t(group_ >> 16), uint8_t(group_ >> 8), uint8_t(group_)};
  info.connection = connection;
  return info;
}

nn::ModelDefinitions NatNetServer::models(nn::Version bitstream) const {
  nn::ModelDefinitions defs;
  // Where each marker sits in the take's first frame, for the models' marker offsets.
  const MarkerFrame& first = take_.frames.front();
  for (std::size_t s = 0; s < set_names_.size(); ++s) {
    defs.models.push_back(nn::MarkerSetDescription{set_names_[s], set_markers_[s]});
    const int32_t id = int32_t(s + 1);
    if (bitstream >= nn::kBitstream41) {
      nn::AssetDescription asset{set_names_[s], 1, id, {}, {}};
      for (std::size_t i = 0; i < set_slots_[s].size(); ++i) {
        const Marker& m = first.markers[set_slots_[s][i]];
        const Eigen::Vector3d p = m.present() ? Eigen::Vector3d(m.position * metres_per_unit_) : Eigen::Vector3d::Zero();
        asset.markers.push_back({set_markers_[s][i], int32_t(i + 1), position_of(p), kMarkerSize, 0});
      }
      defs.models.push_back(std::move(asset));
    } else {
      nn::RigidBodyDescription body{set_names_[s], id, -1, {}, {0, 0, 0, 1}, {}};
      for (std::size_t i = 0; i < set_slots_[s].size(); ++i)
        body.markers.push_back({{}, 0, bitstream >= nn::kBitstream40 ? set_markers_[s][i] : ""});
      defs.models.push_back(std::move(body));
    }
  }
  return defs;
}

nn::FrameOfData NatNetServer::frame_of_data(nn::Version bitstream, int64_t due_ns, int64_t now_ns) const {
  const MarkerFrame& source = take_.frames[next_index_ % take_.frames.size()];
  nn::FrameOfData f;
  f.frame_number = frame_number_;
  if (options_.unlabelled) {
    std::vector<std::size_t> order(take_.labels.size());
    for (std::size_t k = 0; k < order.size(); ++k) order[k] = k;
    std::mt19937 rng{uint32_t(frame_number_)};
    std::shuffle(order.begin(), order.end(), rng);
    for (const std::size_t k : order) {
      if (!source.markers[k].present()) continue;
      f.labelled_markers.push_back({kFirstPointId + int32_t(k), position_of(last_seen_[k]), kMarkerSize,
                                    int16_t(nn::LabelledMarkerFlag::kPointCloudSolved) |
                                        int16_t(nn::LabelledMarkerFlag::kUnlabelled),
                                    0.0f});
    }
  }
  for (std::size_t s = 0; s < set_names_.size(); ++s) {
    nn::MarkerSetData set{set_names_[s], {}};
    nn::AssetData asset{int32_t(s + 1), {}, {}};
    for (std::size_t i = 0; i < set_slots_[s].size(); ++i) {
      const std::size_t k = set_slots_[s][i];
      const bool seen = source.markers[k].present();
      set.markers.push_back(seen ? position_of(last_seen_[k]) : nn::Position{0, 0, 0});
      const int16_t flags = seen ? kSeenFlags : int16_t(kSeenFlags | int16_t(nn::LabelledMarkerFlag::kOccluded));
      const nn::LabelledMarker marker{int32_t(s + 1) << 16 | int32_t(i + 1), position_of(last_seen_[k]), kMarkerSize,
                                      flags, 0.0f};
      f.labelled_markers.push_back(marker);
      if (bitstream >= nn::kBitstream41) asset.markers.push_back(marker);
    }
    f.marker_sets.push_back(std::move(set));
    if (bitstream >= nn::kBitstream41) f.assets.push_back(std::move(asset));
  }
  if (source.timecode.valid()) {
    f.timecode = nn::encode_timecode({source.timecode.hours, source.timecode.minutes, source.timecode.seconds,
                                      source.timecode.frames, 0});
    f.timecode_subframe = uint32_t(std::max(0.0f, source.timecode.subframe));
  }
  f.timestamp_s = double(counts_.frames) / rate_hz_;
  f.camera_mid_exposure = uint64_t(due_ns - int64_t(options_.exposure_latency_ms * kNsPerMs));
  f.camera_data_received = uint64_t(due_ns);
  f.transmit = uint64_t(now_ns);
  f.params = models_changed_frames_ > 0 ? 0x02 : 0;
  return f;
}

nn::Version NatNetServer::bitstream_of(const Endpoint& client) const {
  if (options_.mode == ServeMode::kMulticast) return options_.bitstream;
  const auto it = clients_.find({client.address, client.port});
  return it == clients_.end() ? options_.bitstream : it->second.bitstream;
}

void NatNetServer::reply(std::vector<Outgoing>& out, const Endpoint& to, nn::MessageId id, nn::MessageBody body,
                         nn::Version bitstream) const {
  out.push_back({to, nn::encode_message({id, std::move(body)}, bitstream)});
}

std::vector<Outgoing> NatNetServer::answer(std::span<const char> datagram, const Endpoint& from, int64_t now_ns) {
  std::vector<Outgoing> out;
  const nn::Version bitstream = bitstream_of(from);
  nn::Message m;
  try {
    m = nn::parse_message(datagram, bitstream, "client " + from.to_string());
  } catch (const Error&) {
    ++counts_.bad_requests;
    return out;
  }
  ++counts_.requests;
  const bool unicast = options_.mode != ServeMode::kMulticast;
  const auto client = clients_.find({from.address, from.port});
  if (client != clients_.end()) client->second.last_seen_ns = now_ns;
  switch (m.id) {
    case nn::MessageId::kConnect: {
      const auto& connect = std::get<nn::Connect>(m.body);
      nn::Version asked = options_.bitstream;
      if (connect.options && nn::is_supported_bitstream(connect.options->bitstream))
        asked = {connect.options->bitstream.major, connect.options->bitstream.minor};
      if (unicast && (client != clients_.end() || clients_.size() < kMaxClients))
        clients_[{from.address, from.port}] = Client{asked, now_ns};
      reply(out, from, nn::MessageId::kServerInfo, server_info(), bitstream);
      break;
    }
    case nn::MessageId::kDiscovery: reply(out, from, nn::MessageId::kServerInfo, server_info(), bitstream); break;
    case nn::MessageId::kRequestModelDef:
      reply(out, from, nn::MessageId::kModelDef, models(bitstream), bitstream);
      break;
    case nn::MessageId::kRequestFrameOfData: {
      const int64_t now = monotonic_now_ns();
      reply(out, from, nn::MessageId::kFrameOfData, frame_of_data(bitstream, now, now), bitstream);
      break;
    }
    case nn::MessageId::kEchoRequest: {
      const auto& echo = std::get<nn::EchoRequest>(m.body);
      reply(out, from, nn::MessageId::kEchoResponse, nn::EchoResponse{echo.client_time, uint64_t(monotonic_now_ns())},
            bitstream);
      break;
    }
    case nn::MessageId::kDisconnect: clients_.erase({from.address, from.port}); break;
    case nn::MessageId::kRequest: {
      const auto request = nn::parse_request(std::get<nn::Text>(m.body).text);
      if (!request) {
        reply(out, from, nn::MessageId::kUnrecognizedRequest, nn::RawPayload{}, bitstream);
        break;
      }
      std::string payload;
      const auto put_int = [&](int32_t v) { payload.assign(reinterpret_cast<const char*>(&v), 4); };
      switch (request->kind) {
        case nn::RequestKind::kFrameRate: {
          const float rate = float(rate_hz_);
          payload.assign(reinterpret_cast<const char*>(&rate), 4);
          break;
        }
        case nn::RequestKind::kBitstreamQuery: payload = nn::bitstream_reply(bitstream) + '\0'; break;
        case nn::RequestKind::kSetBitstream: {
          const bool granted = unicast && client != clients_.end() && nn::is_supported_bitstream(request->bitstream);
          if (granted) client->second.bitstream = request->bitstream;
          put_int(granted ? nn::kRequestDone : nn::kRequestRefused);
          break;
        }
        case nn::RequestKind::kAnalogSamplesPerMocapFrame: put_int(0); break;
      }
      reply(out, from, nn::MessageId::kResponse, nn::RawPayload{payload}, bitstream);
      break;
    }
    default: break;  // keep-alives (counted above as the client being seen), others' messages
  }
  return out;
}

std::vector<Outgoing> NatNetServer::next_frame(int64_t due_ns, int64_t now_ns) {
  std::vector<Outgoing> out;
  const MarkerFrame& source = take_.frames[next_index_ % take_.frames.size()];
  for (std::size_t k = 0; k < last_seen_.size(); ++k)
    if (source.markers[k].present()) last_seen_[k] = source.markers[k].position * metres_per_unit_;
  // Forget unicast clients that stopped keeping themselves alive.
  for (auto it = clients_.begin(); it != clients_.end();) {
    if (now_ns - it->second.last_seen_ns > kClientTimeoutNs) {
      reply(out, {it->first.first, it->first.second}, nn::MessageId::kDisconnectByTimeout, nn::RawPayload{},
            it->second.bitstream);
      it = clients_.erase(it);
    } else {
      ++it;
    }
  }
  if (options_.mode == ServeMode::kMulticast) {
    reply(out, {group_, options_.data_port}, nn::MessageId::kFrameOfData,
          frame_of_data(options_.bitstream, due_ns, now_ns), options_.bitstream);
  } else {
    for (const auto& [address, client] : clients_) {
      const Endpoint to{address.first,
                        options_.mode == ServeMode::kUnicast ? address.second : options_.data_port};
      reply(out, to, nn::MessageId::kFrameOfData, frame_of_data(client.bitstream, due_ns, now_ns), client.bitstream);
    }
  }
  counts_.packets += out.size();
  ++counts_.frames;
  ++next_index_;
  ++frame_number_;
  if (models_changed_frames_ > 0) --models_changed_frames_;
  return out;
}

std::vector<Outgoing> NatNetServer::garbage(std::size_t count) {
  std::vector<Endpoint> destinations;
  if (options_.mode == ServeMode::kMulticast) destinations.push_back({group_, options_.data_port});
  for (const auto& [address, client] : clients_)
    destinations.push_back({address.first, options_.mode == ServeMode::kUnicast ? address.second : options_.data_port});
  std::vector<Outgoing> out;
  std::uniform_int_distribution<int> byte(0, 255), length(0, 600);
  for (std::size_t i = 0; i < count && !destinations.empty(); ++i) {
    std::vector<char> bytes;
    const auto payload = [&](std::size_t n) {
      for (std::size_t j = 0; j < n; ++j) bytes.push_back(char(byte(garbage_rng_)));
    };
    const auto header = [&](nn::MessageId id, uint16_t size) {
      bytes = {char(uint16_t(id) & 0xff), char(uint16_t(id) >> 8), char(size & 0xff), char(size >> 8)};
    };
    switch (counts_.garbage % 4) {
      case 0: payload(std::size_t(length(garbage_rng_))); break;
      case 1: header(nn::MessageId::kFrameOfData, 400), payload(100); break;
      case 2: header(nn::MessageId::kKeepAlive, 0), payload(8); break;
      case 3: header(nn::MessageId::kFrameOfData, 8), bytes.insert(bytes.end(), {1, 0, 0, 0, char(0xff), char(0xff), 0, 0}); break;
    }
    out.push_back({destinations[counts_.garbage % destinations.size()], std::move(bytes)});
    ++counts_.garbage;
  }
  return out;
}

void NatNetServer::restart() {
  frame_number_ = 1;
  clients_.clear();
  models_changed_frames_ = kModelsChangedFrames;
}

int NatNetServer::run() {
  using drivers::natnet::UdpSocket;
  UdpSocket socket(drivers::natnet::parse_ipv4(options_.address, "--address"), options_.command_port, false,
                   "natnet-serve command socket");
  if (options_.mode == ServeMode::kMulticast)
    socket.set_multicast_sender(drivers::natnet::resolve_interface(options_.interface), options_.ttl);
  socket.enable_broadcast();  // discovery replies to broadcast senders
  std::signal(SIGINT, on_stop_signal);
  std::signal(SIGTERM, on_stop_signal);
  std::signal(SIGUSR1, on_restart_signal);
  std::signal(SIGUSR2, on_silence_signal);

  const std::string destination =
      options_.mode == ServeMode::kMulticast ? fmt::format("to {}:{}", drivers::natnet::ipv4_string(group_), options_.data_port)
      : options_.mode == ServeMode::kUnicast ? std::string("to each client's command socket")
                                              : fmt::format("to each client's host at port {}", options_.data_port);
  fmt::print("natnet-serve: {} markers as {} at {:g} Hz, bitstream {}, {} {}; commands on {}:{}\n", take_.labels.size(),
             options_.unlabelled ? "unlabelled points" : fmt::format("marker sets {}", fmt::join(set_names_, ", ")),
             rate_hz_, options_.bitstream.major_minor(), kServeModes.name(options_.mode), destination, options_.address,
             options_.command_port);
  std::fflush(stdout);

  const int64_t period_ns = int64_t(std::llround(double(kNsPerSecond) / rate_hz_));
  const int64_t start_ns = monotonic_now_ns();
  const auto at = [&](double s) { return start_ns + int64_t(s * kNsPerSecond); };
  const int64_t end_ns = options_.seconds > 0 ? at(options_.seconds) : INT64_MAX;
  int64_t silence_from = options_.silence_for_s > 0 && options_.silence_at_s > 0 ? at(options_.silence_at_s) : INT64_MAX;
  int64_t silence_until = silence_from == INT64_MAX ? 0 : at(options_.silence_at_s + options_.silence_for_s);
  bool restarted = options_.restart_at_s <= 0;
  bool silent = false;
  int64_t due_ns = start_ns;
  std::vector<char> buffer(nn::kHeaderBytes + nn::kMaxPayloadBytes + 1);
  const auto send_all = [&](const std::vector<Outgoing>& out) {
    for (const Outgoing& o : out) socket.send_to(o.bytes, o.to);
  };

  while (!g_stop.load()) {
    int64_t now = monotonic_now_ns();
    if (now >= end_ns) break;
    if (g_silence.exchange(false)) {
      silence_from = now;
      silence_until = now + int64_t(options_.silence_for_s * kNsPerSecond);
    }
    const bool quiet = now >= silence_from && now < silence_until;
    if (quiet != silent) {
      silent = quiet;
      fmt::print("natnet-serve: {} at {:.1f} s\n", silent ? "falling silent" : "streaming again",
                 double(now - start_ns) / kNsPerSecond);
      std::fflush(stdout);
    }
    if ((!restarted && now >= at(options_.restart_at_s)) || g_restart.exchange(false)) {
      restarted = true;
      restart();
      fmt::print("natnet-serve: restarted at {:.1f} s (frame numbers from 1, clients forgotten)\n",
                 double(now - start_ns) / kNsPerSecond);
      std::fflush(stdout);
    }
    if (options_.garbage_rate > 0 && !silent) {
      const auto due = uint64_t(double(now - start_ns) / kNsPerSecond * options_.garbage_rate);
      if (due > counts_.garbage) send_all(garbage(std::size_t(due - counts_.garbage)));
    }
    if (now >= due_ns) {
      if (!options_.loop && next_index_ >= take_.frames.size()) break;
      if (!silent) send_all(next_frame(due_ns, now));
      else ++next_index_, ++frame_number_;  // time passes while silent: frame numbers move on
      due_ns += period_ns;
      if (now - due_ns > period_ns) {  // fell behind: skip to the next due time
        const int64_t skipped = (now - due_ns) / period_ns;
        counts_.late_frames += uint64_t(skipped);
        due_ns += skipped * period_ns;
      }
    }
    now = monotonic_now_ns();
    const int64_t wake_ns = std::min({due_ns, end_ns, options_.garbage_rate > 0 ? now + kGarbageSliceNs : INT64_MAX});
    if (!drivers::natnet::wait_readable(socket, nullptr, std::max<int64_t>(0, wake_ns - now))) continue;
    while (const auto datagram = socket.receive(buffer)) {
      if (silent) continue;
      send_all(answer(std::span<const char>(buffer.data(), datagram->size), datagram->from, monotonic_now_ns()));
    }
  }
  fmt::print("natnet-serve: {} frames streamed ({} datagrams), {} requests answered, {} bad requests, {} frame times "
             "skipped, {} bad datagrams sent\n",
             counts_.frames, counts_.packets, counts_.requests, counts_.bad_requests, counts_.late_frames, counts_.garbage);
  return 0;
}

}  // namespace facecap::tools
