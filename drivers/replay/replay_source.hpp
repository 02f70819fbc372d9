#pragma once
// Plays a recorded take (C3D, TRC or a facecapd recording) as a marker source, or a
// packet capture of NatNet traffic: its datagrams through the NatNet parser and the
// driver's frame conversion (formats/natnet_markers.hpp) with the NatNet options' marker
// selection, each frame at its capture time. The take is read whole at open(); the loop
// then pulls frames by time (speed, window, loop, source timestamps) or, in lockstep, one
// after another as fast as it solves them.
#include <atomic>
#include <vector>

#include "drivers/api/marker_source.hpp"
#include "drivers/api/source_config.hpp"
#include "formats/take.hpp"

namespace facecap::drivers {

class ReplaySource final : public MarkerSource {
 public:
  // `natnet`: which markers of a NatNet capture to take (marker set, unlabelled slots).
  ReplaySource(ReplayOptions options, NatNetOptions natnet = {});

  void open() override;
  const SourceInfo& info() const noexcept override { return info_; }
  void start(const SourceStart& start) override;
  void stop() noexcept override {}
  // Paced: the newest frame whose play time has come (frames passed over are counted
  // late). Speed 0 or lockstep: the next frame. RT-safe.
  bool take_frame(int64_t now_ns, MarkerFrame& out) noexcept override;
  std::string description() const override;
  SourceHealth health() const noexcept override;
  std::span<const MarkerFrame> recorded_frames() const noexcept override {
    return std::span<const MarkerFrame>(take_.frames).subspan(begin_, end_ - begin_);
  }

  std::size_t window_frames() const noexcept { return end_ - begin_; }

 private:
  bool hand_out(std::size_t index, int64_t cycle, int64_t now_ns, MarkerFrame& out) noexcept;

  ReplayOptions options_;
  NatNetOptions natnet_;
  formats::MarkerTake take_;
  SourceInfo info_;
  std::size_t begin_ = 0, end_ = 0;  // the window, [begin_, end_) into take_.frames
  std::vector<int64_t> play_offset_ns_;  // per window frame: when it plays, at speed 1
  int64_t cycle_length_ns_ = 0;          // one pass of the window, including the last frame's period
  int64_t epoch_ns_ = 0;
  bool paced_ = true;
  // Position of the next frame to hand out: pass number and window index. Solve thread only.
  int64_t next_cycle_ = 0;
  std::size_t next_index_ = 0;
  std::atomic<uint64_t> delivered_{0}, late_{0};
  std::atomic<bool> finished_{false};
};

}  // namespace facecap::drivers
