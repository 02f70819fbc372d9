#pragma once
// The calibration profile: a versioned TOML file holding everything calibrate()
// measured, so that an actor is calibrated once and their takes solved any time later.
// Layout (docs/alignment.md):
//
//   version = 1
//   checksum = "fnv1a64:<16 hex>"     # of every other line; remove it to accept hand edits
//   [rig]        name, content_hash, units
//   [source]     take, frame, units, units_detected
//   [transform]  scale, rotation (3 rows), translation: rig = scale * rotation * take + translation
//   [fit]        hull_rms_mm, trimmed_rms_mm, start
//   [stabilise]  markers = [labels]
//   [[marker]]   label, vertices, barycentric, neutral (take units), bound_point (rig),
//                offset (rig: transform(neutral) - bound_point, the identity mismatch), residual_mm
//   [[head_marker]] label, neutral (take units): a head-rig marker, for the head pose only (version 2)
//   [observability] threshold_mm; [[unobserved_shape]] name, max_displacement_mm: the shapes
//                left out of the weight fit and why (version 3; older profiles have none,
//                and the reader leaves observability_known false)
//   notes = [...]
//
// Reading is strict: unknown keys, wrong types, a bad checksum or a newer version are
// errors naming file:line. Not real-time.
#include <filesystem>
#include <string>
#include <string_view>

#include "solver/align/calibrate.hpp"
#include "solver/rig.hpp"

namespace facecap::align {

// 2: [[head_marker]] entries (written only by profiles that have them).
// 3: [observability] and [[unobserved_shape]] (written by profiles that decided them).
// 4: [observability] distinct_mm, [[unobserved_shape]] same_as and distinct_mm.
inline constexpr int kCalibrationProfileVersion = 4;

std::string write_calibration_profile(const Calibration& calibration);
void save_calibration_profile(const std::filesystem::path& path, const Calibration& calibration);

// name labels errors. Throws Error with file:line.
Calibration read_calibration_profile(std::string_view text, const std::string& name);
Calibration load_calibration_profile(const std::filesystem::path& path);

// Throws Error unless the profile was made for this rig (same content hash) and its
// bindings index the rig's triangles.
void check_profile_matches_rig(const Calibration& calibration, const Rig& rig, const std::string& profile_name);

}  // namespace facecap::align
