#pragma once
// Calibrated IR cameras as a marker source (docs/cameras.md): the driver's thread takes
// each camera's images as they come (V4L2 by default, any CameraFeed in tests), finds the
// markers' blobs at once, gathers one image per camera whose timestamps agree into a set,
// triangulates the set into 3D points and hands them on as a MarkerFrame of unlabelled
// points (kMarkerUnlabelled, slots "unlabelled_1" ... up to max_points): which marker is
// which is for the labeller downstream.
#include <atomic>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "drivers/api/marker_source.hpp"
#include "drivers/api/source_config.hpp"
#include "drivers/v4l2/camera_feed.hpp"
#include "drivers/v4l2/camera_pipeline.hpp"

namespace facecap::drivers {

class V4l2Source final : public MailboxSource {
 public:
  // feed: the cameras' images, in the calibration's camera order; nullptr opens the V4L2
  // devices options.devices names. Not RT-safe.
  explicit V4l2Source(V4l2Options options, std::unique_ptr<v4l2::CameraFeed> feed = nullptr);
  ~V4l2Source() override;

  // Reads the calibration and opens every camera. Throws Error naming the file or the
  // camera's device and what the driver needs. Not RT-safe.
  void open() override;
  const SourceInfo& info() const noexcept override { return info_; }
  void start(const SourceStart& start) override;
  void stop() noexcept override;
  std::string description() const override;

  // Slot labels, as the NatNet driver names its unlabelled slots: "unlabelled_1", ...
  static std::string unlabelled_label(std::size_t index);

  // Frame sets triangulated, camera images that found no set, and points beyond
  // max_points dropped. RT-safe.
  uint64_t frame_sets() const noexcept { return sets_.load(std::memory_order_relaxed); }
  uint64_t images_unmatched() const noexcept { return unmatched_.load(std::memory_order_relaxed); }
  uint64_t points_dropped() const noexcept { return points_dropped_.load(std::memory_order_relaxed); }

 private:
  void run();
  bool recover(std::string why);
  void publish(int64_t set_time_ns);

  V4l2Options options_;
  std::unique_ptr<v4l2::CameraFeed> feed_;
  SourceInfo info_;
  std::unique_ptr<v4l2::CameraPipeline> pipeline_;
  std::unique_ptr<v4l2::FrameSetMatcher> matcher_;
  std::vector<Eigen::Vector3d> points_;
  std::vector<std::string> camera_names_;
  std::thread thread_;
  std::atomic<bool> running_{false};
  std::atomic<uint64_t> sets_{0}, unmatched_{0}, points_dropped_{0};
};

}  // namespace facecap::drivers
