#pragma once
// Finding the most neutral stretch of a take for calibration (`calibrate --auto-neutral`):
// the face at rest is still and looks like the take's typical resting shape. Each frame
// with every marker present is stabilised on the stable markers (marker slots present in
// fewer than half of the frames, a ghost slot or a marker lost for most of the take, are
// ignored: mostly_present_slots); per frame the RMS
// marker speed (mm/s, over 50 ms) and the largest marker distance (mm) to the median shape of the
// stillest 30% of frames are measured; the
// window (window_seconds) with the lowest mean of distance + speed_weight_s x speed wins,
// and its frame closest to the median shape is returned. Not real-time.
#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "core/frame.hpp"

namespace facecap::align {

struct NeutralSearchOptions {
  double rate_hz = 60.0;
  double take_mm_per_unit = 10.0;
  double window_seconds = 0.25;
  double speed_weight_s = 0.05;     // 20 mm/s of motion counts like 1 mm off the median shape
  double max_distance_mm = 5.0;     // the best stretch must be this close to the median shape ...
  double max_speed_mm_s = 40.0;     // ... and this still, or the take has no neutral stretch
};

struct NeutralFrame {
  std::size_t frame_index = 0;   // index into frames
  std::size_t window_start = 0;  // the chosen stretch: frames [window_start, window_start + window_frames)
  std::size_t window_frames = 0;
  double distance_mm = 0.0;      // largest marker distance of that frame to the median shape
  double speed_mm_s = 0.0;       // mean RMS marker speed over the chosen window
  double window_score = 0.0;
  std::size_t candidate_frames = 0;  // frames with every marker present
};

// stable_slots: markers for stabilisation (>= 3), e.g. from find_stable_markers. Throws
// Error when no frame has every (mostly present) marker, the take is shorter than the window, or no
// stretch is neutral-looking (the message gives the best stretch's figures).
NeutralFrame find_neutral_frame(std::span<const MarkerFrame> frames, std::span<const int> stable_slots,
                                const NeutralSearchOptions& options = {});

// Mean marker positions over frames [first, first + count), each frame first moved onto
// frame `anchor` by a rigid fit of the stable markers, so the average is taken in the
// anchor frame's coordinates. Averaging a still stretch divides the capture noise by
// sqrt(count) before calibration. present (K) says which markers were present in at
// least half of the frames used. Frames whose head pose cannot be fitted are skipped.
// Throws Error on bad ranges or when the anchor frame lacks 3 stable markers.
Eigen::Matrix3Xd average_positions(std::span<const MarkerFrame> frames, std::size_t first, std::size_t count,
                                   std::size_t anchor, std::span<const int> stable_slots, std::vector<uint8_t>& present);

}  // namespace facecap::align
