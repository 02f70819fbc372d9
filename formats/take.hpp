#pragma once
// The in-memory marker take that every marker reader returns and every writer accepts,
// and the one dispatch from a path to the right reader or writer.
//
// Missing markers: flag kMarkerMissing set and position NaN (all three coordinates), so
// that code forgetting to check the flag produces NaN instead of a plausible point.
#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "core/frame.hpp"

namespace facecap::formats {

// kNatNetCapture: a packet capture of NatNet traffic (.pcap, .pcapng), whose frames become
// a take only with a marker selection (natnet_markers.hpp capture_take; the replay driver).
enum class TakeFormat : uint8_t { kC3d, kTrc, kRecording, kLiveLinkFace, kNatNetCapture };

// "c3d", "trc", "fcrec", "livelinkface", "pcap".
std::string_view format_name(TakeFormat format) noexcept;

// By file extension (case-insensitive): .c3d, .trc, .fcrec, .csv.
std::optional<TakeFormat> format_from_extension(const std::filesystem::path& path);

// By content (magic bytes or first line); falls back to the extension. Throws Error
// naming the file when neither identifies a format.
TakeFormat detect_format(std::span<const char> head, const std::filesystem::path& path);
// The same for a file, reading only its first bytes.
TakeFormat detect_file_format(const std::filesystem::path& path);

struct MarkerTake {
  TakeFormat format = TakeFormat::kC3d;
  std::vector<std::string> labels;  // one per marker slot; frames[i].markers[k] is labels[k]
  double rate_hz = 0.0;             // frames per second, 0 when unknown
  std::string units;                // as the file states them: "mm", "cm", "m", ...
  int64_t first_frame = 1;          // the file's number of frames[0]
  std::vector<MarkerFrame> frames;  // every frame has labels.size() markers
  // Facts specific to the source (C3D processor type, TRC header fields, ...), in order.
  std::vector<std::pair<std::string, std::string>> metadata;
  // Damage the reader tolerated (an unreadable parameter after the needed ones, extra
  // columns, ...): the take is usable, but the operator should know.
  std::vector<std::string> warnings;

  std::size_t marker_count() const noexcept { return labels.size(); }
  std::string_view metadata_value(std::string_view key) const noexcept;
};

// Frame rates the readers accept as timing: finite, positive, at most kMaxFrameRateHz, and
// slow enough that `frames` frames end within int64 nanoseconds.
inline constexpr double kMaxFrameRateHz = 1e6;
bool usable_frame_rate(double rate_hz, std::size_t frames) noexcept;

// What every marker reader does last, so that all formats treat these alike (warnings in
// take.warnings, each naming `name`):
// - a rate that is not usable_frame_rate becomes 0 (unknown);
// - a label given to more than one marker slot is named with both slots (everything that
//   matches markers by label uses the first);
// - when two or more frames all carry one timestamp, they are re-timed at the nominal rate
//   (replay paces by timestamps), or said to have no timing when there is no rate.
void finish_take(MarkerTake& take, const std::string& name);

// How many marker samples (frames x slots) a file of `bytes` may expand to: a bound
// checked before frames are allocated, generous for real files (a sample costs a few
// bytes of text at least) and small enough that hostile counts cannot exhaust memory.
std::size_t max_take_samples(std::size_t bytes) noexcept;

// Appends a frame of marker_count missing markers labelled from take.labels.
MarkerFrame& append_empty_frame(MarkerTake& take, int64_t frame_no, int64_t source_time_ns);

// Marks a marker missing the one documented way (flag set, position NaN).
void set_missing(Marker& marker) noexcept;

struct GapStats {
  std::size_t missing_samples = 0;  // marker-frames without a position
  std::size_t gap_runs = 0;         // maximal runs of consecutive missing frames, over all markers
};
GapStats count_gaps(const MarkerTake& take);

// Throws Error unless every frame has one marker per label, with matching labels.
void check_take_shape(const MarkerTake& take, const std::string& name);

// Called as frames are written: done of total.
using ProgressFn = std::function<void(std::size_t done, std::size_t total)>;
// Calls progress (when set) every 256 frames and at the last one.
void report_progress(const ProgressFn& progress, std::size_t done, std::size_t total);

// Reads a marker take in any supported format (chosen by content, then extension).
// Live Link Face CSV holds blendshape weights, not markers, and is refused here (read it
// with read_livelinkface), as is a NatNet capture (capture_take). Throws Error.
// Files are mapped, not read: a reader that refuses a file from its header touches no
// more of it. salvage_recording: a recording whose HEAD is damaged and has no intact
// copy is read anyway (RecordingReader::Options::salvage), with a warning.
struct TakeReadOptions {
  bool salvage_recording = false;
};
MarkerTake read_take(const std::filesystem::path& path, const TakeReadOptions& options = {});
MarkerTake read_take(std::span<const char> bytes, const std::string& name);

// Writes a take in the format the extension names (.c3d, .trc, .fcrec), atomically.
void write_take(const std::filesystem::path& path, const MarkerTake& take, const ProgressFn& progress = {});

}  // namespace facecap::formats
