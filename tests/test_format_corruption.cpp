// Every reader meets corrupted input with an Error, never a crash, hang or other
// exception: random byte flips and truncations of real and synthetic files (bounded,
// seeded, so failures reproduce). The libFuzzer targets go further.
#include <random>

#include <catch2/catch.hpp>

#include "core/error.hpp"
#include "core/io.hpp"
#include "formats/c3d.hpp"
#include "formats/livelinkface.hpp"
#include "formats/recording.hpp"
#include "formats/trc.hpp"
#include "tests/formats_test_support.hpp"
#include "tests/test_support.hpp"

using namespace facecap;
using namespace facecap::formats;

namespace {

enum class Reader { kTake, kLiveLinkFace };

// Reads every frame, so lazily decoded recordings are exercised too.
void read_everything(std::span<const char> bytes, Reader reader) {
  if (reader == Reader::kLiveLinkFace) {
    read_livelinkface(std::string_view(bytes.data(), bytes.size()), "mutant.csv");
    return;
  }
  if (bytes.size() >= 5 && std::string_view(bytes.data(), 5) == "FCREC") {
    const RecordingReader recording(bytes, "mutant.fcrec");
    SolvedFrame solved;
    for (std::size_t i = 0; i < recording.solved_frame_count(); ++i) recording.read_solved_frame(i, solved);
  }
  read_take(bytes, "mutant");
}

struct Outcome {
  std::size_t read = 0, refused = 0;
};

// Mutates `original` `iterations` times; each mutant must read or throw Error.
Outcome mutate_and_read(const std::vector<char>& original, Reader reader, int iterations, uint32_t seed) {
  std::mt19937 rng(seed);
  Outcome outcome;
  std::vector<char> mutant;
  for (int i = 0; i < iterations; ++i) {
    mutant = original;
    const int kind = int(rng() % 3);
    if (kind != 1 && !mutant.empty()) {  // flip 1..8 random bytes
      for (int n = int(rng() % 8) + 1; n > 0; --n) mutant[rng() % mutant.size()] = char(rng());
    }
    if (kind != 0) mutant.resize(rng() % (mutant.size() + 1));  // and/or truncate
    try {
      read_everything(mutant, reader);
      ++outcome.read;
    } catch (const Error&) {
      ++outcome.refused;
    } catch (const std::exception& e) {
      FAIL("mutant " << i << " (seed " << seed << ") threw a non-Error exception: " << e.what());
    }
  }
  return outcome;
}

std::vector<char> to_bytes(const std::string& s) { return {s.begin(), s.end()}; }

}  // namespace

TEST_CASE("Corrupted synthetic files of every format throw only Error", "[corruption]") {
  const MarkerTake take = facecap::test::synthetic_take(30, 4);
  const auto dir = facecap::test::scratch_dir("corruption-synthetic");
  write_recording(dir / "take.fcrec", take, "test");
  FaceTake face;
  for (int i = 0; i < 10; ++i) {
    FaceFrame& f = face.frames.emplace_back();
    f.timecode = *parse_livelink_timecode(fmt::format("01:00:00:{:02}.000", i));
    f.tracked = i != 4;
  }
  const std::pair<std::vector<char>, Reader> inputs[] = {
      {write_c3d(take), Reader::kTake},
      {to_bytes(write_trc(take, "t.trc")), Reader::kTake},
      {read_file_bytes(dir / "take.fcrec"), Reader::kTake},
      {to_bytes(write_livelinkface(face)), Reader::kLiveLinkFace},
  };
  uint32_t seed = 1;
  for (const auto& [bytes, reader] : inputs) {
    const Outcome outcome = mutate_and_read(bytes, reader, 400, seed++);
    CHECK(outcome.read + outcome.refused == 400);
    CHECK(outcome.refused > 0);  // the mutations did reach the checks
  }
  // Pure noise, and empty input.
  std::mt19937 rng(99);
  for (int i = 0; i < 200; ++i) {
    std::vector<char> noise(rng() % 2048);
    for (char& c : noise) c = char(rng());
    if (i % 2 == 0 && noise.size() > 2) noise[1] = 0x50;  // looks like a C3D header
    for (Reader reader : {Reader::kTake, Reader::kLiveLinkFace}) {
      try {
        read_everything(noise, reader);
      } catch (const Error&) {
      }
    }
  }
}

TEST_CASE("Corrupted real files throw only Error", "[corruption][shared]") {
  const std::pair<const char*, Reader> files[] = {
      {"c3d/Eb015pi.c3d", Reader::kTake},
      {"c3d/Eb015vr.c3d", Reader::kTake},
      {"c3d/Eb015sr.c3d", Reader::kTake},
      {"c3d/c3dorg_s18_bad_parameter_section.c3d", Reader::kTake},
      {"c3d/c3d_test_file_03.c3d", Reader::kTake},
      {"trc/test_file_04.trc", Reader::kTake},
      {"trc/test_file_01.trc", Reader::kTake},
      {"livelinkface/jmtechart_MySlate_3_Jason_Millers_iPhone.csv", Reader::kLiveLinkFace},
  };
  uint32_t seed = 1000;
  for (const auto& [file, reader] : files) {
    INFO(file);
    FACECAP_REQUIRE_SHARED_DATA(path, file);
    const Outcome outcome = mutate_and_read(read_file_bytes(path), reader, 150, seed++);
    CHECK(outcome.read + outcome.refused == 150);
  }
}
