#pragma once
// Whether a take's values are in the units it states. The marker mapper converts frames
// from the units they state to the calibration's; a take whose header says mm while its
// values are cm would be solved 10 times too small (a face frozen at the neutral, a head
// metres away) with no warning. The calibration knows the actor's face in its own units
// (the markers' neutral positions), so a take of the same actor must be about that size
// once converted: one read in the wrong units is off by a factor of 10 or more.
// Not real-time code.
#include <optional>
#include <string>
#include <string_view>

#include "formats/take.hpp"
#include "solver/align/calibration.hpp"

namespace facecap::pipeline {

struct UnitsCheck {
  double stated_mm_per_unit = 0.0;  // the units the frames are read in (the calibration's when unstated or unknown)
  // The take's face size over the calibration's, both in mm, for the markers they share
  // (median over frames of the RMS distance from their centre); 0 when no frame has 3 of them.
  double size_ratio = 0.0;
  // When the size is implausible: the unit (mm, cm or m) that gives the calibration's size,
  // if one does within the band.
  std::optional<std::string> looks_like;
  bool plausible = true;
};

// A take read in `units` (empty: as it states them) against the calibration. Its face may be
// kMaxSizeRatio times larger or smaller than the calibrated one (expressions, a
// different actor on the same profile); a wrong unit is a factor of 10.
inline constexpr double kMaxSizeRatio = 2.0;
UnitsCheck check_take_units(const formats::MarkerTake& take, std::string_view units, const align::Calibration& calibration);

// Throws Error naming `name` when check_take_units finds the take implausible, saying the
// units it looks like and how to say so (`--units`).
void require_plausible_units(const formats::MarkerTake& take, std::string_view units, const align::Calibration& calibration,
                             const std::string& name);

}  // namespace facecap::pipeline
