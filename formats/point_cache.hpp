#pragma once
// Point caches: a mesh's vertex positions, one sample per frame, as DCC tools replay them
// on a mesh of the same vertex count and order.
//   PC2 (3ds Max Point Cache, Blender's Mesh Cache modifier), little-endian:
//     char[12] "POINTCACHE2\0" | i32 version (1) | i32 points | f32 start frame |
//     f32 sample rate (frames per sample) | i32 samples | samples x points x f32[3]
//   MDD (Motion Designer; LightWave, Blender, Houdini), big-endian:
//     i32 frames | i32 points | frames x f32 time (s) | frames x points x f32[3]
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace facecap::formats {

enum class PointCacheFormat : uint8_t { kPc2, kMdd };

inline constexpr std::size_t kPc2HeaderBytes = 32;

// Streams a point cache to `path` (written beside it and renamed into place on close, so
// a failed export leaves no half file). Not real-time code.
class PointCacheWriter {
 public:
  // frame_times_s: every frame's time from the first, in seconds (MDD stores them, PC2
  // only their count: its samples are one frame apart from frame 0). Throws Error when the
  // file cannot be created or the counts do not fit the format's 32-bit fields.
  PointCacheWriter(const std::filesystem::path& path, PointCacheFormat format, std::size_t point_count,
                   std::span<const double> frame_times_s);
  ~PointCacheWriter();  // removes the partial file unless close() succeeded
  PointCacheWriter(const PointCacheWriter&) = delete;
  PointCacheWriter& operator=(const PointCacheWriter&) = delete;

  // One frame's points (3 x point_count, any units) multiplied by scale. Throws Error on a
  // wrong point count, more frames than announced, or a failed write.
  void append(const Eigen::Ref<const Eigen::Matrix3Xf>& points, float scale);
  // Throws Error unless every announced frame was appended and the file was written.
  void close();

 private:
  void write(const std::vector<char>& bytes);

  std::filesystem::path path_, partial_;
  PointCacheFormat format_;
  std::size_t point_count_;
  std::size_t frame_count_;
  std::size_t frames_written_ = 0;
  std::FILE* file_ = nullptr;
  std::vector<char> frame_bytes_;  // reused per frame
};

}  // namespace facecap::formats
