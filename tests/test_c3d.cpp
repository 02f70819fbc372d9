// C3D reader and writer against the c3d.org conformance files and synthetic takes.
#include <catch2/catch.hpp>

#include "core/error.hpp"
#include "core/io.hpp"
#include "formats/byte_io.hpp"
#include "formats/c3d.hpp"
#include "tests/formats_test_support.hpp"
#include "tests/test_support.hpp"

using namespace facecap;
using namespace facecap::formats;

namespace {

MarkerTake read_shared_c3d(const std::filesystem::path& path) {
  const auto bytes = read_file_bytes(path);
  return read_c3d(bytes, path.string());
}

std::size_t missing_samples(const MarkerTake& take) { return count_gaps(take).missing_samples; }

bool has_warning_containing(const MarkerTake& take, std::string_view text) {
  for (const auto& w : take.warnings) {
    if (w.find(text) != std::string::npos) return true;
  }
  return false;
}

}  // namespace

TEST_CASE("VAX F_floating decodes to IEEE", "[c3d]") {
  // POINT:SCALE of Eb015vi.c3d as stored (bytes aa 3e ab aa) is 1/12.
  const unsigned char scale[4] = {0xaa, 0x3e, 0xab, 0xaa};
  CHECK(vax_f_to_float(scale) == Approx(1.0 / 12.0).epsilon(1e-7));
  const unsigned char zero[4] = {0, 0, 0, 0};
  CHECK(vax_f_to_float(zero) == 0.0f);
  // -1.0: sign bit, exponent 129, mantissa 0 -> first word 0xc080.
  const unsigned char minus_one[4] = {0x80, 0xc0, 0x00, 0x00};
  CHECK(vax_f_to_float(minus_one) == -1.0f);
}

TEST_CASE("ByteReader stops at the end of the buffer with the offset", "[c3d]") {
  const char data[6] = {1, 0, 2, 0, 3, 0};
  ByteReader r(data, "buf", ByteOrder::kBig);
  CHECK(r.u16() == 0x0100);
  CHECK(r.u32() == 0x02000300u);
  try {
    r.u8();
    FAIL("read past the end");
  } catch (const Error& e) {
    CHECK(e.where().offset == 6);
    CHECK(std::string(e.what()).find("buf @ byte 6") != std::string::npos);
  }
}

TEST_CASE("C3D: the six Eb015 encodings decode to the same points", "[c3d][shared]") {
  FACECAP_REQUIRE_SHARED_DATA(reference_path, "c3d/Eb015pi.c3d");
  const MarkerTake reference = read_shared_c3d(reference_path);
  REQUIRE(reference.frames.size() == 450);
  REQUIRE(reference.marker_count() == 26);
  CHECK(reference.rate_hz == 50.0);
  CHECK(reference.first_frame == 1);
  CHECK(reference.units == "mm");
  CHECK(reference.labels.front() == "RFT1");
  CHECK(missing_samples(reference) == 226);
  // First point of the first frame: integers times POINT:SCALE 1/12.
  const auto& rft1 = reference.frames[0].markers[0];
  REQUIRE(rft1.present());
  CHECK(rft1.position.x() == Approx(248.583).margin(1e-3));
  CHECK(rft1.position.y() == Approx(226.833).margin(1e-3));
  CHECK(rft1.position.z() == Approx(37.4167).margin(1e-3));

  for (const char* variant : {"Eb015pr.c3d", "Eb015si.c3d", "Eb015sr.c3d", "Eb015vi.c3d", "Eb015vr.c3d"}) {
    INFO(variant);
    FACECAP_REQUIRE_SHARED_DATA(path, std::string("c3d/") + variant);
    const MarkerTake take = read_shared_c3d(path);
    CHECK(take.rate_hz == reference.rate_hz);
    CHECK(take.first_frame == reference.first_frame);
    facecap::test::require_same_points(reference, take, 1e-3);
  }
}

TEST_CASE("C3D: sample02 pc/dec/sgi integer and real files agree", "[c3d][shared]") {
  FACECAP_REQUIRE_SHARED_DATA(reference_path, "c3d/pc_real.c3d");
  const MarkerTake reference = read_shared_c3d(reference_path);
  REQUIRE(reference.frames.size() == 89);
  REQUIRE(reference.marker_count() == 36);
  CHECK(reference.rate_hz == 50.0);
  CHECK(missing_samples(reference) == 228);
  CHECK(reference.metadata_value("processor") == "intel");
  CHECK(reference.metadata_value("storage") == "float");
  for (const char* variant : {"dec_int.c3d", "dec_real.c3d", "sgi_real.c3d"}) {
    INFO(variant);
    FACECAP_REQUIRE_SHARED_DATA(path, std::string("c3d/") + variant);
    facecap::test::require_same_points(reference, read_shared_c3d(path), 1e-3);
  }
  // pc_int and sgi_int hold, in 59 coordinates, the integer one step nearer zero than
  // dec_int and the real files (2043 where dec_int has 2044: the raw words differ, values
  // truncated instead of rounded when the sample was made). Same masks, never more
  // than one step apart.
  FACECAP_REQUIRE_SHARED_DATA(pc_int_path, "c3d/pc_int.c3d");
  FACECAP_REQUIRE_SHARED_DATA(sgi_int_path, "c3d/sgi_int.c3d");
  const MarkerTake pc_int = read_shared_c3d(pc_int_path);
  facecap::test::require_same_points(pc_int, read_shared_c3d(sgi_int_path), 1e-9);
  const double step = std::stod(std::string(pc_int.metadata_value("scale")));
  CHECK(step == Approx(0.28118187));
  std::size_t one_step_apart = 0;
  for (std::size_t f = 0; f < pc_int.frames.size(); ++f) {
    for (std::size_t k = 0; k < pc_int.marker_count(); ++k) {
      const Marker& a = pc_int.frames[f].markers[k];
      const Marker& b = reference.frames[f].markers[k];
      REQUIRE(a.present() == b.present());
      if (!a.present()) continue;
      for (int axis = 0; axis < 3; ++axis) {
        const double d = b.position[axis] - a.position[axis];
        if (std::abs(d) > 1e-3) {
          CHECK(std::abs(d) == Approx(step).margin(1e-3));
          CHECK(std::abs(a.position[axis]) < std::abs(b.position[axis]));
          ++one_step_apart;
        }
      }
    }
  }
  CHECK(one_step_apart == 59);
}

TEST_CASE("C3D: TEST{A,B,C,D}PI follow the header pointers to moved sections", "[c3d][shared]") {
  FACECAP_REQUIRE_SHARED_DATA(reference_path, "c3d/Eb015pi.c3d");
  const MarkerTake reference = read_shared_c3d(reference_path);
  const std::pair<const char*, const char*> expected_blocks[] = {
      {"TESTAPI.c3d", "11"}, {"TESTBPI.c3d", "20"}, {"TESTCPI.c3d", "20"}, {"TESTDPI.c3d", "20"}};
  for (const auto& [file, data_start] : expected_blocks) {
    INFO(file);
    FACECAP_REQUIRE_SHARED_DATA(path, std::string("c3d/") + file);
    const MarkerTake take = read_shared_c3d(path);
    CHECK(take.metadata_value("data_start_block") == data_start);
    CHECK(take.warnings.empty());
    facecap::test::require_same_points(reference, take, 1e-9);
  }
}

TEST_CASE("C3D: s13 Dance has POINT:DATA_START 0, the header's block is used", "[c3d][shared]") {
  FACECAP_REQUIRE_SHARED_DATA(path, "c3d/c3dorg_s13_Dance.c3d");
  const MarkerTake take = read_shared_c3d(path);
  CHECK(take.metadata_value("data_start_block") == "8");
  // Parameters run past the section's declared 3 blocks; labels are still found.
  CHECK(take.warnings.empty());
  REQUIRE(take.marker_count() == 40);
  CHECK(take.labels.front() == "Channel101");
  CHECK(take.frames.size() == 499);  // header 1..499; POINT:FRAMES (500) overstates
  CHECK(take.rate_hz == Approx(65.0533).margin(1e-3));
  CHECK(missing_samples(take) == 0);
  CHECK(take.frames[0].markers[0].position.x() == Approx(1721.55).margin(0.01));
}

TEST_CASE("C3D: s16 basketball has every residual -1, so every point is missing", "[c3d][shared]") {
  FACECAP_REQUIRE_SHARED_DATA(path, "c3d/c3dorg_s16_basketball.c3d");
  const MarkerTake take = read_shared_c3d(path);
  REQUIRE(take.frames.size() == 34);
  REQUIRE(take.marker_count() == 22);
  CHECK(take.labels.front() == "2000");
  CHECK(missing_samples(take) == 34 * 22);
  CHECK(std::isnan(take.frames[5].markers[7].position.y()));
}

TEST_CASE("C3D: s18 has a damaged parameter section; the needed parameters come first", "[c3d][shared]") {
  FACECAP_REQUIRE_SHARED_DATA(path, "c3d/c3dorg_s18_bad_parameter_section.c3d");
  const MarkerTake take = read_shared_c3d(path);
  CHECK(has_warning_containing(take, "@ byte 5771: parameter section damaged"));
  REQUIRE(take.frames.size() == 332);
  REQUIRE(take.marker_count() == 45);
  CHECK(take.labels.front() == "P1");
  CHECK(take.labels.back() == "P45");
  CHECK(take.rate_hz == 120.0);
  CHECK(take.metadata_value("storage") == "integer");
  CHECK(take.frames[0].markers[0].position.x() == Approx(-587.371).margin(1e-3));
  CHECK(take.frames[331].markers[0].position.x() == Approx(2568.31156).margin(1e-4));
}

TEST_CASE("C3D: s20 PhaseSpace has no parameters; the header describes the data", "[c3d][shared]") {
  FACECAP_REQUIRE_SHARED_DATA(path, "c3d/c3dorg_s20_phasespace_sample.c3d");
  const MarkerTake take = read_shared_c3d(path);
  CHECK(has_warning_containing(take, "no parameters"));
  REQUIRE(take.frames.size() == 701);
  REQUIRE(take.marker_count() == 40);
  CHECK(take.labels.front() == "point_1");
  CHECK(take.rate_hz == 30.0);
  CHECK(take.units == "mm");
  CHECK(missing_samples(take) == 1281);
  CHECK(take.frames[0].markers[0].position.z() == Approx(1296.68).margin(0.01));
}

TEST_CASE("C3D: small test files skip their analog samples", "[c3d][shared]") {
  FACECAP_REQUIRE_SHARED_DATA(path1, "c3d/c3d_test_file_01.c3d");
  const MarkerTake one = read_shared_c3d(path1);
  CHECK(one.frames.size() == 8);
  CHECK(one.marker_count() == 8);
  CHECK(one.metadata_value("analog_words_per_frame") == "360");  // 36 channels x 10 samples
  CHECK(one.labels.front() == "RAsis");
  CHECK(one.frames[0].markers[0].position.x() == Approx(-477.99).margin(0.01));
  // The last frame's points (offsets computed by hand): a wrong analog stride would shift them.
  CHECK(one.frames[7].markers[0].position.x() == Approx(-477.21255).margin(1e-4));
  CHECK(one.frames[7].markers[0].position.z() == Approx(1036.79236).margin(1e-4));

  FACECAP_REQUIRE_SHARED_DATA(path3, "c3d/c3d_test_file_03.c3d");
  const MarkerTake three = read_shared_c3d(path3);
  CHECK(three.frames.size() == 4);
  CHECK(three.first_frame == 228);  // TRIAL:ACTUAL_START_FIELD
  CHECK(three.frames.back().frame_no == 231);
  CHECK(three.labels.front() == "PEL_MO");
  CHECK(three.rate_hz == 100.0);
}

TEST_CASE("C3D: damaged headers fail with the offset and the reason", "[c3d]") {
  const auto good = write_c3d(facecap::test::synthetic_take(10, 3));
  auto expect_error = [](std::span<const char> bytes, std::string_view text) {
    try {
      read_c3d(bytes, "bad.c3d");
      FAIL("no error");
    } catch (const Error& e) {
      INFO(e.what());
      CHECK(std::string(e.what()).find("bad.c3d @ byte") == 0);
      CHECK(std::string(e.what()).find(text) != std::string::npos);
    }
  };
  expect_error(std::span(good).first(300), "shorter than the 512-byte header");
  auto wrong_key = good;
  wrong_key[1] = 0x51;
  expect_error(wrong_key, "not a C3D file");
  auto wrong_processor = good;
  wrong_processor[512 + 3] = 90;
  expect_error(wrong_processor, "processor type");
  expect_error(std::span(good).first(good.size() - 512), "complete frames");
}

TEST_CASE("C3D writer: synthetic take round-trips, including > 255 labels", "[c3d]") {
  MarkerTake take = facecap::test::synthetic_take(20, 300, 120.0);
  take.first_frame = 7;
  for (std::size_t f = 0; f < take.frames.size(); ++f) take.frames[f].frame_no = 7 + int64_t(f);
  const auto bytes = write_c3d(take);
  CHECK(bytes.size() % 512 == 0);
  const MarkerTake back = read_c3d(bytes, "synthetic.c3d");
  CHECK(back.warnings.empty());
  CHECK(back.rate_hz == 120.0);
  CHECK(back.first_frame == 7);
  CHECK(back.frames.back().frame_no == 26);
  CHECK(back.units == "mm");
  CHECK(back.labels[299] == "M299");  // from POINT:LABELS2
  const double worst = facecap::test::require_same_points(take, back, 1e-4);
  CHECK(worst > 0.0);  // positions went through float32
}

TEST_CASE("C3D writer: takes past 65535 frames use the TRIAL fields", "[c3d]") {
  const MarkerTake take = facecap::test::synthetic_take(70'000, 1, 1000.0);
  const MarkerTake back = read_c3d(write_c3d(take), "long.c3d");
  CHECK(back.frames.size() == 70'000);
  CHECK(back.frames.back().frame_no == 70'000);
  facecap::test::require_same_points(take, back, 1e-4);
}

TEST_CASE("C3D writer: every shared C3D file reads back through our writer", "[c3d][shared]") {
  FACECAP_REQUIRE_SHARED_DATA(dir, "c3d");
  std::size_t files = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    if (entry.path().extension() != ".c3d") continue;
    INFO(entry.path().string());
    const MarkerTake original = read_shared_c3d(entry.path());
    const MarkerTake back = read_c3d(write_c3d(original), "rewritten.c3d");
    CHECK(back.rate_hz == Approx(original.rate_hz).epsilon(1e-6));
    CHECK(back.first_frame == original.first_frame);
    CHECK(back.units == original.units);
    // Exactly float32 of the original positions; missing markers exactly preserved.
    facecap::test::require_same_points(original, back, 1e-3);
    std::size_t differing = 0;
    for (std::size_t f = 0; f < original.frames.size(); ++f) {
      for (std::size_t k = 0; k < original.marker_count(); ++k) {
        const Marker& a = original.frames[f].markers[k];
        const Marker& b = back.frames[f].markers[k];
        if (a.present() && !facecap::test::same_float32(a.position, b.position)) ++differing;
      }
    }
    CHECK(differing == 0);
    ++files;
  }
  CHECK(files == 22);
}
