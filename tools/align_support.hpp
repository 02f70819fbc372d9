#pragma once
// What calibrate, solve and eval share: reading a take with its units, choosing the
// calibration frame, the solver list, and turning a calibration into a solver model and
// a per-frame marker mapper.
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "formats/take.hpp"
#include "solver/align/calibrate.hpp"
#include "solver/face_solver.hpp"
#include "solver/rig.hpp"

namespace facecap::tools {

// Millimetres per rig unit: the override ("mm", "cm", "m"), else guessed from the face's
// size. Throws Error when neither names a unit.
double rig_mm_per_unit(const Rig& rig, const std::string& override_units);

// Positions (3 x K) and presence flags of one frame.
Eigen::Matrix3Xd frame_positions(const MarkerFrame& frame, std::vector<uint8_t>& present);

// Index into take.frames of the frame whose number (as in the file) is frame_no.
std::size_t frame_index(const formats::MarkerTake& take, int64_t frame_no, const std::string& take_name);

}  // namespace facecap::tools
