#include "outputs/recording/recorder.hpp"

#include <algorithm>
#include <ctime>

#include <fmt/format.h>

#include "core/error.hpp"
#include "core/log.hpp"
#include "core/time.hpp"

namespace facecap::outputs {
namespace {

// The writer thread polls the queue; at 120-1000 Hz this batches a few frames per wake.
constexpr int64_t kPollNs = 2 * kNsPerMs;
// Buffered chunks reach the kernel at least this often: a killed facecapd loses at most
// this much plus a poll and what the queue held, inside the 50 ms the docs promise with
// room for a loaded host (at 50 ms itself a kill lost 58 ms).
constexpr int64_t kFlushIntervalNs = 20 * kNsPerMs;
// How often the file is checked for having been deleted under the recorder.
constexpr int64_t kDeletedCheckIntervalNs = kNsPerSecond;

SolvedFrame sized_frame(Eigen::Index shape_count, Eigen::Index vertex_count) {
  SolvedFrame frame;
  frame.resize(shape_count, vertex_count);
  return frame;
}

}  // namespace

Recorder::Recorder(RecorderOptions options, Eigen::Index vertex_count)
    : options_(std::move(options)),
      queue_(options_.queue_frames,
             Entry{false, false, false, make_marker_frame(options_.header.marker_labels),
                   sized_frame(Eigen::Index(options_.header.shape_names.size()), options_.vertices ? vertex_count : 0)}) {
  start_state_.reserve(options_.start_state_bytes);
  std::filesystem::create_directories(options_.file.parent_path().empty() ? "." : options_.file.parent_path());
  writer_ = std::make_unique<formats::RecordingWriter>(options_.file, options_.header,
                                                       formats::RecordingWriter::Options{.write = options_.write});
  thread_ = std::thread([this] { run(); });
}

Recorder::~Recorder() {
  try {
    stop();
  } catch (const std::exception& e) {
    spdlog::error("recording {}: {}", options_.file.string(), e.what());
  }
}

std::string Recorder::description() const {
  return fmt::format("recording {} ({}{}{})", options_.file.string(), options_.markers ? "markers" : "",
                     options_.markers && options_.solved ? " and " : "",
                     options_.solved ? (options_.vertices ? "solved frames with vertices" : "solved frames") : "");
}

void Recorder::offer_start_state(std::span<const char> state) noexcept {
  if (first_offered_) return;
  start_state_too_large_ = state.size() > start_state_.capacity();
  start_state_offered_ = !start_state_too_large_;
  if (start_state_offered_) start_state_.assign(state.begin(), state.end());  // within capacity: no allocation
}

void Recorder::offer(const MarkerFrame& markers, const SolvedFrame& solved) noexcept {
  offered_.fetch_add(1, std::memory_order_relaxed);
  const bool first = !first_offered_;  // a dropped first frame takes the start state with it
  first_offered_ = true;
  Entry* slot = queue_.begin_push();
  if (!slot) {
    dropped_.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  // Slots were sized like these frames, so the copies reuse their storage.
  slot->has_start_state = first && (start_state_offered_ || start_state_too_large_);
  slot->has_markers = options_.markers;
  slot->has_solved = options_.solved;
  if (options_.markers) slot->markers = markers;
  if (options_.solved) copy_solved_frame(solved, slot->solved);
  queue_.commit_push();
}

SinkHealth Recorder::health() const noexcept {
  SinkHealth h;
  h.offered = offered_.load(std::memory_order_relaxed);
  h.delivered = written_.load(std::memory_order_relaxed);
  h.dropped = dropped_.load(std::memory_order_relaxed);
  h.errors = errors_.load(std::memory_order_relaxed);
  h.failed = h.errors > 0;
  return h;
}

void Recorder::count_written() {
  marker_frames_.store(writer_->marker_frames(), std::memory_order_relaxed);
  solved_frames_.store(writer_->solved_frames(), std::memory_order_relaxed);
}

void Recorder::fail(const std::string& what) {
  // Every loop frame adds one chunk of each kind recorded, so the frames whole in the file
  // are the chunks it kept over that; those counted written beyond them were lost.
  const uint64_t chunks_per_frame = uint64_t(options_.markers) + uint64_t(options_.solved);
  const uint64_t in_file = writer_->file_deleted() || chunks_per_frame == 0
                               ? 0
                               : (writer_->marker_frames() + writer_->solved_frames()) / chunks_per_frame;
  const uint64_t written = written_.load(std::memory_order_relaxed);
  const uint64_t lost = written > in_file ? written - in_file : 0;
  written_.store(written - lost, std::memory_order_relaxed);
  dropped_.fetch_add(lost, std::memory_order_relaxed);
  errors_.fetch_add(1, std::memory_order_relaxed);
  if (in_file == 0) {
    marker_frames_.store(0, std::memory_order_relaxed);
    solved_frames_.store(0, std::memory_order_relaxed);
  } else {
    count_written();
  }
  failure_ = what;
  spdlog::error("recording {} stopped: {}; it holds {} frames, {} more were lost with the failure, and every later "
                "frame is dropped (solving and the other outputs go on)",
                options_.file.string(), what, written - lost, lost);
  try {
    writer_->close();  // after a failed write: adds the index if it fits, never throws again
  } catch (const std::exception&) {
  }
}

void Recorder::store_start_state() {
  if (start_state_offered_) return writer_->append_start_state(start_state_);
  spdlog::warn("recording {}: the solve's state before the first frame did not fit the {} bytes kept for it (the "
               "solver was rebuilt since the take started); a re-solve starts cold",
               options_.file.string(), start_state_.capacity());
}

// The writer thread. Not RT-safe (encodes, allocates, writes).
void Recorder::run() {
  int64_t last_flush_ns = monotonic_now_ns();
  int64_t last_deleted_check_ns = last_flush_ns;
  for (;;) {
    const bool stopping = stop_requested_.load(std::memory_order_acquire);
    while (Entry* entry = queue_.front()) {
      if (writer_->is_open()) {
        try {
          if (entry->has_start_state) store_start_state();
          if (entry->has_markers) writer_->append_marker_frame(entry->markers);
          if (entry->has_solved) writer_->append_solved_frame(entry->solved);
          written_.fetch_add(1, std::memory_order_relaxed);
          count_written();
        } catch (const std::exception& e) {
          dropped_.fetch_add(1, std::memory_order_relaxed);  // this frame
          fail(e.what());
        }
      } else {
        dropped_.fetch_add(1, std::memory_order_relaxed);  // the recording stopped: not on disk
      }
      queue_.pop();
    }
    if (stopping) break;
    const int64_t now = monotonic_now_ns();
    if (now - last_deleted_check_ns >= kDeletedCheckIntervalNs && writer_->is_open()) {
      last_deleted_check_ns = now;
      if (writer_->file_deleted()) fail("the file was deleted (or its directory removed) while recording");
    }
    if (now - last_flush_ns >= kFlushIntervalNs && writer_->is_open()) {
      try {
        writer_->flush();
      } catch (const std::exception& e) {
        fail(e.what());
      }
      last_flush_ns = now;
    }
    timespec ts{0, long(kPollNs)};
    nanosleep(&ts, nullptr);
  }
}

void Recorder::stop() {
  if (!thread_.joinable()) return;
  stop_requested_.store(true, std::memory_order_release);
  thread_.join();
  if (!writer_->is_open()) return;
  if (writer_->file_deleted()) return fail("the file was deleted (or its directory removed) while recording");
  try {
    writer_->close();
  } catch (const Error& e) {
    fail(e.what());
    throw;
  }
}

RecorderCounters Recorder::counters() const noexcept {
  return {marker_frames_.load(std::memory_order_relaxed), solved_frames_.load(std::memory_order_relaxed),
          dropped_.load(std::memory_order_relaxed), errors_.load(std::memory_order_relaxed)};
}

namespace {

std::filesystem::path unique_path(const std::filesystem::path& directory, const std::string& stem) {
  std::filesystem::path path = directory / (stem + ".fcrec");
  for (int n = 2; std::filesystem::exists(path); ++n) path = directory / fmt::format("{}-{}.fcrec", stem, n);
  return path;
}

// Letters, digits, '.' and '-' only, no leading '.', at most 64 bytes.
std::string safe_part(std::string_view text) {
  std::string out;
  for (const char c : text.substr(0, 64)) {
    const bool safe = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '.' || c == '-';
    out += safe ? c : '-';
  }
  while (!out.empty() && out.front() == '.') out.front() = '-';
  return out;
}

}  // namespace

namespace {

// "<scene>_<shot>_" (the fields given), the file name's part before the take.
std::string slate_prefix(const std::string& scene, const std::string& shot) {
  std::string prefix;
  for (const std::string* field : {&scene, &shot})
    if (!field->empty()) prefix += safe_part(*field) + "_";
  return prefix;
}

}  // namespace

std::filesystem::path take_path(const std::filesystem::path& directory, const formats::RecordingHeader& slate) {
  if (slate.take.empty()) throw Error("a take needs a name or number");
  const std::filesystem::path path = directory / (slate_prefix(slate.scene, slate.shot) + safe_part(slate.take) + ".fcrec");
  std::error_code ec;
  if (std::filesystem::exists(path, ec))
    throw Error(fmt::format("scene \"{}\" shot \"{}\" take \"{}\" is already recorded in {}: give another take, or none "
                            "for the next number ({})",
                            slate.scene, slate.shot, slate.take, path.string(), next_take_number(directory, slate.scene, slate.shot)));
  return path;
}

std::string next_take_number(const std::filesystem::path& directory, const std::string& scene, const std::string& shot) {
  const std::string prefix = slate_prefix(scene, shot);
  uint64_t largest = 0;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(directory, ec)) {
    const std::string name = entry.path().filename().string();
    if (!name.starts_with(prefix) || !name.ends_with(".fcrec")) continue;
    const std::string_view number = std::string_view(name).substr(prefix.size(), name.size() - prefix.size() - 6);
    if (number.empty() || number.size() > 9 || number.find_first_not_of("0123456789") != std::string_view::npos) continue;
    largest = std::max<uint64_t>(largest, std::stoull(std::string(number)));
  }
  return std::to_string(largest + 1);
}

std::filesystem::path new_recording_path(const std::filesystem::path& directory) {
  const std::time_t now = std::time(nullptr);
  std::tm local{};
  localtime_r(&now, &local);
  char stamp[32];
  std::strftime(stamp, sizeof stamp, "%Y%m%d-%H%M%S", &local);
  return unique_path(directory, fmt::format("facecapd-{}", stamp));
}

}  // namespace facecap::outputs
