#pragma once
// The recordings in facecapd's recording directory, for the dashboard's replay page
// (GET /recordings, GET /recordings/frames; docs/control-api.md): what each holds, and a
// run of one's solved frames as the stream's frame messages, so that a recorded take is
// drawn by the same view as the live one. Runs on a worker thread (it maps and decodes
// files); never on the solve or I/O thread. Not real-time code.
#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "control/commands.hpp"

namespace facecap::control {

// The most frames one GET /recordings/frames answers (each may carry the mesh).
inline constexpr std::size_t kMaxRecordingFramesPerRequest = 60;
// The most mesh vertices one answer carries (a few MB of JSON): with a large mesh it holds
// fewer frames than asked, so that its size does not grow with count x the mesh.
inline constexpr std::size_t kMaxRecordingVerticesPerReply = 200'000;

// {"directory", "recordings": [{"name", "file", "bytes", "take", "actor", "scene", "shot",
// "notes", "rig", "rate_hz", "created_unix_ns", "marker_frames", "solved_frames",
// "seconds", "vertices", "truncated"} | {"name", "file", "error"}]}, newest first.
Reply list_recordings(const std::string& directory);

// The running rig, for drawing a recording solved on it.
struct ReplayRig {
  uint64_t hash = 0;
  uint32_t vertex_count = 0;
  std::vector<int32_t> triangles;  // 3 vertex indices each
  // The mesh for a recorded frame that kept only its weights: x0 + B w (3 x N, rig units).
  std::function<void(const Eigen::VectorXf& weights, Eigen::Matrix3Xf& vertices)> blend;
};

// {"schema": the stream's schema message for the recording (the mesh only when it was
// solved on `rig`), "vertices_from": "recorded" | "blend" | "none", "solved_frames",
// "frames": [frame messages of solved frames first, first + step, ... (at most count, and
// at most kMaxRecordingVerticesPerReply vertices in all, at least one frame)]}.
// 404: no such recording; 416: `first` is past its last solved frame; 422: unreadable.
Reply recording_frames(const std::string& directory, const ReadRecording& request, const ReplayRig& rig);

}  // namespace facecap::control
