// facecap natnet-serve: streams a marker take as Motive would, over NatNet (tools/natnet_server.hpp).
#include <memory>

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include "core/error.hpp"
#include "formats/natnet_request.hpp"
#include "formats/take.hpp"
#include "tools/commands.hpp"
#include "tools/natnet_server.hpp"

namespace facecap::tools {
namespace {

struct NatNetServeOptions {
  std::string take;
  std::string bitstream = "4.1";
  std::string mode = "multicast";
  std::vector<std::string> marker_sets;
  ServeOptions serve;
};

int run_serve(NatNetServeOptions& o) {
  const auto bitstream = formats::natnet::parse_version(o.bitstream);
  if (!bitstream || !formats::natnet::is_supported_bitstream(*bitstream))
    throw Error(fmt::format("--bitstream {}: give 3.0, 3.1, 4.0, 4.1 or 4.2", o.bitstream));
  o.serve.bitstream = {bitstream->major, bitstream->minor};
  const auto mode = kServeModes.parse(o.mode);
  if (!mode) throw Error(fmt::format("--mode {}: give multicast, unicast or unicast-data-port", o.mode));
  o.serve.mode = *mode;
  for (const std::string& spec : o.marker_sets) {
    const auto equals = spec.find('=');
    o.serve.marker_sets.push_back(
        {spec.substr(0, equals), equals == std::string::npos ? std::string() : spec.substr(equals + 1)});
    if (o.serve.marker_sets.back().name.empty()) throw Error(fmt::format("--marker-set \"{}\" has no name", spec));
  }
  NatNetServer server(o.serve, formats::read_take(o.take));
  return server.run();
}

}  // namespace

void add_natnet_serve_command(CLI::App& app, int& exit_code) {
  auto o = std::make_shared<NatNetServeOptions>();
  auto* cmd = app.add_subcommand("natnet-serve", "Stream a take (C3D, TRC, .fcrec) over NatNet as OptiTrack Motive would");
  cmd->add_option("take", o->take, "The take to stream")->required()->check(CLI::ExistingFile);
  cmd->add_option("--rate", o->serve.rate_hz, "Frames per second (default: the take's)");
  cmd->add_flag("--loop", o->serve.loop, "Start again after the last frame");
  cmd->add_option("--seconds", o->serve.seconds, "Stop after this long (default: at the take's end, or never with --loop)");
  cmd->add_option("--mode", o->mode,
                  "multicast, unicast (frames to each client's command socket, as NatNet 4.x servers do) or "
                  "unicast-data-port (to each client's host at the data port, as 3.x servers do)")
      ->capture_default_str();
  cmd->add_option("--bitstream", o->bitstream, "NatNet version announced and streamed: 3.0, 3.1, 4.0, 4.1 or 4.2 (unicast "
                                               "clients may ask for another)")
      ->capture_default_str();
  cmd->add_option("--address", o->serve.address, "Address the command socket binds to")->capture_default_str();
  cmd->add_option("--command-port", o->serve.command_port, "Command port")->capture_default_str();
  cmd->add_option("--data-port", o->serve.data_port, "Data port (multicast, and 3.x-style unicast)")->capture_default_str();
  cmd->add_option("--multicast-group", o->serve.multicast_group, "Multicast group")->capture_default_str();
  cmd->add_option("--interface", o->serve.interface, "Interface multicast goes out of, by IPv4 address or name (lo)");
  cmd->add_option("--ttl", o->serve.ttl, "Multicast time-to-live (hops)")->capture_default_str();
  cmd->add_option("--marker-set", o->marker_sets,
                  "NAME[=PREFIX]: a marker set of the take's labels beginning with PREFIX, named without it "
                  "(repeatable: several actors in one stream); default: one set \"Face\" of every label");
  cmd->add_flag("--unlabelled", o->serve.unlabelled, "Stream every marker as an unlabelled point, in shuffled order");
  cmd->add_option("--exposure-latency-ms", o->serve.exposure_latency_ms,
                  "Stamp each frame's camera mid-exposure this long before it is due (a simulated camera latency)");
  cmd->add_option("--silence-at", o->serve.silence_at_s, "Fall silent (send and answer nothing) at this time, s");
  cmd->add_option("--silence-for", o->serve.silence_for_s, "... for this long, s (also after SIGUSR2, which silences now)");
  cmd->add_option("--first-frame", o->serve.first_frame, "The first frame's number")->capture_default_str();
  cmd->add_option("--garbage-rate", o->serve.garbage_rate,
                  "Also send this many bad datagrams a second where the frames go: random bytes, cut and overlong "
                  "packets, frames with impossible counts (robustness tests)");
  cmd->add_option("--restart-at", o->serve.restart_at_s,
                  "Restart at this time, s: frame numbers from 1, clients forgotten, \"models changed\" (SIGUSR1: "
                  "restart now)");
  cmd->callback([o, &exit_code] { exit_code = run_serve(*o); });
}

}  // namespace facecap::tools
