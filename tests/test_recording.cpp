// .fcrec recordings: round trip, index, crash safety (truncation at every byte), versions.
#include <algorithm>
#include <array>
#include <cerrno>
#include <csignal>
#include <cstring>
#include <cmath>
#include <functional>
#include <limits>
#include <random>

#include <sched.h>
#include <sys/mount.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <catch2/catch.hpp>

#include "core/error.hpp"
#include "core/io.hpp"
#include "formats/recording.hpp"
#include "tests/formats_test_support.hpp"
#include "tests/test_support.hpp"

using namespace facecap;
using namespace facecap::formats;

namespace {

RecordingHeader test_header() {
  RecordingHeader h;
  h.rig_name = "ict-narrow";
  h.rig_hash = 0x0123456789abcdefull;
  h.source_description = "sim: 3 markers";
  h.calibration = "[calibration]\nscale = 1.25\n";
  h.units = "mm";
  h.rate_hz = 120.0;
  h.created_unix_ns = 1'700'000'000'000'000'000;
  h.marker_labels = {"nose", "chin", "brow"};
  h.shape_names = {"jawOpen", "eyeBlink_L"};
  h.rig_units = "cm";
  h.solver_settings = "method = \"nonlinear\"\nalpha = 0.1\n";
  return h;
}

MarkerFrame test_marker_frame(int64_t i) {
  MarkerFrame f;
  f.frame_no = 100 + i;
  f.source_time_ns = i * 8'333'333;
  f.receive_time_ns = 5'000'000'000 + i * 8'400'000;
  f.timecode = Timecode{1, 2, 3, uint8_t(i % 60), 0.5f, 60};
  for (int k = 0; k < 3; ++k) {
    Marker m;
    m.id = k + 10;
    m.label.assign(test_header().marker_labels[std::size_t(k)]);
    m.position = Eigen::Vector3d(double(i) + 0.125 * k, -double(k), 1e-3 * double(i));
    if ((i + k) % 4 == 0) set_missing(m);
    f.markers.push_back(m);
  }
  return f;
}

SolvedFrame test_solved_frame(int64_t i) {
  SolvedFrame f;
  f.resize(2, 4);
  f.frame_no = 100 + i;
  f.source_time_ns = i * 8'333'333;
  f.receive_time_ns = 7;
  f.solve_start_ns = 1000 + i;
  f.solve_end_ns = 2000 + i;
  f.head_rotation = Eigen::Quaterniond(Eigen::AngleAxisd(0.1 * double(i), Eigen::Vector3d::UnitY()));
  f.head_translation = Eigen::Vector3d(1, 2, double(i));
  f.weights << 0.25f * float(i), 1.0f;
  for (Eigen::Index v = 0; v < 4; ++v) f.vertices.col(v) = Eigen::Vector3f(float(v), float(i), -1.0f);
  for (std::size_t s = 0; s < f.stage_ns.size(); ++s) f.stage_ns[s] = int64_t(s) * 10 + i;
  f.collision_constraints = 3;
  f.markers_used = 2;
  f.flags = kSolvedHeadPoseHeld;
  f.fold_deadline_rounds = int32_t(i) - 1;  // -1: not stopped, then after 0 rounds
  return f;
}

void check_marker_frame(const MarkerFrame& got, const MarkerFrame& want) {
  CHECK(got.frame_no == want.frame_no);
  CHECK(got.source_time_ns == want.source_time_ns);
  CHECK(got.receive_time_ns == want.receive_time_ns);
  CHECK(got.timecode == want.timecode);
  REQUIRE(got.markers.size() == want.markers.size());
  for (std::size_t k = 0; k < got.markers.size(); ++k) {
    CHECK(got.markers[k].id == want.markers[k].id);
    CHECK(got.markers[k].label == want.markers[k].label);
    CHECK(got.markers[k].flags == want.markers[k].flags);
    if (want.markers[k].present()) CHECK(got.markers[k].position == want.markers[k].position);
  }
}

void check_solved_frame(const SolvedFrame& got, const SolvedFrame& want) {
  CHECK(got.frame_no == want.frame_no);
  CHECK(got.solve_end_ns == want.solve_end_ns);
  CHECK(got.head_rotation.coeffs() == want.head_rotation.coeffs());
  CHECK(got.head_translation == want.head_translation);
  CHECK(got.weights == want.weights);
  CHECK(got.vertices == want.vertices);
  CHECK(got.stage_ns == want.stage_ns);
  CHECK(got.collision_constraints == want.collision_constraints);
  CHECK(got.markers_used == want.markers_used);
  CHECK(got.flags == want.flags);
  CHECK(got.fold_deadline_rounds == want.fold_deadline_rounds);
}

// A small recording: 3 marker frames and 2 solved frames, interleaved.
std::filesystem::path write_small_recording(const std::filesystem::path& dir) {
  const auto path = dir / "small.fcrec";
  RecordingWriter writer(path, test_header());
  for (int64_t i = 0; i < 3; ++i) {
    writer.append_marker_frame(test_marker_frame(i));
    if (i < 2) writer.append_solved_frame(test_solved_frame(i));
  }
  writer.close();
  return path;
}

}  // namespace

TEST_CASE("Recording: header and frames round-trip through the index", "[recording]") {
  const auto path = write_small_recording(facecap::test::scratch_dir("recording-roundtrip"));
  const RecordingReader reader(path);
  CHECK_FALSE(reader.index_rebuilt());
  CHECK_FALSE(reader.truncated());
  const RecordingHeader& h = reader.header();
  const RecordingHeader want = test_header();
  CHECK(h.format_version == kRecordingFormatVersion);
  CHECK(h.min_reader_version == kRecordingReaderVersion);
  CHECK(h.rig_name == want.rig_name);
  CHECK(h.rig_hash == want.rig_hash);
  CHECK(h.source_description == want.source_description);
  CHECK(h.calibration == want.calibration);
  CHECK(h.units == want.units);
  CHECK(h.rate_hz == want.rate_hz);
  CHECK(h.created_unix_ns == want.created_unix_ns);
  CHECK(h.marker_labels == want.marker_labels);
  CHECK(h.rig_units == want.rig_units);
  CHECK(h.solver_settings == want.solver_settings);
  CHECK(h.shape_names == want.shape_names);
  REQUIRE(reader.marker_frame_count() == 3);
  REQUIRE(reader.solved_frame_count() == 2);
  CHECK(reader.index().size() == 5);
  MarkerFrame marker_frame;
  SolvedFrame solved_frame;
  for (std::size_t i = 0; i < 3; ++i) {
    reader.read_marker_frame(i, marker_frame);
    check_marker_frame(marker_frame, test_marker_frame(int64_t(i)));
  }
  for (std::size_t i = 0; i < 2; ++i) {
    reader.read_solved_frame(i, solved_frame);
    check_solved_frame(solved_frame, test_solved_frame(int64_t(i)));
  }
  CHECK_THROWS_AS(reader.read_marker_frame(3, marker_frame), Error);
}

TEST_CASE("Recording: the start state goes before the first frame, reads back, and a damaged one is named, not fatal",
          "[recording]") {
  const auto dir = facecap::test::scratch_dir("recording-start-state");
  CHECK(RecordingReader(write_small_recording(dir)).start_state().empty());
  const std::string state = "state bytes";
  {
    RecordingWriter writer(dir / "state.fcrec", test_header());
    writer.append_start_state(std::span<const char>(state.data(), state.size()));
    CHECK_THROWS_WITH(writer.append_start_state(std::span<const char>(state.data(), state.size())),
                      Catch::Contains("the start state goes before the first frame, once"));
    writer.append_marker_frame(test_marker_frame(0));
    writer.append_solved_frame(test_solved_frame(0));
    writer.close();
  }
  const RecordingReader reader(dir / "state.fcrec");
  CHECK(std::string(reader.start_state().begin(), reader.start_state().end()) == state);
  CHECK(take_from_recording(reader).metadata_value("start_state_bytes") == "11");
  CHECK(reader.start_state_damage().empty());
  CHECK(reader.marker_frame_count() == 1);
  CHECK(reader.solved_frame_count() == 1);
  // A flipped bit in the state: reported, and the frames read as usual.
  auto bytes = read_file_bytes(dir / "state.fcrec");
  const std::size_t at = std::string_view(bytes.data(), bytes.size()).find(state);
  REQUIRE(at != std::string_view::npos);
  bytes[at] ^= 0x08;
  const RecordingReader damaged(std::span<const char>(bytes.data(), bytes.size()), "damaged.fcrec");
  CHECK(damaged.start_state().empty());
  CHECK_THAT(damaged.start_state_damage(), Catch::Contains("checksum mismatch in chunk STAT"));
  CHECK_THAT(take_from_recording(damaged).warnings.front(),
             Catch::Contains("damaged.fcrec: start state unreadable: checksum mismatch in chunk STAT"));
  CHECK(damaged.marker_frame_count() == 1);
  CHECK(damaged.solved_frame_count() == 1);
}

TEST_CASE("Recording cut off at every byte reads back up to its last complete chunk", "[recording]") {
  const auto bytes = read_file_bytes(write_small_recording(facecap::test::scratch_dir("recording-truncate")));
  // Where each frame chunk ends: where the next begins, and the last where INDX begins
  // (the TAIL's first payload word, 16 bytes before the end of a closed file).
  const RecordingReader full(bytes, "full");
  uint64_t index_offset = 0;
  std::memcpy(&index_offset, bytes.data() + bytes.size() - 16, 8);
  const uint64_t header_end = full.index().front().offset;
  // The last frame chunk ends where HCPY (HEAD's copy, as long as HEAD) begins.
  const uint64_t head_copy_offset = index_offset - (header_end - 16);
  std::vector<uint64_t> chunk_end;
  for (std::size_t c = 0; c < full.index().size(); ++c) {
    chunk_end.push_back(c + 1 < full.index().size() ? full.index()[c + 1].offset : head_copy_offset);
  }

  MarkerFrame marker_frame;
  SolvedFrame solved_frame;
  std::size_t refused = 0;
  for (std::size_t cut = 0; cut < bytes.size(); ++cut) {
    INFO("cut at byte " << cut << " of " << bytes.size());
    const std::span<const char> part(bytes.data(), cut);
    if (cut < header_end) {
      CHECK_THROWS_AS(RecordingReader(part, "cut"), Error);  // no complete header: nothing to replay
      ++refused;
      continue;
    }
    const RecordingReader reader(part, "cut");
    std::size_t want_markers = 0, want_solved = 0;
    for (std::size_t c = 0; c < chunk_end.size(); ++c) {
      if (chunk_end[c] <= cut) ++(full.index()[c].kind == ChunkKind::kMarkerFrame ? want_markers : want_solved);
    }
    CHECK(reader.index_rebuilt());
    REQUIRE(reader.header().rig_name == "ict-narrow");
    REQUIRE(reader.marker_frame_count() == want_markers);
    REQUIRE(reader.solved_frame_count() == want_solved);
    const bool at_boundary = cut == header_end || cut == index_offset /* HCPY end */ ||
                             cut == bytes.size() - 32 /* INDX end, TAIL start */ ||
                             std::find(chunk_end.begin(), chunk_end.end(), cut) != chunk_end.end();
    CHECK(reader.truncated() == !at_boundary);
    for (std::size_t i = 0; i < reader.marker_frame_count(); ++i) {
      reader.read_marker_frame(i, marker_frame);
      check_marker_frame(marker_frame, test_marker_frame(int64_t(i)));
    }
    for (std::size_t i = 0; i < reader.solved_frame_count(); ++i) {
      reader.read_solved_frame(i, solved_frame);
      check_solved_frame(solved_frame, test_solved_frame(int64_t(i)));
    }
  }
  CHECK(refused == header_end);
  CHECK(header_end > 100);  // the header holds the calibration text and names
}

TEST_CASE("Recording: a cut exactly at a chunk boundary is not flagged truncated", "[recording]") {
  const auto bytes = read_file_bytes(write_small_recording(facecap::test::scratch_dir("recording-boundary")));
  const RecordingReader full(bytes, "full");
  const uint64_t second = full.index()[1].offset;
  const RecordingReader at_boundary(std::span<const char>(bytes).first(second), "boundary");
  CHECK_FALSE(at_boundary.truncated());
  CHECK(at_boundary.marker_frame_count() == 1);
  const RecordingReader inside(std::span<const char>(bytes).first(second + 3), "inside");
  CHECK(inside.truncated());
  CHECK(inside.stop_reason() == fmt::format("incomplete chunk header at byte {}", second));
}

TEST_CASE("Recording: flushed frames are readable while the writer is still open", "[recording]") {
  const auto path = facecap::test::scratch_dir("recording-flush") / "live.fcrec";
  RecordingWriter writer(path, test_header());
  writer.append_marker_frame(test_marker_frame(0));
  writer.append_marker_frame(test_marker_frame(1));
  CHECK(RecordingReader(path).marker_frame_count() == 0);  // still buffered
  writer.flush();
  {
    const RecordingReader reader(path);
    CHECK(reader.index_rebuilt());
    CHECK_FALSE(reader.truncated());
    CHECK(reader.marker_frame_count() == 2);
  }
  writer.append_solved_frame(test_solved_frame(0));
  writer.close();
  const RecordingReader reader(path);
  CHECK_FALSE(reader.index_rebuilt());
  CHECK(reader.marker_frame_count() == 2);
  CHECK(reader.solved_frame_count() == 1);
  CHECK_THROWS_AS(writer.append_marker_frame(test_marker_frame(2)), Error);
}

TEST_CASE("Recording: existing files are not overwritten unless asked", "[recording]") {
  const auto path = write_small_recording(facecap::test::scratch_dir("recording-exists"));
  CHECK_THROWS_WITH(RecordingWriter(path, test_header()),
                    Catch::Contains("cannot create recording") && Catch::Contains("exists"));
  RecordingWriter(path, test_header(), RecordingWriter::Options{.overwrite = true}).close();
  CHECK(RecordingReader(path).marker_frame_count() == 0);
}

TEST_CASE("Recording: a damaged chunk costs its own frame, with or without the index", "[recording]") {
  const auto bytes = read_file_bytes(write_small_recording(facecap::test::scratch_dir("recording-damage")));
  const RecordingReader full(bytes, "full");
  const uint64_t second = full.index()[1].offset;  // the first solved frame

  auto flipped = bytes;
  flipped[second + 40] ^= 0x10;  // inside the payload
  const std::string why = fmt::format("checksum mismatch in chunk SLVF at byte {}", second);
  const RecordingReader with_index(flipped, "flipped.fcrec");
  CHECK_FALSE(with_index.index_rebuilt());
  CHECK_FALSE(with_index.truncated());
  CHECK(with_index.marker_frame_count() == 3);
  REQUIRE(with_index.solved_frame_count() == 1);
  REQUIRE(with_index.skipped().size() == 1);
  CHECK(with_index.skipped()[0].offset == second);
  CHECK(with_index.skipped()[0].bytes == full.index()[2].offset - second);
  CHECK(with_index.skipped()[0].why == why + " (frame 100)");
  SolvedFrame solved;
  with_index.read_solved_frame(0, solved);
  check_solved_frame(solved, test_solved_frame(1));

  // Without the tail the scan skips the damaged chunk and resynchronises on the next.
  const RecordingReader scanned(std::span<const char>(flipped).first(flipped.size() - 8), "flipped.fcrec");
  CHECK(scanned.index_rebuilt());
  CHECK(scanned.truncated());  // the cut TAIL
  CHECK(scanned.marker_frame_count() == 3);
  REQUIRE(scanned.solved_frame_count() == 1);
  REQUIRE(scanned.skipped().size() == 1);
  CHECK(scanned.skipped()[0].offset == second);
  CHECK(scanned.skipped()[0].why == why);
  CHECK_THAT(scanned.damage_summary(), Catch::StartsWith("1 damaged stretch skipped (") && Catch::Contains(why) &&
                                           Catch::Contains("; cut off: "));
  scanned.read_solved_frame(0, solved);
  check_solved_frame(solved, test_solved_frame(1));
  MarkerFrame marker;
  scanned.read_marker_frame(2, marker);
  check_marker_frame(marker, test_marker_frame(2));
  // The take keeps every frame it could read and says what it skipped.
  const MarkerTake take = take_from_recording(scanned);
  CHECK(take.frames.size() == 3);
  REQUIRE_FALSE(take.warnings.empty());
  CHECK_THAT(take.warnings.back(), Catch::Contains("recording damaged: 1 damaged stretch skipped"));
}

TEST_CASE("Recording: flipped bits anywhere in frame chunks lose those frames only", "[recording]") {
  // 200 loop frames (a marker and a solved chunk each); one bit flipped in each of 12
  // chunks, in the header (kind, size, checksum) or the payload.
  const auto path = facecap::test::scratch_dir("recording-bits") / "take.fcrec";
  {
    RecordingWriter writer(path, test_header());
    for (int64_t i = 0; i < 200; ++i) {
      writer.append_marker_frame(test_marker_frame(i));
      writer.append_solved_frame(test_solved_frame(i));
    }
    writer.close();
  }
  auto bytes = read_file_bytes(path);
  const RecordingReader clean(bytes, "clean");
  REQUIRE(clean.index().size() == 400);
  std::vector<std::size_t> damaged_chunks;
  for (std::size_t k = 0; k < 12; ++k) {
    const std::size_t chunk = 7 + 31 * k;  // every kind of chunk, both ends of the file
    const std::size_t within = std::array<std::size_t, 6>{0, 5, 12, 16, 30, 60}[k % 6];  // kind, size, checksum, payload
    bytes[clean.index()[chunk].offset + within] ^= char(1 << (k % 8));
    damaged_chunks.push_back(chunk);
  }
  auto frames_left = [&](ChunkKind kind) {
    std::size_t n = 0;
    for (std::size_t c = 0; c < 400; ++c)
      if (clean.index()[c].kind == kind && std::find(damaged_chunks.begin(), damaged_chunks.end(), c) == damaged_chunks.end()) ++n;
    return n;
  };
  const std::size_t want_markers = frames_left(ChunkKind::kMarkerFrame), want_solved = frames_left(ChunkKind::kSolvedFrame);
  CHECK(want_markers + want_solved == 388);
  // Indexed, then cut before the INDX (the writer killed before close): the same frames.
  for (const std::size_t size : {bytes.size(), std::size_t(clean.index().back().offset) + 200}) {
    INFO("file of " << size << " bytes");
    const RecordingReader reader(std::span<const char>(bytes).first(size), "damaged.fcrec");
    CHECK(reader.index_rebuilt() == (size != bytes.size()));
    CHECK(reader.skipped().size() == 12);
    const std::size_t last_lost = size == bytes.size() ? 0 : 1;  // the cut removes the last solved frame
    CHECK(reader.marker_frame_count() == want_markers);
    CHECK(reader.solved_frame_count() == want_solved - last_lost);
    // Every frame read is the frame written, in order, none repeated.
    MarkerFrame marker;
    int64_t previous = -1;
    for (std::size_t i = 0; i < reader.marker_frame_count(); ++i) {
      reader.read_marker_frame(i, marker);
      CHECK(marker.frame_no > previous);
      previous = marker.frame_no;
      check_marker_frame(marker, test_marker_frame(marker.frame_no - 100));
    }
    const MarkerTake take = take_from_recording(reader);
    CHECK(take.frames.size() == want_markers);
  }
}

TEST_CASE("Recording: 20 random bit flips in HEAD lose no frame (its copy), and --salvage reads an unclosed one",
          "[recording][salvage]") {
  const auto path = facecap::test::scratch_dir("recording-head-bits") / "take.fcrec";
  constexpr int64_t kFrames = 92;  // 184 frame chunks, as the take of issue 35
  {
    RecordingWriter writer(path, test_header());
    for (int64_t i = 0; i < kFrames; ++i) {
      writer.append_marker_frame(test_marker_frame(i));
      writer.append_solved_frame(test_solved_frame(i));
    }
    writer.close();
  }
  const std::vector<char> clean = read_file_bytes(path);
  const RecordingReader intact(clean, "intact");
  const std::size_t head_end = std::size_t(intact.index().front().offset);  // preamble, HEAD's header and payload
  CHECK(intact.header_damage().empty());
  auto check_all_frames = [&](const RecordingReader& reader, int64_t marker_frames, int64_t solved_frames) {
    REQUIRE(reader.marker_frame_count() == std::size_t(marker_frames));
    REQUIRE(reader.solved_frame_count() == std::size_t(solved_frames));
    MarkerFrame marker;
    SolvedFrame solved;
    for (std::size_t i = 0; i < std::size_t(marker_frames); ++i) {
      reader.read_marker_frame(i, marker);
      check_marker_frame(marker, test_marker_frame(int64_t(i)));
    }
    for (std::size_t i = 0; i < std::size_t(solved_frames); ++i) {
      reader.read_solved_frame(i, solved);
      check_solved_frame(solved, test_solved_frame(int64_t(i)));
    }
  };
  std::mt19937 rng(35);
  std::uniform_int_distribution<std::size_t> byte_in_head(16, head_end - 1);  // HEAD: its chunk header and payload
  for (int flip = 0; flip < 20; ++flip) {
    std::vector<char> bytes = clean;  // a fresh copy for every flip
    const std::size_t at = byte_in_head(rng);
    const int bit = int(rng() % 8);
    bytes[at] = char(bytes[at] ^ (1 << bit));
    INFO("bit " << bit << " of byte " << at);
    const RecordingReader reader(bytes, "flipped.fcrec");
    CHECK_THAT(reader.header_damage(), Catch::Contains("HEAD damaged") && Catch::Contains("from the copy at byte"));
    CHECK_THAT(reader.damage_summary(), Catch::Contains("HEAD damaged"));
    CHECK(reader.header().rig_name == "ict-narrow");
    CHECK(reader.header().shape_names == test_header().shape_names);
    CHECK_FALSE(reader.index_rebuilt());
    check_all_frames(reader, kFrames, kFrames);
  }

  // Killed before close: no copy. Refused, naming --salvage; salvaged, every frame is read.
  std::vector<char> unclosed(clean.begin(), clean.begin() + std::ptrdiff_t(intact.index().back().offset));
  unclosed[33] = char(unclosed[33] ^ 0x10);  // HEAD payload: the rig name is 4,106 bytes long
  CHECK_THROWS_WITH(RecordingReader(unclosed, "unclosed.fcrec"),
                    Catch::Contains("unclosed.fcrec @ byte 16") && Catch::Contains("no intact copy") &&
                        Catch::Contains("--salvage"));
  const RecordingReader salvaged(unclosed, "unclosed.fcrec", {.salvage = true});
  CHECK_THAT(salvaged.header_damage(), Catch::Contains("salvaged") && Catch::Contains("frames looked for from byte 32 on"));
  CHECK(salvaged.index_rebuilt());
  CHECK(salvaged.header().rig_name.empty());  // HEAD no longer decodes: its fields are unknown
  check_all_frames(salvaged, kFrames, kFrames - 1);  // the cut took the last solved frame
  const MarkerTake take = take_from_recording(salvaged);
  CHECK(take.frames.size() == std::size_t(kFrames));
  CHECK(take.labels == test_header().marker_labels);  // from the frames' own labels
}

TEST_CASE("Recording: a take from frames timed at both ends of i64 gets a finite rate, no signed overflow",
          "[recording]") {
  // Found by the fcrec fuzz target under UBSan: last minus first source time overflowed.
  const auto path = facecap::test::scratch_dir("recording-time-span") / "span.fcrec";
  RecordingHeader header = test_header();
  header.rate_hz = 0;  // unknown: the rate comes from the frames' times
  {
    RecordingWriter writer(path, header);
    MarkerFrame frame = test_marker_frame(0);
    frame.source_time_ns = std::numeric_limits<int64_t>::min() + 1;
    writer.append_marker_frame(frame);
    frame.source_time_ns = std::numeric_limits<int64_t>::max();
    writer.append_marker_frame(frame);
    writer.close();
  }
  const MarkerTake take = take_from_recording(RecordingReader(path));
  // One interval of 1.8e19 ns: about 5.4e-11 Hz, which cannot time the take (a wrapped
  // difference was negative: no rate, and no word of it).
  CHECK(take.rate_hz == 0);
  REQUIRE(take.warnings.size() == 1);
  CHECK_THAT(take.warnings[0], Catch::Contains("frame rate 5.42") && Catch::Contains("e-11 Hz is not usable"));
}

TEST_CASE("Recording: a file for a newer reader is refused; a bad magic is named", "[recording]") {
  auto bytes = read_file_bytes(write_small_recording(facecap::test::scratch_dir("recording-version")));
  bytes[10] = char(kRecordingReaderVersion + 1);
  CHECK_THROWS_WITH(RecordingReader(bytes, "future.fcrec"),
                    Catch::Contains("future.fcrec @ byte 10") && Catch::Contains("needs reader version 2"));
  bytes[0] = 'X';
  CHECK_THROWS_WITH(RecordingReader(bytes, "other.bin"), Catch::Contains("not a facecap recording"));
}

TEST_CASE("Recording <-> take: labels become slots, absent markers missing", "[recording]") {
  const auto dir = facecap::test::scratch_dir("recording-take");
  const MarkerTake take = facecap::test::synthetic_take(40, 6, 100.0);
  write_recording(dir / "take.fcrec", take, "test");
  const MarkerTake back = take_from_recording(RecordingReader(dir / "take.fcrec"));
  CHECK(back.format == TakeFormat::kRecording);
  CHECK(back.rate_hz == 100.0);
  CHECK(back.units == "mm");
  CHECK(back.first_frame == 1);
  facecap::test::require_same_points(take, back, 0.0);

  // A live source whose marker set changes: a marker appears late, one has no label. Its
  // slate shows in the take's metadata (what `facecap inspect` prints), empty fields not.
  RecordingHeader header;
  header.take = "t7";
  header.actor = "ann";
  header.shot = "3";
  {
    RecordingWriter writer(dir / "live.fcrec", header);
    MarkerFrame f0;
    f0.frame_no = 5;
    f0.source_time_ns = 0;
    Marker a;
    a.label.assign("a");
    a.position = Eigen::Vector3d(1, 2, 3);
    f0.markers = {a};
    writer.append_marker_frame(f0);
    MarkerFrame f1 = f0;
    f1.frame_no = 6;
    f1.source_time_ns = 10'000'000;
    Marker b;
    b.id = 42;
    b.position = Eigen::Vector3d(4, 5, 6);
    f1.markers = {b};
    writer.append_marker_frame(f1);
  }  // the destructor closes the file
  const MarkerTake live = take_from_recording(RecordingReader(dir / "live.fcrec"));
  CHECK(live.labels == std::vector<std::string>{"a", "id_42"});
  CHECK(live.metadata_value("take") == "t7");
  CHECK(live.metadata_value("actor") == "ann");
  CHECK(live.metadata_value("shot") == "3");
  CHECK(std::none_of(live.metadata.begin(), live.metadata.end(), [](const auto& kv) { return kv.first == "scene"; }));
  CHECK(std::none_of(back.metadata.begin(), back.metadata.end(), [](const auto& kv) { return kv.first == "take"; }));
  REQUIRE(live.frames.size() == 2);
  CHECK(live.frames[0].markers[0].position == Eigen::Vector3d(1, 2, 3));
  CHECK_FALSE(live.frames[0].markers[1].present());
  CHECK_FALSE(live.frames[1].markers[0].present());
  CHECK(live.frames[1].markers[1].position == Eigen::Vector3d(4, 5, 6));
  CHECK(live.rate_hz == Approx(100.0));  // from the timestamps: the header had none
  CHECK(count_gaps(live).missing_samples == 2);
}

TEST_CASE("Recording: a format version 1 header reads without the fields version 2 appended", "[recording]") {
  const auto path = write_small_recording(facecap::test::scratch_dir("recording-v1"));
  std::vector<char> bytes = read_file_bytes(path);
  bytes[8] = 1;  // format_version: the HEAD payload's appended fields are then unknown
  const RecordingReader reader(std::span<const char>(bytes), "v1");
  CHECK(reader.header().format_version == 1);
  CHECK(reader.header().shape_names == test_header().shape_names);
  CHECK(reader.header().rig_units.empty());
  CHECK(reader.header().solver_settings.empty());
  CHECK(reader.solved_frame_count() == 2);
}

namespace {

// A disk that takes bytes up to a limit and then fails with an errno, handing out at most
// chunk_bytes per call (short writes); what a full disk or a quota does to pwrite(2).
struct FailingDisk {
  static inline uint64_t limit = 0;
  static inline int error = ENOSPC;
  static inline std::size_t chunk_bytes = 1000;
  static inline int failures_left = 1 << 30;  // after this many failed calls, writes succeed again
  static ssize_t write(int fd, const void* data, std::size_t size, off_t offset) {
    const uint64_t room = uint64_t(offset) < limit ? limit - uint64_t(offset) : 0;
    if (room == 0 && failures_left > 0) {
      --failures_left;
      errno = error;
      return -1;
    }
    const std::size_t n = std::min({size, chunk_bytes, failures_left > 0 ? std::size_t(room) : size});
    return ::pwrite(fd, data, n, offset);
  }
};

// Appends loop frames (a marker and a solved chunk each) until the writer throws; returns
// how many frames were appended without an error and the error's text.
std::pair<int64_t, std::string> append_until_failure(RecordingWriter& writer, int64_t frames) {
  for (int64_t i = 0; i < frames; ++i) {
    try {
      writer.append_marker_frame(test_marker_frame(i));
      writer.append_solved_frame(test_solved_frame(i));
    } catch (const Error& e) {
      return {i, e.what()};
    }
  }
  return {frames, ""};
}

// The file holds exactly frames 0..n-1 of both kinds, nothing repeated or shifted.
void check_frames_are_a_prefix(const RecordingReader& reader, std::size_t markers, std::size_t solved) {
  CHECK(reader.skipped().empty());
  CHECK_FALSE(reader.truncated());
  REQUIRE(reader.marker_frame_count() == markers);
  REQUIRE(reader.solved_frame_count() == solved);
  MarkerFrame marker;
  SolvedFrame solved_frame;
  for (std::size_t i = 0; i < markers; ++i) {
    reader.read_marker_frame(i, marker);
    check_marker_frame(marker, test_marker_frame(int64_t(i)));
  }
  for (std::size_t i = 0; i < solved; ++i) {
    reader.read_solved_frame(i, solved_frame);
    check_solved_frame(solved_frame, test_solved_frame(int64_t(i)));
  }
}

}  // namespace

TEST_CASE("Recording: short writes resume exactly where the file ends", "[recording][disk]") {
  const auto path = facecap::test::scratch_dir("recording-short") / "take.fcrec";
  FailingDisk::limit = uint64_t(1) << 40;
  FailingDisk::chunk_bytes = 7;  // every chunk split across many calls
  FailingDisk::failures_left = 0;
  RecordingWriter writer(path, test_header(), {.buffer_bytes = 4096, .write = &FailingDisk::write});
  const auto [appended, error] = append_until_failure(writer, 300);
  CHECK(error.empty());
  writer.close();
  const RecordingReader reader(path);
  CHECK_FALSE(reader.index_rebuilt());
  check_frames_are_a_prefix(reader, 300, 300);
}

TEST_CASE("Recording: a full disk ends the file at its last whole chunk, never re-writing a partial one", "[recording][disk]") {
  const auto dir = facecap::test::scratch_dir("recording-full");
  FailingDisk::error = ENOSPC;
  FailingDisk::chunk_bytes = 1000;
  FailingDisk::limit = 150'000;  // full partway through a chunk of the third 64 KiB buffer
  SECTION("the disk stays full: no index, the scan reads every frame written") {
    FailingDisk::failures_left = 1 << 30;
    const auto path = dir / "stays-full.fcrec";
    RecordingWriter writer(path, test_header(), {.buffer_bytes = 64 << 10, .write = &FailingDisk::write});
    const auto [appended, error] = append_until_failure(writer, 2000);
    CHECK_THAT(error, Catch::Contains("write failed: No space left on device; the file keeps its first"));
    REQUIRE(appended < 2000);
    // Later appends and flushes say why the recording stopped, and write nothing.
    CHECK_THROWS_WITH(writer.append_marker_frame(test_marker_frame(0)), Catch::Contains("recording stopped: write failed"));
    CHECK_THROWS_WITH(writer.flush(), Catch::Contains("recording stopped"));
    const std::size_t markers = writer.marker_frames(), solved = writer.solved_frames();
    CHECK(markers < std::size_t(appended));  // the frames of the failed buffer are not counted
    CHECK(markers - solved <= 1);
    writer.close();  // no room for the index: closes without throwing again
    CHECK(std::filesystem::file_size(path) <= 150'000);
    const RecordingReader reader(path);
    CHECK(reader.index_rebuilt());
    check_frames_are_a_prefix(reader, markers, solved);
  }
  SECTION("one moment of ENOSPC: the file stops there, and the index is written at close") {
    FailingDisk::failures_left = 1;
    const auto path = dir / "moment.fcrec";
    RecordingWriter writer(path, test_header(), {.buffer_bytes = 64 << 10, .write = &FailingDisk::write});
    const auto [appended, error] = append_until_failure(writer, 2000);
    CHECK_THAT(error, Catch::Contains("No space left on device"));
    const std::size_t markers = writer.marker_frames(), solved = writer.solved_frames();
    writer.close();
    const RecordingReader reader(path);
    CHECK_FALSE(reader.index_rebuilt());  // the index fitted once space was back
    check_frames_are_a_prefix(reader, markers, solved);
    CHECK(markers > 100);
  }
}

namespace {

// What a child process's writer did: 0 when it failed with the expected error (1: the
// child could not set up, 2: another outcome), and the frames the writer counted.
struct ChildReport {
  uint64_t status = 2, markers = 0, solved = 0;
};

// Runs body in a forked child (whose limits and mounts stay there) and returns its report.
ChildReport in_child(const std::function<ChildReport()>& body) {
  int fds[2];
  REQUIRE(::pipe(fds) == 0);
  const pid_t child = ::fork();
  REQUIRE(child >= 0);
  if (child == 0) {
    ::close(fds[0]);
    ChildReport report;
    try {
      report = body();
    } catch (...) {
      report.status = 2;
    }
    [[maybe_unused]] const ssize_t n = ::write(fds[1], &report, sizeof report);
    ::_exit(0);
  }
  ::close(fds[1]);
  ChildReport report;
  CHECK(::read(fds[0], &report, sizeof report) == ssize_t(sizeof report));
  ::close(fds[0]);
  ::waitpid(child, nullptr, 0);
  return report;
}

// Writes frames to path until the writer fails; the report says whether it failed with
// `expected` in its message, and what it counted.
ChildReport write_until_full(const std::filesystem::path& path, const std::string& expected) {
  RecordingWriter writer(path, test_header(), {.buffer_bytes = 16 << 10});
  const auto result = append_until_failure(writer, 5000);
  ChildReport report{result.second.find(expected) == std::string::npos ? 2u : 0u, writer.marker_frames(),
                     writer.solved_frames()};
  writer.close();
  return report;
}

}  // namespace

TEST_CASE("Recording: a file-size limit (EFBIG) ends the file at its last whole chunk", "[recording][disk]") {
  // RLIMIT_FSIZE with SIGXFSZ ignored: the kernel's own EFBIG.
  const auto path = facecap::test::scratch_dir("recording-efbig") / "take.fcrec";
  const ChildReport report = in_child([&] {
    ::signal(SIGXFSZ, SIG_IGN);
    const rlimit limit{100'000, 100'000};
    ::setrlimit(RLIMIT_FSIZE, &limit);
    return write_until_full(path, "File too large");
  });
  REQUIRE(report.status == 0);  // the child saw "File too large" and closed without throwing
  CHECK(std::filesystem::file_size(path) <= 100'000);
  CHECK(report.markers > 50);
  check_frames_are_a_prefix(RecordingReader(path), report.markers, report.solved);
}

TEST_CASE("Recording: a full tmpfs ends the file at its last whole chunk", "[recording][disk]") {
  // A real full file system: a 192 KiB tmpfs in a mount namespace of a child process
  // (root, or an unprivileged user namespace). The child writes until the disk is full,
  // closes, and copies the file out of the namespace.
  const auto dir = facecap::test::scratch_dir("recording-tmpfs");
  const auto mount_point = dir / "mnt";
  std::filesystem::create_directories(mount_point);
  const ChildReport report = in_child([&] {
    const uid_t uid = ::getuid();
    const gid_t gid = ::getgid();
    bool entered = ::unshare(CLONE_NEWNS) == 0;
    if (!entered && ::unshare(CLONE_NEWUSER | CLONE_NEWNS) == 0) {
      facecap::test::write_text("/proc/self/setgroups", "deny");
      facecap::test::write_text("/proc/self/uid_map", fmt::format("0 {} 1", uid));
      facecap::test::write_text("/proc/self/gid_map", fmt::format("0 {} 1", gid));
      entered = true;
    }
    entered = entered && ::mount("none", "/", nullptr, MS_REC | MS_PRIVATE, nullptr) == 0 &&
              ::mount("tmpfs", mount_point.c_str(), "tmpfs", 0, "size=192k") == 0;
    if (!entered) return ChildReport{1};
    const ChildReport written = write_until_full(mount_point / "take.fcrec", "No space left on device");
    std::filesystem::copy_file(mount_point / "take.fcrec", dir / "copied.fcrec",
                               std::filesystem::copy_options::overwrite_existing);
    return written;
  });
  if (report.status == 1) {
    WARN("SKIPPED: no mount namespace for a small tmpfs here (needs root or unprivileged user namespaces)");
    return;
  }
  REQUIRE(report.status == 0);
  CHECK(report.markers > 50);
  check_frames_are_a_prefix(RecordingReader(dir / "copied.fcrec"), report.markers, report.solved);
}
