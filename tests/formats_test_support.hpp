#pragma once
// Helpers shared by the format tests: synthetic takes and point-by-point comparison.
#include <cmath>
#include <string>
#include <string_view>
#include <vector>

#include <catch2/catch.hpp>
#include <fmt/format.h>

#include "formats/byte_io.hpp"
#include "formats/take.hpp"

namespace facecap::test {

// A 1 KB C3D (header block, parameter block) of no points whose only parameter is a
// real-typed POINT:<name> (at most 15 characters); the header declares no frames.
inline std::vector<char> c3d_with_real_point_parameter(std::string_view name, float value) {
  std::vector<char> file;
  formats::ByteWriter w(file);
  w.u8(2);     // parameter block
  w.u8(0x50);  // C3D key
  w.u16(0);    // header points
  w.u16(0);    // analog words
  w.u16(1);    // first frame
  w.u16(0);    // last frame: no frames
  w.u16(0);
  w.f32(-1.0f);  // float storage
  w.u16(3);      // data start block
  w.u16(0);
  w.f32(60.0f);
  file.resize(512, '\0');
  w.u8(1);
  w.u8(0x50);
  w.u8(1);       // blocks
  w.u8(83 + 1);  // Intel
  // group POINT (id -1), then parameter USED: type 4 (real), no dimensions.
  w.i8(5);
  w.i8(-1);
  w.bytes("POINT");
  w.i16(3);  // to the next entry, counted from this word
  w.u8(0);   // empty description
  w.i8(int8_t(name.size()));
  w.i8(1);
  w.bytes(name);
  w.i16(0);  // last entry
  w.i8(4);
  w.u8(0);
  w.f32(value);
  w.u8(0);
  file.resize(1024, '\0');
  return file;
}

inline std::vector<char> c3d_with_real_point_count(float points) { return c3d_with_real_point_parameter("USED", points); }

// A take whose positions are distinct functions of (frame, marker) and whose missing
// markers follow a fixed pattern (every 7th sample), so comparisons catch shuffles.
inline formats::MarkerTake synthetic_take(std::size_t frames, std::size_t markers, double rate_hz = 60.0) {
  formats::MarkerTake take;
  take.rate_hz = rate_hz;
  take.units = "mm";
  take.first_frame = 1;
  for (std::size_t k = 0; k < markers; ++k) take.labels.push_back(fmt::format("M{:03}", k));
  for (std::size_t f = 0; f < frames; ++f) {
    auto& frame = formats::append_empty_frame(take, int64_t(f) + 1, std::llround(double(f) * 1e9 / rate_hz));
    for (std::size_t k = 0; k < markers; ++k) {
      if ((f * markers + k) % 7 == 3) continue;  // stays missing
      auto& m = frame.markers[k];
      m.flags = 0;
      m.position = Eigen::Vector3d(100.0 * std::sin(0.01 * double(f) + double(k)), 50.0 + double(k) * 0.25,
                                   -20.0 + 0.125 * double(f));
    }
  }
  return take;
}

// True when both positions round to the same float32 (the precision C3D and our TRC
// writer store). Compares floats, not double(float(x)): GCC 12.2 at -O2 drops that
// round trip when it SLP-vectorises a loop over xyz triples.
inline bool same_float32(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return float(a.x()) == float(b.x()) && float(a.y()) == float(b.y()) && float(a.z()) == float(b.z());
}

// Same labels, frame count and missing masks; present positions within tolerance.
// Returns the largest coordinate difference seen.
inline double require_same_points(const formats::MarkerTake& a, const formats::MarkerTake& b, double tolerance) {
  REQUIRE(a.labels == b.labels);
  REQUIRE(a.frames.size() == b.frames.size());
  double worst = 0.0;
  std::size_t mask_mismatches = 0;
  for (std::size_t f = 0; f < a.frames.size(); ++f) {
    REQUIRE(a.frames[f].markers.size() == b.frames[f].markers.size());
    for (std::size_t k = 0; k < a.frames[f].markers.size(); ++k) {
      const auto& ma = a.frames[f].markers[k];
      const auto& mb = b.frames[f].markers[k];
      if (ma.present() != mb.present()) {
        ++mask_mismatches;
        continue;
      }
      if (!ma.present()) {
        CHECK(std::isnan(ma.position.x()));
        CHECK(std::isnan(mb.position.x()));
        continue;
      }
      worst = std::max(worst, (ma.position - mb.position).cwiseAbs().maxCoeff());
    }
  }
  CHECK(mask_mismatches == 0);
  CHECK(worst <= tolerance);
  return worst;
}

}  // namespace facecap::test
