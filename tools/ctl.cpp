// facecap ctl: drives a running facecapd through its control API (docs/control-api.md):
// status, metrics, actors, calibration on the box and takes.
#include <cstdio>
#include <memory>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "config/config_file.hpp"
#include "control/commands.hpp"
#include "control/http_client.hpp"
#include "core/error.hpp"
#include "core/io.hpp"
#include "core/printable.hpp"
#include "tools/commands.hpp"

namespace facecap::tools {
namespace {

using nlohmann::json;

// Text facecapd passes on from outside (take names, notes, NatNet server names), made safe
// for the terminal (core/printable.hpp).
std::string shown(const json& text) { return printable(text.get<std::string>()); }

struct CtlOptions {
  std::string config;  // facecapd.toml to take the address, port and token file from
  std::string address = "127.0.0.1";
  int port = 8765;
  std::string token_file;
  std::string tls_ca;  // HTTPS, trusting this certificate (facecapd's control.http.tls_certificate)
  bool json = false;
  // Commands' arguments.
  std::string actor_name, actor_file;
  double seconds = 3.0;
  std::string save;
  bool replace = false;
  control::StartRecording slate;
};

// The API's answer as JSON; throws Error with its message unless it is a 2xx.
json call(const CtlOptions& o, std::string_view method, std::string_view target, const json& body = nullptr) {
  std::string address = o.address, token_file = o.token_file, tls_ca = o.tls_ca;
  int port = o.port;
  if (!o.config.empty()) {
    const config::LoadedConfig loaded = config::load_config(o.config, {}, config::Checks::kValues);
    const config::HttpSection& http = loaded.values.control.http;
    address = http.address;
    port = int(http.port);
    if (token_file.empty()) token_file = http.token_file;
    if (tls_ca.empty() && http.tls) tls_ca = http.tls_certificate;
  }
  std::string token;
  if (!token_file.empty()) {
    const std::vector<char> bytes = read_file_bytes(token_file);
    token.assign(bytes.begin(), bytes.end());
    token.erase(token.find_last_not_of(" \t\r\n") + 1);
    token.erase(0, token.find_first_not_of(" \t\r\n"));
  }
  // A box listening on every address is asked on loopback.
  if (address == "0.0.0.0") address = "127.0.0.1";
  if (address == "::") address = "::1";
  control::HttpClient client(address, uint16_t(port), token, 120.0, tls_ca);
  const control::HttpResult result = client.request(method, target, body.is_null() ? std::string() : body.dump());
  if (result.content_type.rfind("text/plain", 0) == 0 && result.status == 200) return result.body;
  json answer = json::parse(result.body, nullptr, false);
  if (result.status / 100 != 2) {
    const std::string what = answer.is_object() && answer.contains("error") ? shown(answer["error"]) : printable(result.body);
    throw Error(fmt::format("{} {}: {} (HTTP {})", method, target, what, result.status));
  }
  if (answer.is_discarded()) throw Error(fmt::format("{} {}: the answer is not JSON", method, target));
  return answer;
}

void print_json(const json& j) { std::puts(j.dump(2).c_str()); }

void print_status(const json& s) {
  const json& w = s["window"];
  const json& t = s["totals"];
  fmt::print("{}, pid {}, up {:.1f} s{}\n", shown(s["version"]).empty() ? "facecapd" : shown(s["version"]),
             s["pid"].get<int64_t>(), s["uptime_s"].get<double>(),
             shown(s["busy"]).empty() ? "" : fmt::format("; busy {}", shown(s["busy"])));
  fmt::print("source     {}\n", shown(s["source"]["description"]));
  fmt::print("rig        {} ({} vertices, {} shapes), solver {}\n", shown(s["rig"]["name"]),
             s["rig"]["vertices"].get<int64_t>(), s["rig"]["shapes"].get<int64_t>(), shown(s["solver"]));
  const json& c = s["calibration"];
  fmt::print("actor      {} (calibration {}: {} markers, {} in the source, head {})\n",
             shown(s["actor"]).empty() ? "none" : shown(s["actor"]), shown(c["source"]),
             c["markers"].get<uint64_t>(), c["markers_in_source"].get<uint64_t>(),
             c["head_stabilised"].get<bool>() ? "stabilised" : "not stabilised");
  fmt::print("loop       {} {:g} Hz: {:.1f} fps, latency p50 {:.2f} p99 {:.2f} ms, {} missed deadlines ({} in the last {:.1f} s)\n",
             shown(s["loop"]["mode"]), s["loop"]["rate_hz"].get<double>(), w["solved_fps"].get<double>(),
             w["latency_ms"]["p50"].get<double>(), w["latency_ms"]["p99"].get<double>(), t["missed_deadlines"].get<uint64_t>(),
             w["missed_deadlines"].get<uint64_t>(), w["seconds"].get<double>());
  std::string quality = shown(w["quality"]);
  for (const auto& reason : w["quality_reasons"]) quality += (quality.find(':') == std::string::npos ? ": " : ", ") + shown(reason);
  fmt::print("capture    {}\n           markers {:.1f} of {:.0f}, head held {:.0f}%, face held {:.0f}%, fit residual p50 {:.2f} p95 {:.2f} max {:.2f} mm\n",
             quality, w["markers_used"].get<double>(), w["markers_expected"].get<double>(),
             100 * w["head_held_fraction"].get<double>(), 100 * w["face_held_fraction"].get<double>(),
             w["residual_mm"]["p50"].get<double>(), w["residual_mm"]["p95"].get<double>(), w["residual_mm"]["max"].get<double>());
  std::string flagged;
  for (const auto& [name, count] : t["flagged_frames"].items())
    if (count.get<uint64_t>() > 0) flagged += fmt::format("{}{} {}", flagged.empty() ? "" : ", ", name, count.get<uint64_t>());
  if (!flagged.empty()) fmt::print("flagged    {}\n", flagged);
  for (const auto& o : s["outputs"])
    fmt::print("output     {}: {} offered, {} delivered, {} dropped, {} errors; offer p99 {:.1f} us\n", shown(o["name"]),
               o["offered"].get<uint64_t>(), o["delivered"].get<uint64_t>(), o["dropped"].get<uint64_t>(),
               o["errors"].get<uint64_t>(), o["offer_us"]["p99"].get<double>());
  const json& r = s["recording"];
  if (r["active"].get<bool>())
    fmt::print("recording  take {} ({:.1f} s, {} frames, {} dropped) to {}\n", shown(r["take"]), r["seconds"].get<double>(),
               r["frames_written"].get<uint64_t>(), r["frames_dropped"].get<uint64_t>(), shown(r["file"]));
  else
    fmt::print("recording  no take\n");
}

}  // namespace

void add_ctl_command(CLI::App& app, int& exit_code) {
  auto o = std::make_shared<CtlOptions>();
  auto* ctl = app.add_subcommand("ctl", "Drive a running facecapd through its control API (docs/control-api.md)");
  ctl->require_subcommand(1);
  // ctl's options after a subcommand too (`facecap ctl record stop --json`): subcommands
  // made below inherit this.
  ctl->fallthrough();
  ctl->add_option("--config", o->config, "facecapd.toml to take control.http's address, port and token file from")
      ->check(CLI::ExistingFile);
  ctl->add_option("--address", o->address, "Address of facecapd's control API")->capture_default_str();
  ctl->add_option("--port", o->port, "Port of facecapd's control API")->capture_default_str()->check(CLI::Range(1, 65535));
  ctl->add_option("--token-file", o->token_file, "File holding the bearer token")->check(CLI::ExistingFile);
  ctl->add_option("--tls-ca", o->tls_ca,
                  "Speak HTTPS, trusting this certificate (facecapd's control.http.tls_certificate; with --config and "
                  "control.http.tls on, that file)")
      ->check(CLI::ExistingFile);
  ctl->add_flag("--json", o->json, "Print the API's JSON answer");
  auto done = [o, &exit_code](const json& answer, auto&& print) {
    if (o->json) print_json(answer);
    else print(answer);
    exit_code = 0;
  };

  ctl->add_subcommand("status", "What facecapd is doing: rate, latency, capture quality, outputs, the take")
      ->callback([o, done] { done(call(*o, "GET", "/status"), print_status); });
  ctl->add_subcommand("metrics", "The Prometheus metrics, as text")->callback([o, done] {
    const json text = call(*o, "GET", "/metrics");
    done(text, [](const json& t) { std::fputs(t.get<std::string>().c_str(), stdout); });
  });
  ctl->add_subcommand("actors", "The actor profiles facecapd can load")->callback([o, done] {
    done(call(*o, "GET", "/actors"), [](const json& a) {
      fmt::print("profiles in {} (current: {})\n", shown(a["directory"]),
                 shown(a["current"]).empty() ? "none" : shown(a["current"]));
      for (const auto& actor : a["actors"])
        fmt::print("  {:<24} {}\n", shown(actor["name"]),
                   actor["usable"].get<bool>() ? fmt::format("{} markers, from {}", actor["markers"].get<uint64_t>(),
                                                             shown(actor["calibrated_from"]))
                                               : "unusable: " + shown(actor["error"]));
    });
  });
  auto* actor = ctl->add_subcommand("actor", "Solve with an actor's profile from now on (no restart, no frame lost)");
  actor->add_option("name", o->actor_name, "Profile name (in calibration.profiles_directory)");
  actor->add_option("--file", o->actor_file, "A profile or calibration file of calibration.profiles_directory instead, by its file name");
  actor->callback([o, done] {
    json body = o->actor_file.empty() ? json{{"name", o->actor_name}} : json{{"file", o->actor_file}};
    done(call(*o, "POST", "/actor", body), [](const json& a) {
      fmt::print("actor {}: {} markers, {} in the source, head {} (built in {:.2f} s)\n", shown(a["actor"]),
                 a["markers"].get<uint64_t>(), a["markers_in_source"].get<uint64_t>(),
                 a["head_stabilised"].get<bool>() ? "stabilised" : "not stabilised", a["build_seconds"].get<double>());
    });
  });
  auto* calibrate = ctl->add_subcommand("calibrate", "Capture the actor's neutral from the live source, calibrate, swap it in");
  calibrate->add_option("--seconds", o->seconds, "How long to capture (the actor holds a neutral face)")->capture_default_str();
  calibrate->add_option("--save", o->save, "Save the calibration as this actor's profile");
  calibrate->add_flag("--force", o->replace, "Replace the --save profile if it exists, keeping the old one as NAME.toml.bak");
  calibrate->callback([o, done] {
    json body = {{"seconds", o->seconds}};
    if (!o->save.empty()) body["save"] = o->save;
    if (o->replace) body["replace"] = true;
    done(call(*o, "POST", "/calibrate", body), [](const json& c) {
      fmt::print("calibrated from {} ({} frames, neutral at frame {}, {} averaged): units {}, surface ICP {:.2f} mm\n",
                 shown(c["capture"]), c["frames"].get<uint64_t>(), c["neutral_frame"].get<int64_t>(),
                 c["averaged_frames"].get<uint64_t>(), shown(c["units"]), c["trimmed_rms_mm"].get<double>());
      for (const auto& [label, residual] : c["marker_residual_mm"].items())
        fmt::print("  {:<24} {:7.2f} mm\n", printable(label), residual.get<double>());
      fmt::print("residual median {:.2f} mm, max {:.2f} mm; {} markers, head {}; {}\n", c["residual_mm"]["median"].get<double>(),
                 c["residual_mm"]["max"].get<double>(), c["markers"].get<uint64_t>(),
                 c["head_stabilised"].get<bool>() ? "stabilised" : "not stabilised",
                 c["profile"].is_null() ? std::string("not saved") : "saved as " + shown(c["profile"]));
      if (!c["backup"].is_null()) fmt::print("the old profile is kept as {}\n", shown(c["backup"]));
      for (const auto& w : c["warnings"]) fmt::print("warning: {}\n", shown(w));
      for (const auto& n : c["notes"]) fmt::print("note: {}\n", shown(n));
    });
  });
  auto* record = ctl->add_subcommand("record", "Start or stop a take");
  record->require_subcommand(1);
  auto* start = record->add_subcommand("start", "Record a take (file named from the slate)");
  start->add_option("take", o->slate.take, "The take's name or number (default: the scene and shot's next number)");
  start->add_option("--actor", o->slate.actor, "Actor (default: the current actor's name)");
  start->add_option("--scene", o->slate.scene, "Scene");
  start->add_option("--shot", o->slate.shot, "Shot");
  start->add_option("--notes", o->slate.notes, "Notes");
  start->add_flag("--markers-only", o->slate.markers_only, "Record raw markers only (a new actor with no profile yet)");
  start->callback([o, done] {
    const control::StartRecording& s = o->slate;
    json body = {{"take", s.take}, {"markers_only", s.markers_only}};
    for (const auto& [key, value] : {std::pair{"actor", s.actor}, {"scene", s.scene}, {"shot", s.shot}, {"notes", s.notes}})
      if (!value.empty()) body[key] = value;
    done(call(*o, "POST", "/record/start", body), [](const json& r) {
      fmt::print("recording take {} to {} ({:g} Hz{})\n", shown(r["take"]), shown(r["file"]),
                 r["rate_hz"].get<double>(), r["markers_only"].get<bool>() ? ", markers only" : "");
    });
  });
  record->add_subcommand("stop", "Stop the take and close its file")->callback([o, done] {
    done(call(*o, "POST", "/record/stop", json::object()), [](const json& r) {
      fmt::print("take {} stopped after {:.1f} s: {} marker frames, {} solved frames, {} dropped, in {}\n",
                 shown(r["take"]), r["seconds"].get<double>(), r["marker_frames"].get<uint64_t>(),
                 r["solved_frames"].get<uint64_t>(), r["dropped"].get<uint64_t>(), shown(r["file"]));
    });
  });
}

}  // namespace facecap::tools
