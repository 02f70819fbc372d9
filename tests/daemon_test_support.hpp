#pragma once
// Helpers shared by the daemon tests.
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>

#include "solver/marker_layout.hpp"
#include "drivers/api/marker_source.hpp"
#include "drivers/sim/sim_source.hpp"
#include "formats/take.hpp"
#include "solver/rig.hpp"

namespace facecap::test {

// The sim source's first `frames` frames (its configuration `sim`, driving `rig` with
// `markers`) written to `file` as a 120 Hz recording: a take for the replay driver. It
// states the sim's units unless `units` says otherwise (the values stay the sim's).
inline void write_sim_take(const std::filesystem::path& file, const drivers::SimOptions& options,
                           std::shared_ptr<const Rig> rig, const MarkerSet& markers, int64_t frames,
                           const std::string& units = {}) {
  drivers::SimSource sim(options, std::move(rig), markers);
  sim.open();
  formats::MarkerTake take;
  take.format = formats::TakeFormat::kRecording;
  take.labels = sim.info().labels;
  take.rate_hz = 120;
  take.units = units.empty() ? sim.info().units : units;
  for (int64_t n = 0; n < frames; ++n) {
    MarkerFrame f = make_marker_frame(take.labels);
    sim.render_frame(n, f);
    take.frames.push_back(f);
  }
  formats::write_take(file, take);
}

}  // namespace facecap::test
