#pragma once
// facecapd's effective configuration. Member paths are the TOML key paths
// (config.loop.rate_hz is `[loop] rate_hz`): config/schema.cpp declares each key's type,
// default, unit, range and description from the member itself, so the two cannot drift.
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "core/enum_table.hpp"
#include "core/log.hpp"
#include "drivers/api/source_config.hpp"
#include "solver/params.hpp"

namespace facecap::config {

enum class LoopMode : uint8_t { kFixed, kLockstep };
inline constexpr EnumTable kLoopModes{std::array{
    EnumEntry{LoopMode::kFixed, "fixed", "at every tick, solve the newest frame (live sources, paced replay)"},
    EnumEntry{LoopMode::kLockstep, "lockstep",
              "solve every frame of the source in order as fast as possible (replay only; not real time)"},
}};

// When the temporal filter ([filter]) runs.
enum class FilterMode : uint8_t { kLive, kOn, kOff };
inline constexpr EnumTable kFilterModes{std::array{
    EnumEntry{FilterMode::kLive, "live", "on when facecapd solves a source, off in facecap solve and eval"},
    EnumEntry{FilterMode::kOn, "on", "always"},
    EnumEntry{FilterMode::kOff, "off", "never"},
}};

struct RigSection {
  std::string path;
  bool cache = true;
};

// calibration.marker_consistency_mm to turn the check on with (rig mm): about half a brow's
// marker spacing, well above the residual spread between neighbours on clean takes
// (docs/alignment.md "Label swaps"). Off by default: on clean takes it also leaves out
// markers that truly moved unlike their neighbours (EyebrowsMoCap's held-out p95 +3.1%).
inline constexpr double kSuggestedMarkerConsistencyMm = 10.0;

struct CalibrationSection {
  std::string file;
  std::string profiles_directory;
  int64_t face_markers = 0;
  int64_t head_markers = 0;
  bool stabilise_head = true;
  bool label_markers = false;
  double max_marker_speed_mm_s = 0.0;
  double neutral_min_presence = 0.0;
  double marker_consistency_mm = 0.0;
};

// The solver's parameters as the solver takes them (their initialisers are the defaults),
// and the method.
struct SolverSection : SolverParams {
  SolverMethod method = SolverMethod::kNonlinear;
};

// The One Euro filter on marker targets (and optionally on weights), pipeline/temporal_filter.hpp.
struct FilterSection {
  FilterMode mode = FilterMode::kLive;
  double min_cutoff_hz = 0.0;
  double beta = 0.0;  // Hz per mm/s
  double d_cutoff_hz = 0.0;
  bool weights = false;
  double weights_beta = 0.0;  // Hz per weight/s
};

struct LoopSection {
  double rate_hz = 0.0;
  LoopMode mode = LoopMode::kFixed;
  int64_t phase_margin_us = 0;
  int64_t prefetch_lead_us = 0;
  bool realtime = true;
  int64_t priority = 0;
  bool lock_memory = false;
  std::vector<int64_t> cpu_affinity;
};

struct ShmSection {
  bool enabled = true;
  std::string name;
  int64_t slots = 0;
  bool vertices = true;
};

struct RecordingSection {
  bool enabled = false;
  std::string directory;
  bool markers = true;
  bool solved = true;
  bool vertices = false;
  int64_t queue_frames = 0;
};
// What [outputs.vmc] calls the shapes it sends.
enum class VmcNames : uint8_t { kArkit, kRig, kMap };
inline constexpr EnumTable kVmcNames{std::array{
    EnumEntry{VmcNames::kArkit, "arkit",
              "the 52 ARKit names in PascalCase (\"perfect sync\": JawOpen, EyeBlinkLeft, ...), mapped from the rig's"},
    EnumEntry{VmcNames::kRig, "rig", "the rig's own shape names"},
    EnumEntry{VmcNames::kMap, "map", "the names outputs.vmc.map_file gives the rig's shapes"},
}};

// The keys every network output has.
struct NetworkOutput {
  bool enabled = false;
  std::string address;
  int64_t port = 0;
  double max_rate_hz = 0.0;
};

struct UdpSection : NetworkOutput {
  bool vertices = false;
  int64_t multicast_ttl = 0;
  std::string multicast_interface;
};

struct VmcSection : NetworkOutput {
  VmcNames names = VmcNames::kArkit;
  std::string map_file;
  bool root_pose = false;
  double root_scale = 0.0;
};

struct LiveLinkSection : NetworkOutput {
  std::string subject_name;
  std::string device_id;
};

struct OutputsSection {
  ShmSection shm;
  RecordingSection recording;
  UdpSection udp;
  VmcSection vmc;
  LiveLinkSection livelink;
};


struct HttpSection {
  bool enabled = false;
  std::string address;
  int64_t port = 0;
  std::string token_file;
  std::string viewer_token_file;
  std::string allowed_hosts;    // comma-separated
  std::string allowed_origins;  // comma-separated
  int64_t session_max_age_s = 0;
  std::string dashboard_dir;  // "": the built or installed dashboard (daemon/dashboard_location)
  int64_t max_connections = 0;
  int64_t max_connections_per_address = 0;
  int64_t max_stream_clients = 0;
  bool tls = false;
  std::string tls_certificate;  // PEM; made with tls_key on first start when neither exists
  std::string tls_key;
};

struct ControlSection {
  double status_interval_s = 0.0;
  double run_seconds = 0.0;
  HttpSection http;
};

// The capture-quality state's thresholds (good / degraded / bad), per status window.
struct QualitySection {
  double markers_used_degraded = 0.0;  // fractions of the calibration's face markers
  double markers_used_bad = 0.0;
  double head_held_degraded = 0.0;     // fractions of the solved frames
  double head_held_bad = 0.0;
  double residual_p95_degraded_mm = 0.0;
  double residual_p95_bad_mm = 0.0;
  double noise_degraded_mm = 0.0;      // the median marker's noise, per coordinate
  double noise_bad_mm = 0.0;
  double hold_s = 0.0;                 // a new state shows once it held this long
};

struct LoggingSection {
  LogLevel level = LogLevel::kInfo;
  double stats_interval_s = 0.0;
  std::string stats_file;
};

struct DaemonConfig {
  int64_t version = 0;
  drivers::SourceConfig source;
  RigSection rig;
  CalibrationSection calibration;
  SolverSection solver;
  FilterSection filter;
  LoopSection loop;
  OutputsSection outputs;
  ControlSection control;
  QualitySection quality;
  LoggingSection logging;
};

}  // namespace facecap::config
