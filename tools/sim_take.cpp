// facecap sim-take: writes what facecapd's sim source would deliver (same configuration
// keys: rig, calibration, source.sim) as a marker take, for replays and benchmarks.
#include <cmath>
#include <filesystem>

#include <fmt/format.h>

#include "config/config_file.hpp"
#include "core/error.hpp"
#include "daemon/calibration.hpp"
#include "drivers/sim/sim_source.hpp"
#include "formats/take.hpp"
#include "tools/commands.hpp"
#include "tools/progress.hpp"

namespace facecap::tools {

void add_sim_take_command(CLI::App& app, int& exit_code) {
  struct Options {
    std::string output;
    std::string config;
    std::vector<std::string> overrides;
    double seconds = 10.0;
    bool force = false;
  };
  auto opts = std::make_shared<Options>();
  auto* cmd = app.add_subcommand("sim-take", "Write the frames facecapd's sim source would deliver as a marker take");
  cmd->add_option("out", opts->output, "Output take; the extension picks the format (.fcrec, .c3d, .trc)")->required();
  cmd->add_option("--seconds", opts->seconds, "Length of the take")->capture_default_str();
  cmd->add_option("--config", opts->config, "facecapd configuration (rig, calibration, source.sim)");
  cmd->add_option("--set", opts->overrides, "Override a facecapd key, e.g. --set source.sim.rate_hz=240 (repeatable)");
  cmd->add_flag("--force", opts->force, "Replace the output file if it exists");
  cmd->callback([opts, &exit_code] {
    const std::filesystem::path output(opts->output);
    if (!opts->force && std::filesystem::exists(output)) throw file_error(output.string(), "exists; pass --force to replace it");
    const config::LoadedConfig loaded = config::load_config(opts->config, opts->overrides);
    const config::DaemonConfig& c = loaded.values;
    RigLoadOptions rig_options;
    rig_options.use_cache = c.rig.cache;
    auto rig = std::make_shared<const Rig>(load_rig(c.rig.path, rig_options));
    const daemon::MarkerCalibration calibration = daemon::load_calibration(c.calibration, *rig);
    drivers::SimSource sim(c.source.sim, rig, calibration.markers);
    sim.open();

    formats::MarkerTake take;
    take.format = formats::format_from_extension(output).value_or(formats::TakeFormat::kRecording);
    take.labels = sim.info().labels;
    take.rate_hz = c.source.sim.rate_hz;
    take.units = sim.info().units;
    take.first_frame = 0;
    take.metadata.emplace_back("source", sim.description());
    const auto frame_count = std::size_t(std::llround(opts->seconds * c.source.sim.rate_hz));
    take.frames.reserve(frame_count);
    ProgressBar bar("simulating", stderr_is_terminal() && frame_count > 1000);
    for (std::size_t i = 0; i < frame_count; ++i) {
      MarkerFrame frame = drivers::make_marker_frame(take.labels);
      sim.render_frame(int64_t(i), frame);
      take.frames.push_back(std::move(frame));
      bar.update(i + 1, frame_count);
    }
    bar.finish();
    formats::write_take(output, take);
    fmt::print("{}: {} frames of {} markers at {:g} Hz ({})\n", output.string(), frame_count, take.labels.size(),
               take.rate_hz, sim.description());
    exit_code = 0;
  });
}

}  // namespace facecap::tools
