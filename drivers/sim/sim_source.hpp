#pragma once
// The simulated capture system: drives a rig with a performance (the built-in motion or a
// Live Link Face CSV), samples the markers of a MarkerSet on the posed face, sways the
// head, adds noise and dropouts, and delivers frames at a fixed rate from its own thread.
// Deterministic: frame i is the same for a given seed whatever the timing.
#include <atomic>
#include <memory>
#include <thread>

#include <Eigen/Geometry>

#include "solver/marker_layout.hpp"
#include "drivers/api/marker_source.hpp"
#include "drivers/api/source_config.hpp"
#include "solver/rig.hpp"

namespace facecap::drivers {

class SimSource final : public MailboxSource {
 public:
  SimSource(SimOptions options, std::shared_ptr<const Rig> rig, MarkerSet markers);
  ~SimSource() override;

  void open() override;
  const SourceInfo& info() const noexcept override { return info_; }
  void start(const SourceStart& start) override;
  void stop() noexcept override;
  std::string description() const override;

  // The ground truth, for tests and evaluation. Not RT-safe.
  // Rig weights (M) the performance has at frame_no.
  Eigen::VectorXd weights_at(int64_t frame_no) const;
  // T_world_head: where the head is at frame_no (marker p_world = T * p_rig).
  Eigen::Isometry3d head_pose_at(int64_t frame_no) const;
  // Frame frame_no exactly as the source thread produces it (receive time left 0).
  void render_frame(int64_t frame_no, MarkerFrame& out) const;

  // The performance: rig weights over time (defined in sim_source.cpp).
  class Motion;

 private:
  void run(int64_t epoch_ns);

  SimOptions options_;
  std::shared_ptr<const Rig> rig_;
  MarkerSet markers_;
  SourceInfo info_;
  std::unique_ptr<Motion> motion_;
  bool articulated_ = false;  // the built-in face: pose with real hinges, not linear blends
  double units_per_mm_ = 0.1;
  Eigen::Vector3d head_pivot_ = Eigen::Vector3d::Zero();
  std::thread thread_;
  std::atomic<bool> running_{false};
};

}  // namespace facecap::drivers
