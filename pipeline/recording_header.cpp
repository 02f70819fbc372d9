#include "pipeline/recording_header.hpp"

#include <algorithm>

#include "core/units.hpp"
#include "solver/align/profile.hpp"

namespace facecap::pipeline {

formats::RecordingHeader make_recording_header(const Rig& rig, const align::Calibration& calibration,
                                               const SourceDescription& source, std::string source_description,
                                               double rate_hz, std::string solver_settings) {
  formats::RecordingHeader h;
  h.rig_name = rig.name;
  h.rig_hash = rig.content_hash();
  h.rig_units = unit_name(calibration.rig_mm_per_unit);
  h.source_description = std::move(source_description);
  h.calibration = align::write_calibration_profile(calibration);
  h.units = source.units;
  h.rate_hz = rate_hz;
  h.marker_labels = source.labels;
  h.shape_names = rig.shape_names;
  h.solver_settings = std::move(solver_settings);
  return h;
}

double recorded_rate_hz(double source_rate_hz, double loop_rate_hz, bool lockstep) {
  if (source_rate_hz <= 0.0) return 0.0;
  return lockstep ? source_rate_hz : std::min(source_rate_hz, loop_rate_hz);
}

}  // namespace facecap::pipeline
