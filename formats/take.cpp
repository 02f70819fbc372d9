#include "formats/take.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <unordered_map>

#include <fmt/format.h>
#include <unistd.h>

#include "core/error.hpp"
#include "core/io.hpp"
#include "formats/c3d.hpp"
#include "formats/pcap.hpp"
#include "formats/recording.hpp"
#include "formats/text.hpp"
#include "formats/trc.hpp"

namespace facecap::formats {

std::string_view format_name(TakeFormat format) noexcept {
  switch (format) {
    case TakeFormat::kC3d: return "c3d";
    case TakeFormat::kTrc: return "trc";
    case TakeFormat::kRecording: return "fcrec";
    case TakeFormat::kLiveLinkFace: return "livelinkface";
    case TakeFormat::kNatNetCapture: return "pcap";
  }
  return "?";
}

std::optional<TakeFormat> format_from_extension(const std::filesystem::path& path) {
  const std::string ext = path.extension().string();
  if (equals_ignore_case(ext, ".c3d")) return TakeFormat::kC3d;
  if (equals_ignore_case(ext, ".trc")) return TakeFormat::kTrc;
  if (equals_ignore_case(ext, ".fcrec")) return TakeFormat::kRecording;
  if (equals_ignore_case(ext, ".csv")) return TakeFormat::kLiveLinkFace;
  return std::nullopt;
}

namespace {

bool starts_with_nocase(std::span<const char> head, std::string_view prefix) {
  return head.size() >= prefix.size() && equals_ignore_case(std::string_view(head.data(), prefix.size()), prefix);
}

}  // namespace

TakeFormat detect_format(std::span<const char> head, const std::filesystem::path& path) {
  if (starts_with_nocase(head, "FCREC\r\n\x1a")) return TakeFormat::kRecording;
  if (starts_with_nocase(head, "PathFileType")) return TakeFormat::kTrc;
  if (starts_with_nocase(head, "Timecode,")) return TakeFormat::kLiveLinkFace;
  if (looks_like_capture(head)) return TakeFormat::kNatNetCapture;
  if (auto by_extension = format_from_extension(path)) return *by_extension;
  // C3D has no magic string, only 0x50 as its second byte.
  if (head.size() >= 2 && uint8_t(head[1]) == 0x50) return TakeFormat::kC3d;
  throw file_error(path.string(),
                   "unknown format: not C3D, TRC, Live Link Face CSV or a facecap recording "
                   "(by content or extension)");
}

std::string_view MarkerTake::metadata_value(std::string_view key) const noexcept {
  for (const auto& [k, v] : metadata) {
    if (k == key) return v;
  }
  return {};
}

void set_missing(Marker& marker) noexcept {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  marker.flags |= kMarkerMissing;
  marker.position = Eigen::Vector3d(nan, nan, nan);
}

MarkerFrame& append_empty_frame(MarkerTake& take, int64_t frame_no, int64_t source_time_ns) {
  MarkerFrame& frame = take.frames.emplace_back();
  frame.frame_no = frame_no;
  frame.source_time_ns = source_time_ns;
  frame.markers.resize(take.labels.size());
  for (std::size_t k = 0; k < take.labels.size(); ++k) {
    frame.markers[k].id = int32_t(k);
    frame.markers[k].label.assign(take.labels[k]);
    set_missing(frame.markers[k]);
  }
  return frame;
}

bool usable_frame_rate(double rate_hz, std::size_t frames) noexcept {
  return std::isfinite(rate_hz) && rate_hz > 0.0 && rate_hz <= kMaxFrameRateHz &&
         double(frames) * 1e9 / rate_hz < 9.0e18;
}

std::size_t max_take_samples(std::size_t bytes) noexcept { return 16 * bytes + (std::size_t(1) << 20); }

namespace {

// Labels given to more than one slot, each with its first two slots (1-based, as the
// formats number points and markers).
void warn_duplicate_labels(MarkerTake& take, const std::string& name) {
  constexpr std::size_t kNamed = 5;  // a hostile file may repeat thousands: name a few, count the rest
  std::unordered_map<std::string_view, std::size_t> first_slot;
  std::size_t repeated = 0;
  for (std::size_t k = 0; k < take.labels.size(); ++k) {
    const auto [it, added] = first_slot.emplace(take.labels[k], k);
    if (added) continue;
    if (++repeated <= kNamed) {
      take.warnings.push_back(fmt::format("{}: label '{}' is given to markers {} and {}; matching by label uses marker {}",
                                          name, take.labels[k], it->second + 1, k + 1, it->second + 1));
    }
  }
  if (repeated > kNamed)
    take.warnings.push_back(fmt::format("{}: {} more markers repeat an earlier label", name, repeated - kNamed));
}

void retime_equal_timestamps(MarkerTake& take, const std::string& name) {
  auto& frames = take.frames;
  if (frames.size() < 2) return;
  const int64_t first_ns = frames.front().source_time_ns;
  for (const auto& f : frames)
    if (f.source_time_ns != first_ns) return;
  if (take.rate_hz <= 0.0) {
    take.warnings.push_back(fmt::format("{}: all {} frames carry the same timestamp and the take states no frame "
                                        "rate: its frames have no timing",
                                        name, frames.size()));
    return;
  }
  take.warnings.push_back(fmt::format("{}: all {} frames carry the same timestamp ({} ns); timed at the nominal "
                                      "{} Hz instead",
                                      name, frames.size(), first_ns, take.rate_hz));
  const double span_ns = double(frames.size()) * 1e9 / take.rate_hz;  // < 9e18: the rate is usable
  const int64_t base_ns = double(first_ns) + span_ns < 9.2e18 ? first_ns : 0;
  for (std::size_t i = 0; i < frames.size(); ++i)
    frames[i].source_time_ns = base_ns + std::llround(double(i) * 1e9 / take.rate_hz);
}

}  // namespace

void finish_take(MarkerTake& take, const std::string& name) {
  if (take.rate_hz != 0.0 && !usable_frame_rate(take.rate_hz, take.frames.size())) {
    take.warnings.push_back(fmt::format("{}: frame rate {} Hz is not usable; treated as unknown", name, take.rate_hz));
    take.rate_hz = 0.0;
  }
  warn_duplicate_labels(take, name);
  retime_equal_timestamps(take, name);
}

void report_progress(const ProgressFn& progress, std::size_t done, std::size_t total) {
  if (progress && (done % 256 == 0 || done == total)) progress(done, total);
}

GapStats count_gaps(const MarkerTake& take) {
  GapStats stats;
  std::vector<bool> in_gap(take.labels.size(), false);
  for (const auto& frame : take.frames) {
    for (std::size_t k = 0; k < frame.markers.size() && k < in_gap.size(); ++k) {
      const bool missing = !frame.markers[k].present();
      stats.missing_samples += missing ? 1 : 0;
      stats.gap_runs += (missing && !in_gap[k]) ? 1 : 0;
      in_gap[k] = missing;
    }
  }
  return stats;
}

void check_take_shape(const MarkerTake& take, const std::string& name) {
  for (std::size_t f = 0; f < take.frames.size(); ++f) {
    const auto& markers = take.frames[f].markers;
    if (markers.size() != take.labels.size()) {
      throw Error(fmt::format("{}: frame {} has {} markers, the take has {} labels", name, f, markers.size(),
                              take.labels.size()));
    }
  }
}

MarkerTake read_take(std::span<const char> bytes, const std::string& name) {
  switch (detect_format(bytes.first(std::min<std::size_t>(bytes.size(), 64)), name)) {
    case TakeFormat::kC3d: return read_c3d(bytes, name);
    case TakeFormat::kTrc: return read_trc(std::string_view(bytes.data(), bytes.size()), name);
    case TakeFormat::kRecording: return take_from_recording(RecordingReader(bytes, name));
    case TakeFormat::kLiveLinkFace:
      throw file_error(name, "a Live Link Face CSV holds blendshape weights, not markers");
    case TakeFormat::kNatNetCapture:
      throw file_error(name, "a packet capture: its NatNet frames become markers only for a chosen marker set "
                             "(the replay driver takes source.natnet.marker_set); facecap inspect shows what it holds");
  }
  throw file_error(name, "unknown format");
}

TakeFormat detect_file_format(const std::filesystem::path& path) {
  const MappedFile file(path);
  return detect_format(file.bytes().first(std::min<std::size_t>(file.bytes().size(), 64)), path);
}

MarkerTake read_take(const std::filesystem::path& path, const TakeReadOptions& options) {
  const MappedFile file(path);
  const std::span<const char> bytes = file.bytes();
  if (detect_format(bytes.first(std::min<std::size_t>(bytes.size(), 64)), path) == TakeFormat::kRecording)
    return take_from_recording(RecordingReader(bytes, path.string(), {.salvage = options.salvage_recording}));
  return read_take(bytes, path.string());
}

void write_take(const std::filesystem::path& path, const MarkerTake& take, const ProgressFn& progress) {
  const auto format = format_from_extension(path);
  if (!format) throw file_error(path.string(), "cannot tell the output format: use .c3d, .trc or .fcrec");
  switch (*format) {
    case TakeFormat::kC3d: {
      const auto bytes = write_c3d(take, progress);
      write_file_atomically(path, bytes);
      return;
    }
    case TakeFormat::kTrc: {
      const auto text = write_trc(take, path.filename().string(), progress);
      write_file_atomically(path, std::span<const char>(text.data(), text.size()));
      return;
    }
    case TakeFormat::kRecording: {
      // Written beside the target and renamed, like the other formats.
      const auto tmp = std::filesystem::path(path.string() + fmt::format(".tmp.{}", ::getpid()));
      try {
        write_recording(tmp, take, fmt::format("converted from a {} take", format_name(take.format)), progress);
        std::error_code ec;
        std::filesystem::rename(tmp, path, ec);
        if (ec)
          throw file_error(path.string(),
                           fmt::format("cannot rename the finished recording into place: {}", ec.message()));
      } catch (...) {
        std::error_code ec;
        std::filesystem::remove(tmp, ec);
        throw;
      }
      return;
    }
    case TakeFormat::kLiveLinkFace:
      throw file_error(path.string(), "markers cannot be written as Live Link Face CSV (it holds blendshape weights)");
    case TakeFormat::kNatNetCapture: throw file_error(path.string(), "takes are not written as packet captures");
  }
}

}  // namespace facecap::formats
