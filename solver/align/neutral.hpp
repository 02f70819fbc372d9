#pragma once
// Finding the most neutral stretch of a take for calibration (`calibrate --auto-neutral`):
// the face at rest is still and looks like the take's typical resting shape. Each frame
// whose head pose fits is stabilised on the stable markers (marker slots present in fewer
// than half of the frames, a ghost slot or a marker lost for most of the take, are
// ignored: mostly_present_slots); per frame the RMS speed of the markers present (mm/s,
// over 50 ms) and the largest distance of a present marker (mm) to its median position
// over the stillest 30% of frames are measured. Among the windows (window_seconds) where
// each marker is present in at least min_presence of the frames (markers drop out on a
// real stage), the one with the lowest mean of distance + speed_weight_s x speed wins,
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
  double min_presence = 0.8;        // fraction of the window's frames each marker must be present in
};

struct NeutralFrame {
  std::size_t frame_index = 0;   // index into frames
  std::size_t window_start = 0;  // the chosen stretch: frames [window_start, window_start + window_frames)
  std::size_t window_frames = 0;
  double distance_mm = 0.0;      // largest marker distance of that frame to the median shape
  double speed_mm_s = 0.0;       // mean RMS marker speed over the chosen window
  double window_score = 0.0;
  std::size_t candidate_frames = 0;  // frames whose head pose fits
};

// stable_slots: markers for stabilisation (>= 3), e.g. from find_stable_markers. Throws
// Error when no frame has every stable marker, the take is shorter than the window, no
// window has each marker present often enough (the message names the markers too often
// missing and their best presence) or no stretch is neutral-looking (the message gives the
// best stretch's figures).
NeutralFrame find_neutral_frame(std::span<const MarkerFrame> frames, std::span<const int> stable_slots,
                                const NeutralSearchOptions& options = {});

// Robust mean marker positions over frames [first, first + count), each frame first moved
// onto frame `anchor` by a rigid fit of the stable markers, so the average is taken in the
// anchor frame's coordinates; per marker, samples beyond 3 robust standard deviations of
// its median (a swap, a jump) are left out. Averaging a still stretch divides the capture
// noise by about sqrt(count) before calibration. present (K) says which markers were
// present in at least min_presence of the frames; the others are NaN. Frames whose head
// pose cannot be fitted are skipped. Throws Error on bad ranges or when the anchor frame
// lacks a stable marker.
Eigen::Matrix3Xd average_positions(std::span<const MarkerFrame> frames, std::size_t first, std::size_t count,
                                   std::size_t anchor, std::span<const int> stable_slots, double min_presence,
                                   std::vector<uint8_t>& present);

}  // namespace facecap::align
