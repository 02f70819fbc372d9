#include "drivers/v4l2/v4l2_source.hpp"

#include <algorithm>
#include <chrono>
#include <limits>

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <spdlog/spdlog.h>

#include "core/error.hpp"
#include "core/text_list.hpp"
#include "core/time.hpp"
#include "drivers/v4l2/v4l2_feed.hpp"

namespace facecap::drivers {
namespace {

constexpr int kWaitMs = 50;                          // the thread checks its state this often
constexpr int64_t kSilentCameraNs = kNsPerSecond;    // a camera quiet this long is reported
constexpr int64_t kStateRefreshNs = 250 * kNsPerMs;
constexpr int64_t kReopenEveryNs = kNsPerSecond;      // a lost camera is looked for this often

}  // namespace

V4l2Source::V4l2Source(V4l2Options options, std::unique_ptr<v4l2::CameraFeed> feed)
    : options_(std::move(options)), feed_(std::move(feed)) {}

V4l2Source::~V4l2Source() {
  stop();
  if (feed_) feed_->stop();
}

std::string V4l2Source::unlabelled_label(std::size_t index) { return fmt::format("unlabelled_{}", index + 1); }

void V4l2Source::open() {
  if (options_.calibration.empty())
    throw Error("the v4l2 driver needs the cameras' calibration: source.v4l2.calibration names an OpenCV-style YAML "
                "file (docs/cameras.md)");
  v4l2::CameraCalibration calibration = v4l2::read_camera_calibration(options_.calibration);
  camera_names_.clear();
  for (const v4l2::CameraModel& c : calibration.cameras) camera_names_.push_back(c.name);
  if (!feed_) {
    const std::vector<std::string> devices = split_list(options_.devices);
    if (devices.size() != calibration.cameras.size())
      throw Error(fmt::format("source.v4l2.devices names {} device(s) for the {} cameras of {}: the v4l2 driver needs "
                              "one V4L2 capture device per calibrated camera, comma-separated, in the calibration's "
                              "order", devices.size(), calibration.cameras.size(), options_.calibration));
    std::vector<v4l2::V4l2CameraSpec> specs;
    for (std::size_t i = 0; i < devices.size(); ++i)
      specs.push_back({devices[i], calibration.cameras[i].name, calibration.cameras[i].width, calibration.cameras[i].height});
    feed_ = std::make_unique<v4l2::V4l2Feed>(std::move(specs), options_.pixel_format, options_.frame_rate_hz);
  } else if (feed_->cameras() != calibration.cameras.size()) {
    throw Error(fmt::format("{} cameras' images for the {} cameras of {}", feed_->cameras(), calibration.cameras.size(),
                            options_.calibration));
  }
  feed_->open();

  const v4l2::BlobParams blobs{.threshold = int(options_.threshold),
                               .min_area_px = int(options_.min_blob_area_px),
                               .max_area_px = int(options_.max_blob_area_px),
                               .min_roundness = options_.min_roundness};
  // A point must reproject a little looser than the pairs' epipolar band: its own noise
  // in both views adds up.
  const v4l2::TriangulationParams triangulation{.epipolar_tolerance_px = options_.epipolar_tolerance_px,
                                                .max_reprojection_px = 1.5 * options_.epipolar_tolerance_px};
  info_.units = calibration.units;
  const std::size_t cameras = calibration.cameras.size();
  pipeline_ = std::make_unique<v4l2::CameraPipeline>(std::move(calibration), blobs, triangulation);
  matcher_ = std::make_unique<v4l2::FrameSetMatcher>(
      cameras, int64_t(options_.sync_tolerance_ms * double(kNsPerMs)));
  info_.labels.clear();
  for (int64_t i = 0; i < options_.max_points; ++i) info_.labels.push_back(unlabelled_label(std::size_t(i)));
  info_.nominal_rate_hz = options_.frame_rate_hz;
  info_.own_clock = true;
  info_.unlabelled = true;
  points_.reserve(std::size_t(options_.max_points) * 2);
  configure_mailbox(info_.labels);
}

std::string V4l2Source::description() const {
  return fmt::format("v4l2: {} cameras ({}), up to {} unlabelled points a frame in {}; {}", camera_names_.size(),
                     fmt::join(camera_names_, ", "), info_.labels.size(), info_.units,
                     feed_ ? feed_->description() : std::string("not open"));
}

void V4l2Source::start(const SourceStart& start) {
  if (!pipeline_) throw Error("v4l2 source started before open()");
  if (start.lockstep) throw Error("the v4l2 source runs on the cameras' clock and cannot run in lockstep");
  stop();
  feed_->start();
  running_.store(true);
  thread_ = start_driver_thread(start, [this] { run(); });
}

void V4l2Source::stop() noexcept {
  running_.store(false);
  if (thread_.joinable()) thread_.join();
}

// The driver's thread: images in, blobs at once, sets by timestamp, points out; a camera
// that fails takes the cameras down until they all stream again (recover()). Not RT-safe
// (OpenCV may allocate; it logs).
void V4l2Source::run() {
  v4l2::CameraImage image;
  std::vector<int64_t> last_image_ns(pipeline_->cameras(), monotonic_now_ns());
  int64_t state_written_ns = 0;
  bool silent = false;
  while (running_.load(std::memory_order_relaxed)) {
    try {
      if (feed_->next(image, kWaitMs)) {
        last_image_ns[image.camera] = monotonic_now_ns();
        pipeline_->detect(image.camera, image.grey);
        if (matcher_->add(image.camera, image.timestamp_ns)) {
          pipeline_->triangulate(points_);
          publish(matcher_->set_time_ns());
        }
        unmatched_.store(matcher_->unmatched(), std::memory_order_relaxed);
      }
    } catch (const Error& e) {
      if (!recover(e.what())) return;
      std::fill(last_image_ns.begin(), last_image_ns.end(), monotonic_now_ns());
      silent = false;
      continue;
    }
    // A camera that sends nothing holds every set back: say which.
    const int64_t now_ns = monotonic_now_ns();
    if (now_ns - state_written_ns < kStateRefreshNs) continue;
    state_written_ns = now_ns;
    const auto quiet = std::min_element(last_image_ns.begin(), last_image_ns.end());
    if (now_ns - *quiet > kSilentCameraNs) {
      const auto camera = std::size_t(quiet - last_image_ns.begin());
      state_.set(fmt::format("camera {} ({}) has sent nothing for {:.1f} s", camera, camera_names_[camera],
                             double(now_ns - *quiet) / kNsPerSecond));
      silent = true;
    } else if (silent) {
      state_.set("");
      silent = false;
    }
  }
}

// A camera unplugged (or its driver gone) fails the feed: every camera is closed and the
// whole feed reopened every kReopenEveryNs until it streams again, the daemon solving on
// (held frames) meanwhile. False when the source was stopped first.
bool V4l2Source::recover(std::string why) {
  errors_.fetch_add(1, std::memory_order_relaxed);
  spdlog::error("v4l2: {}; reopening the cameras every {:g} s", why, double(kReopenEveryNs) / kNsPerSecond);
  feed_->stop();
  const int64_t lost_ns = monotonic_now_ns();
  int64_t next_try_ns = lost_ns + kReopenEveryNs;
  while (running_.load(std::memory_order_relaxed)) {
    const int64_t now_ns = monotonic_now_ns();
    if (now_ns < next_try_ns) {
      state_.set(fmt::format("cameras lost {:.1f} s ago, reopening: {}", double(now_ns - lost_ns) / kNsPerSecond, why));
      std::this_thread::sleep_for(std::chrono::milliseconds(kWaitMs));
      continue;
    }
    next_try_ns = now_ns + kReopenEveryNs;
    try {
      feed_->open();
      feed_->start();
    } catch (const Error& e) {
      feed_->stop();
      why = e.what();
      continue;
    }
    reconnects_.fetch_add(1, std::memory_order_relaxed);
    spdlog::info("v4l2: the cameras stream again after {:.1f} s", double(monotonic_now_ns() - lost_ns) / kNsPerSecond);
    state_.set(fmt::format("cameras back after a gap of {:.1f} s", double(monotonic_now_ns() - lost_ns) / kNsPerSecond));
    return true;
  }
  return false;
}

void V4l2Source::publish(int64_t set_time_ns) {
  MarkerFrame& out = mailbox_->write_buffer();
  const std::size_t slots = out.markers.size();
  if (points_.size() > slots) points_dropped_.fetch_add(points_.size() - slots, std::memory_order_relaxed);
  for (std::size_t i = 0; i < slots; ++i) {
    Marker& m = out.markers[i];
    m.id = int32_t(i);
    if (i < points_.size()) {
      m.position = points_[i];
      m.flags = kMarkerUnlabelled;
    } else {
      m.position.setConstant(std::numeric_limits<double>::quiet_NaN());
      m.flags = kMarkerMissing | kMarkerUnlabelled;
    }
  }
  out.frame_no = int64_t(sets_.fetch_add(1, std::memory_order_relaxed));
  out.source_time_ns = set_time_ns;
  out.receive_time_ns = monotonic_now_ns();
  out.timecode = Timecode{};
  mailbox_->publish();
}

}  // namespace facecap::drivers
