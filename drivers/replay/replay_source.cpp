#include "drivers/replay/replay_source.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "core/error.hpp"
#include "core/time.hpp"
#include "drivers/capture/capture_file.hpp"
#include "formats/natnet_markers.hpp"

namespace facecap::drivers {
namespace {

// Every slot of every frame carries kMarkerUnlabelled: a recording of cameras' points or of
// a NatNet cloud, which only the labeller can solve (as facecapd did when it recorded them).
bool only_unlabelled_points(const formats::MarkerTake& take) {
  bool any = false;
  for (const MarkerFrame& frame : take.frames)
    for (const Marker& m : frame.markers) {
      if ((m.flags & kMarkerUnlabelled) == 0) return false;
      any = true;
    }
  return any;
}

}  // namespace

ReplaySource::ReplaySource(ReplayOptions options, NatNetOptions natnet)
    : options_(std::move(options)), natnet_(std::move(natnet)) {}

void ReplaySource::open() {
  if (options_.file.empty()) throw Error("replay needs a file (source.replay.file)");
  if (formats::detect_file_format(options_.file) == formats::TakeFormat::kNatNetCapture) {
    const formats::natnet::MarkerSelection selection{natnet_.marker_set, std::size_t(natnet_.unlabelled_markers),
                                                     uint16_t(natnet_.timecode_rate_hz)};
    take_ = formats::natnet::capture_take(capture::read_natnet_capture(options_.file), selection, options_.file);
  } else {
    take_ = formats::read_take(options_.file);
  }
  for (const auto& warning : take_.warnings) spdlog::warn("{}", warning);
  if (take_.frames.empty()) throw file_error(options_.file, "the take has no frames");
  formats::check_take_shape(take_, options_.file);
  const bool nominal_usable = take_.rate_hz > 0.0;
  if (!options_.source_timestamps && !nominal_usable)
    throw file_error(options_.file, "the take states no frame rate: replay it with source_timestamps = true");

  // Play time of every frame, at speed 1, from the take's first frame.
  const std::size_t n = take_.frames.size();
  std::vector<int64_t> time_ns(n);
  const int64_t period_ns = nominal_usable ? int64_t(std::llround(double(kNsPerSecond) / take_.rate_hz)) : 0;
  for (std::size_t i = 0; i < n; ++i)
    time_ns[i] = options_.source_timestamps ? take_.frames[i].source_time_ns - take_.frames[0].source_time_ns
                                            : int64_t(i) * period_ns;
  if (options_.source_timestamps && !std::is_sorted(time_ns.begin(), time_ns.end()))
    throw file_error(options_.file, "frame timestamps go backwards: replay it with source_timestamps = false");
  // (The readers re-time such frames when the take states a rate.)
  if (n > 1 && time_ns.back() == 0)
    throw file_error(options_.file, "all frames carry one timestamp and the take states no frame rate: nothing to pace them by");

  const auto start_ns = int64_t(std::llround(options_.start_s * double(kNsPerSecond)));
  const auto end_ns = options_.end_s > 0.0 ? int64_t(std::llround(options_.end_s * double(kNsPerSecond))) : INT64_MAX;
  begin_ = std::size_t(std::lower_bound(time_ns.begin(), time_ns.end(), start_ns) - time_ns.begin());
  end_ = std::size_t(std::upper_bound(time_ns.begin(), time_ns.end(), end_ns) - time_ns.begin());
  if (begin_ >= end_)
    throw file_error(options_.file, fmt::format("the window {} s to {} s holds no frame of the take ({:.3f} s long)",
                                                options_.start_s, options_.end_s == 0.0 ? "end" : fmt::format("{}", options_.end_s),
                                                double(time_ns.back()) / kNsPerSecond));
  play_offset_ns_.resize(end_ - begin_);
  for (std::size_t i = begin_; i < end_; ++i) play_offset_ns_[i - begin_] = time_ns[i] - time_ns[begin_];
  const int64_t frame_ns = period_ns > 0 ? period_ns
                           : play_offset_ns_.size() > 1 ? play_offset_ns_.back() / int64_t(play_offset_ns_.size() - 1)
                                                        : kNsPerSecond / 60;
  cycle_length_ns_ = play_offset_ns_.back() + frame_ns;

  info_.labels = take_.labels;
  info_.units = options_.units == TakeUnits::kStated ? take_.units : std::string(kTakeUnits.name(options_.units));
  info_.nominal_rate_hz = take_.rate_hz;
  info_.own_clock = false;
  info_.unlabelled = only_unlabelled_points(take_);
}

void ReplaySource::start(const SourceStart& start) {
  epoch_ns_ = start.epoch_ns;
  paced_ = !start.lockstep && options_.speed > 0.0;
  next_cycle_ = 0;
  next_index_ = 0;
  finished_.store(false);
}

std::string ReplaySource::description() const {
  return fmt::format("replay: {} ({}, {} markers, {} frames{} at {:g} Hz), speed {}{}", options_.file,
                     formats::format_name(take_.format), take_.labels.size(), end_ - begin_,
                     end_ - begin_ == take_.frames.size() ? "" : fmt::format(" of {}", take_.frames.size()),
                     take_.rate_hz, options_.speed == 0.0 ? "as fast as possible" : fmt::format("{:g}x", options_.speed),
                     options_.loop ? ", looping" : "");
}

SourceHealth ReplaySource::health() const noexcept {
  SourceHealth h;
  h.frames_delivered = delivered_.load(std::memory_order_relaxed);
  h.frames_late = late_.load(std::memory_order_relaxed);
  h.finished = finished_.load(std::memory_order_relaxed);
  return h;
}

bool ReplaySource::hand_out(std::size_t index, int64_t cycle, int64_t now_ns, MarkerFrame& out) noexcept {
  const MarkerFrame& frame = take_.frames[begin_ + index];
  out = frame;  // same marker count as `out` was sized for: no allocation
  // A looping replay keeps numbering and time moving forward.
  out.frame_no = frame.frame_no + cycle * int64_t(end_ - begin_);
  out.source_time_ns = frame.source_time_ns + cycle * cycle_length_ns_;
  out.receive_time_ns = now_ns;
  next_index_ = index + 1;
  next_cycle_ = cycle;
  if (next_index_ == end_ - begin_) {
    next_index_ = 0;
    ++next_cycle_;
  }
  delivered_.fetch_add(1, std::memory_order_relaxed);
  return true;
}

bool ReplaySource::take_frame(int64_t now_ns, MarkerFrame& out) noexcept {
  if (finished_.load(std::memory_order_relaxed)) return false;
  const std::size_t count = end_ - begin_;
  if (next_cycle_ > 0 && !options_.loop) {
    finished_.store(true, std::memory_order_relaxed);
    return false;
  }
  if (!paced_) return hand_out(next_index_, next_cycle_, now_ns, out);

  const auto played_ns = int64_t(double(now_ns - epoch_ns_) * options_.speed);
  if (played_ns < 0) return false;
  int64_t cycle = played_ns / cycle_length_ns_;
  if (!options_.loop && cycle > 0) cycle = 0;  // the last frame is still due
  const int64_t within_ns = options_.loop || played_ns < cycle_length_ns_ ? played_ns - cycle * cycle_length_ns_
                                                                          : cycle_length_ns_;
  // The newest frame whose time has come.
  const auto due = std::upper_bound(play_offset_ns_.begin(), play_offset_ns_.end(), within_ns) - play_offset_ns_.begin() - 1;
  if (due < 0) return false;
  const auto due_index = std::size_t(due);
  if (cycle < next_cycle_ || (cycle == next_cycle_ && due_index < next_index_)) return false;  // already handed out
  const int64_t skipped = (cycle - next_cycle_) * int64_t(count) + int64_t(due_index) - int64_t(next_index_);
  if (skipped > 0) late_.fetch_add(uint64_t(skipped), std::memory_order_relaxed);
  return hand_out(due_index, cycle, now_ns, out);
}

}  // namespace facecap::drivers
