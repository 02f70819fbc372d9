#pragma once
// Helpers shared by the daemon tests.
#include <algorithm>
#include <cstdint>
#include <random>
#include <filesystem>
#include <memory>
#include <string>

#include <fmt/format.h>

#include "solver/marker_layout.hpp"
#include "drivers/api/marker_source.hpp"
#include "drivers/sim/sim_source.hpp"
#include "formats/take.hpp"
#include "solver/rig.hpp"

namespace facecap::test {

enum class SimTakeLabels {
  kNamed,      // the sim's marker names, each in its slot
  kUnlabelled  // slots "unlabelled_1", ... in an order shuffled every frame, every point
               // flagged kMarkerUnlabelled, as the camera driver records them
};

// The sim source's first `frames` frames (its configuration `sim`, driving `rig` with
// `markers`) written to `file` as a 120 Hz recording: a take for the replay driver. It
// states the sim's units unless `units` says otherwise (the values stay the sim's).
inline void write_sim_take(const std::filesystem::path& file, const drivers::SimOptions& options,
                           std::shared_ptr<const Rig> rig, const MarkerSet& markers, int64_t frames,
                           const std::string& units = {}, SimTakeLabels labels = SimTakeLabels::kNamed) {
  drivers::SimSource sim(options, std::move(rig), markers);
  sim.open();
  formats::MarkerTake take;
  take.format = formats::TakeFormat::kRecording;
  take.labels = sim.info().labels;
  if (labels == SimTakeLabels::kUnlabelled)
    for (std::size_t k = 0; k < take.labels.size(); ++k) take.labels[k] = fmt::format("unlabelled_{}", k + 1);
  take.rate_hz = 120;
  take.units = units.empty() ? sim.info().units : units;
  std::mt19937 shuffle(7);
  for (int64_t n = 0; n < frames; ++n) {
    MarkerFrame f = make_marker_frame(sim.info().labels);
    sim.render_frame(n, f);
    if (labels == SimTakeLabels::kUnlabelled) {
      std::shuffle(f.markers.begin(), f.markers.end(), shuffle);
      for (std::size_t k = 0; k < f.markers.size(); ++k) {
        f.markers[k].id = -1;
        f.markers[k].label = MarkerLabel(take.labels[k]);
        f.markers[k].flags |= kMarkerUnlabelled;
      }
    }
    take.frames.push_back(f);
  }
  formats::write_take(file, take);
}

}  // namespace facecap::test
