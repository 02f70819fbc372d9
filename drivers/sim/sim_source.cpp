#include "drivers/sim/sim_source.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <numbers>
#include <random>

#include <fmt/format.h>

#include "core/error.hpp"
#include "core/time.hpp"
#include "formats/arkit.hpp"
#include "formats/livelinkface.hpp"
#include "solver/builtin_face.hpp"

namespace facecap::drivers {
namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;
// The sim thread sleeps in slices this long so that stop() returns promptly at any rate.
constexpr int64_t kMaxSleepSliceNs = 20 * kNsPerMs;

bool is_builtin_face(const Rig& rig) {
  const Rig& builtin = BuiltinFace::instance().rig();
  return &rig == &builtin || (rig.name == builtin.name && rig.content_hash() == builtin.content_hash());
}

}  // namespace

// The performance: weights over time for the rig's shapes, matched by name.
class SimSource::Motion {
 public:
  virtual ~Motion() = default;
  virtual Eigen::VectorXd weights(double t_seconds) const = 0;
  virtual std::string description() const = 0;
};

namespace {

// BuiltinFace::motion_weights, mapped by shape name onto any rig (ICT shares the names).
class BuiltinMotion final : public SimSource::Motion {
 public:
  explicit BuiltinMotion(const Rig& rig) {
    const Rig& builtin = BuiltinFace::instance().rig();
    for (Eigen::Index s = 0; s < builtin.shape_count(); ++s)
      if (auto target = rig.shape_index(builtin.shape_names[std::size_t(s)])) mapping_.emplace_back(s, *target);
    shape_count_ = rig.shape_count();
    if (mapping_.empty())
      throw Error(fmt::format("the built-in motion drives none of rig '{}''s shapes (it uses ICT/ARKit names such "
                              "as jawOpen, eyeBlink_L)", rig.name));
  }
  Eigen::VectorXd weights(double t) const override {
    const Eigen::VectorXd source = BuiltinFace::instance().motion_weights(t);
    Eigen::VectorXd w = Eigen::VectorXd::Zero(shape_count_);
    for (const auto& [from, to] : mapping_) w[to] = source[from];
    return w;
  }
  std::string description() const override { return "built-in motion"; }

 private:
  std::vector<std::pair<Eigen::Index, Eigen::Index>> mapping_;
  Eigen::Index shape_count_ = 0;
};

// A Live Link Face CSV: ARKit weights per row, mapped onto the rig's shapes, looped.
// Rows where tracking was lost hold the previous tracked row.
class LiveLinkMotion final : public SimSource::Motion {
 public:
  LiveLinkMotion(const std::string& path, const Rig& rig) : path_(path), shape_count_(rig.shape_count()) {
    const formats::FaceTake take = formats::read_livelinkface(std::filesystem::path(path));
    rate_hz_ = take.rate_hz > 0.0 ? take.rate_hz : 60.0;
    const auto matches = formats::match_arkit_to_rig(rig.shape_names);
    std::size_t driven = 0;
    for (const auto& m : matches) driven += m.empty() ? 0 : 1;
    if (driven == 0) throw file_error(path, fmt::format("none of its ARKit shapes matches a shape of rig '{}'", rig.name));
    Eigen::VectorXd held = Eigen::VectorXd::Zero(shape_count_);
    for (const formats::FaceFrame& frame : take.frames) {
      if (frame.tracked) {
        held.setZero();
        for (std::size_t a = 0; a < matches.size(); ++a)
          for (const std::size_t s : matches[a]) held[Eigen::Index(s)] = std::clamp(double(frame.weights[a]), 0.0, 1.0);
      }
      rows_.push_back(held);
    }
    if (rows_.empty()) throw file_error(path, "the Live Link Face CSV has no rows");
  }
  Eigen::VectorXd weights(double t) const override {
    const auto row = int64_t(std::floor(t * rate_hz_)) % int64_t(rows_.size());
    return rows_[std::size_t(row < 0 ? row + int64_t(rows_.size()) : row)];
  }
  std::string description() const override {
    return fmt::format("Live Link Face {} ({} rows at {:g} Hz, looped)", path_, rows_.size(), rate_hz_);
  }

 private:
  std::string path_;
  Eigen::Index shape_count_ = 0;
  double rate_hz_ = 60.0;
  std::vector<Eigen::VectorXd> rows_;
};

}  // namespace

SimSource::SimSource(SimOptions options, std::shared_ptr<const Rig> rig, MarkerSet markers)
    : options_(std::move(options)), rig_(std::move(rig)), markers_(std::move(markers)) {}

SimSource::~SimSource() { stop(); }

void SimSource::open() {
  if (!(options_.rate_hz > 0.0)) throw Error(fmt::format("sim rate {} Hz must be positive", options_.rate_hz));
  if (markers_.face.empty()) throw Error("the sim needs at least one face marker");
  if (options_.motion == "builtin") motion_ = std::make_unique<BuiltinMotion>(*rig_);
  else motion_ = std::make_unique<LiveLinkMotion>(options_.motion, *rig_);
  articulated_ = is_builtin_face(*rig_);
  units_per_mm_ = rig_units_per_mm(*rig_);
  // The head sways about a point behind the face, roughly where the neck meets the skull.
  const BoundingBox box = bounding_box(rig_->neutral);
  head_pivot_ = Eigen::Vector3d(0.5 * (box.min.x() + box.max.x()), box.min.y() + 0.3 * box.size().y(),
                                box.min.z() - 0.8 * box.size().z());
  info_.labels = markers_.labels();
  info_.units = guess_face_units(box);
  info_.nominal_rate_hz = options_.rate_hz;
  info_.own_clock = true;
  configure_mailbox(info_.labels);
}

std::string SimSource::description() const {
  return fmt::format("sim: {} on rig '{}', {} face + {} head markers at {:g} Hz, noise {:g} mm, dropouts {:g}%, seed {}",
                     motion_ ? motion_->description() : options_.motion, rig_->name, markers_.face.size(),
                     markers_.head.size(), options_.rate_hz, options_.noise_mm, 100.0 * options_.dropout_probability,
                     options_.seed);
}

Eigen::VectorXd SimSource::weights_at(int64_t frame_no) const { return motion_->weights(double(frame_no) / options_.rate_hz); }

Eigen::Isometry3d SimSource::head_pose_at(int64_t frame_no) const {
  const double t = double(frame_no) / options_.rate_hz;
  const double a = options_.head_motion_degrees * std::numbers::pi / 180.0;
  const double yaw = a * std::sin(kTwoPi * t / 6.1);
  const double pitch = 0.6 * a * std::sin(kTwoPi * t / 4.3 + 1.0);
  const double roll = 0.4 * a * std::sin(kTwoPi * t / 7.9 + 2.0);
  const double d = options_.head_motion_mm * units_per_mm_;
  const Eigen::Vector3d shift(d * std::sin(kTwoPi * t / 5.7), 0.5 * d * std::sin(kTwoPi * t / 3.9 + 0.5),
                              0.7 * d * std::sin(kTwoPi * t / 8.3 + 1.3));
  const Eigen::Matrix3d rotation = (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitY()) *
                                    Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitX()) *
                                    Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitZ())).toRotationMatrix();
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = rotation;
  pose.translation() = head_pivot_ - rotation * head_pivot_ + shift;
  return pose;
}

void SimSource::render_frame(int64_t frame_no, MarkerFrame& out) const {
  const Eigen::VectorXd w = weights_at(frame_no);
  const Eigen::Isometry3d head = head_pose_at(frame_no);
  // Per-frame generator: frame i's noise does not depend on which frames were skipped.
  std::mt19937_64 rng(uint64_t(options_.seed) * 0x9E3779B97F4A7C15ull + uint64_t(frame_no));
  std::normal_distribution<double> noise(0.0, std::max(options_.noise_mm * units_per_mm_, 0.0));
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  const bool noisy = options_.noise_mm > 0.0;

  auto emit = [&](std::size_t slot, const Eigen::Vector3d& rig_point) {
    Marker& m = out.markers[slot];
    if (uniform(rng) < options_.dropout_probability) {
      m.flags = kMarkerMissing;
      m.position.setConstant(std::numeric_limits<double>::quiet_NaN());
      return;
    }
    m.flags = 0;
    m.position = head * rig_point;
    if (noisy) m.position += Eigen::Vector3d(noise(rng), noise(rng), noise(rng));
  };

  if (articulated_) {
    const Eigen::Matrix3Xd pose = BuiltinFace::instance().articulated_pose(w);
    for (std::size_t k = 0; k < markers_.face.size(); ++k) emit(k, binding_point(markers_.face[k], pose));
  } else {
    // Linear blend at the bound vertices only: x0_v + sum_s B_vs w_s.
    for (std::size_t k = 0; k < markers_.face.size(); ++k) {
      const MarkerBinding& b = markers_.face[k];
      Eigen::Vector3d p = Eigen::Vector3d::Zero();
      for (int c = 0; c < 3; ++c) {
        const int v = b.vertices[std::size_t(c)];
        p += b.barycentric[c] * (rig_->neutral.col(v) + rig_->deltas.middleRows(3 * Eigen::Index(v), 3) * w);
      }
      emit(k, p);
    }
  }
  for (std::size_t h = 0; h < markers_.head.size(); ++h) emit(markers_.face.size() + h, markers_.head[h].position);

  const int64_t period_ns = int64_t(std::llround(double(kNsPerSecond) / options_.rate_hz));
  out.frame_no = frame_no;
  out.source_time_ns = frame_no * period_ns;
  out.receive_time_ns = 0;
  out.timecode = Timecode{};
}

void SimSource::start(const SourceStart& start) {
  if (!motion_) throw Error("sim source started before open()");
  if (start.lockstep) throw Error("the sim source runs on its own clock and cannot run in lockstep");
  stop();
  running_.store(true);
  thread_ = start_driver_thread(start, [this, epoch_ns = start.epoch_ns] { run(epoch_ns); });
}

void SimSource::stop() noexcept {
  running_.store(false);
  if (thread_.joinable()) thread_.join();
}

// The simulated device's thread: renders frame i ahead of time, releases it at its due
// time. Not RT-safe (it allocates while rendering), and it does not need to be.
void SimSource::run(int64_t epoch_ns) {
  const int64_t period_ns = int64_t(std::llround(double(kNsPerSecond) / options_.rate_hz));
  int64_t frame_no = 0;
  while (running_.load(std::memory_order_relaxed)) {
    const int64_t due_ns = epoch_ns + frame_no * period_ns;
    MarkerFrame& frame = mailbox_->write_buffer();
    render_frame(frame_no, frame);
    for (int64_t now = monotonic_now_ns(); now < due_ns && running_.load(std::memory_order_relaxed);
         now = monotonic_now_ns())
      sleep_until(std::min(due_ns, now + kMaxSleepSliceNs));
    if (!running_.load(std::memory_order_relaxed)) break;
    const int64_t now_ns = monotonic_now_ns();
    frame.receive_time_ns = now_ns;
    mailbox_->publish();
    ++frame_no;
    // A device that fell behind (rendering slower than the rate) skips what it missed.
    if (const int64_t behind = now_ns - (epoch_ns + frame_no * period_ns); behind > 0) {
      const int64_t skipped = behind / period_ns + 1;
      late_.fetch_add(uint64_t(skipped), std::memory_order_relaxed);
      frame_no += skipped;
    }
  }
}

}  // namespace facecap::drivers
