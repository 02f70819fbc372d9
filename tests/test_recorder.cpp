// The recorder (outputs/recording) on its own: what it counts when the disk fails or its
// file is deleted, checked against the file it leaves. Light enough (core, formats and the
// recorder) for the sanitizer builds (scripts/sanitize: ASan+UBSan and TSan).
#include <cerrno>
#include <chrono>
#include <thread>

#include <catch2/catch.hpp>
#include <unistd.h>

#include "core/time.hpp"
#include "formats/recording.hpp"
#include "outputs/recording/recorder.hpp"
#include "tests/test_support.hpp"

using namespace facecap;
using Catch::Contains;
namespace fs = std::filesystem;

namespace {

// A disk with room for `limit` bytes of a recording, then ENOSPC.
struct FullDisk {
  static inline uint64_t limit = 0;
  static ssize_t write(int fd, const void* data, std::size_t size, off_t offset) {
    if (uint64_t(offset) >= limit) {
      errno = ENOSPC;
      return -1;
    }
    return ::pwrite(fd, data, std::min<uint64_t>(size, limit - uint64_t(offset)), offset);
  }
};

outputs::RecorderOptions small_recording(const fs::path& file) {
  outputs::RecorderOptions options;
  options.file = file;
  options.header.marker_labels = {"nose", "chin", "brow"};
  options.header.shape_names = {"jawOpen", "eyeBlink_L"};
  return options;
}

// Offers loop frames for `seconds` at about 500 Hz, numbered from `first`; returns the next number.
int64_t offer_frames(outputs::Recorder& recorder, int64_t first, double seconds) {
  MarkerFrame markers = make_marker_frame({"nose", "chin", "brow"});
  SolvedFrame solved;
  solved.resize(2, 0);
  const int64_t until = monotonic_now_ns() + int64_t(seconds * kNsPerSecond);
  int64_t n = first;
  for (; monotonic_now_ns() < until; ++n) {
    markers.frame_no = solved.frame_no = n;
    recorder.offer(markers, solved);
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  return n;
}

}  // namespace

TEST_CASE("the recorder counts every frame a full disk kept out of the file as dropped, and the file reads back") {
  const fs::path file = test::scratch_dir("recorder-full") / "take.fcrec";
  FullDisk::limit = 40'000;  // some hundred loop frames, then full partway through a chunk
  outputs::RecorderOptions options = small_recording(file);
  options.write = &FullDisk::write;
  outputs::Recorder recorder(options, 0);
  offer_frames(recorder, 0, 1.5);
  recorder.stop();
  const outputs::RecorderCounters counters = recorder.counters();
  const outputs::SinkHealth health = recorder.health();
  INFO(health.offered << " offered, " << health.delivered << " delivered, " << health.dropped << " dropped");
  CHECK(health.failed);
  CHECK(counters.errors == 1);
  CHECK_THAT(recorder.failure(), Contains("No space left on device"));
  CHECK(health.offered == health.delivered + health.dropped);  // every frame is either in the file or dropped
  CHECK(health.dropped > health.offered / 2);
  // What the counters call written is exactly what the file holds, whole and in order.
  const formats::RecordingReader reader(file);
  CHECK(reader.skipped().empty());
  CHECK_FALSE(reader.truncated());
  CHECK(reader.marker_frame_count() == counters.marker_frames);
  CHECK(reader.solved_frame_count() == counters.solved_frames);
  CHECK(counters.solved_frames == health.delivered);
  CHECK(counters.marker_frames - health.delivered <= 1);  // a frame's marker chunk may fit where its solved one did not
  REQUIRE(counters.marker_frames > 20);
  MarkerFrame last;
  reader.read_marker_frame(reader.marker_frame_count() - 1, last);
  CHECK(last.frame_no == int64_t(counters.marker_frames) - 1);
  CHECK(fs::file_size(file) <= FullDisk::limit);
}

TEST_CASE("the recorder reports a recording directory deleted under it and counts its frames as lost") {
  const fs::path dir = test::scratch_dir("recorder-deleted") / "recordings";
  outputs::Recorder recorder(small_recording(dir / "take.fcrec"), 0);
  const int64_t next = offer_frames(recorder, 0, 0.3);
  CHECK(recorder.counters().marker_frames > 50);
  fs::remove_all(dir);
  offer_frames(recorder, next, 1.3);  // the check runs once a second
  CHECK(recorder.health().failed);
  recorder.stop();
  const outputs::RecorderCounters counters = recorder.counters();
  const outputs::SinkHealth health = recorder.health();
  CHECK(counters.errors == 1);
  CHECK(counters.marker_frames == 0);
  CHECK(health.delivered == 0);
  CHECK(health.dropped == health.offered);
  CHECK_THAT(recorder.failure(), Contains("deleted"));
  CHECK_FALSE(fs::exists(dir));
}
