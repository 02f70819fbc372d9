#include "formats/point_cache.hpp"

#include <cerrno>
#include <cstring>
#include <limits>

#include <unistd.h>

#include <fmt/format.h>

#include "core/error.hpp"
#include "formats/byte_io.hpp"

namespace facecap::formats {

namespace {
ByteOrder byte_order(PointCacheFormat format) {
  return format == PointCacheFormat::kPc2 ? ByteOrder::kLittle : ByteOrder::kBig;
}
}  // namespace

PointCacheWriter::PointCacheWriter(const std::filesystem::path& path, PointCacheFormat format, std::size_t point_count,
                                   std::span<const double> frame_times_s)
    : path_(path), partial_(path.string() + ".partial"), format_(format), point_count_(point_count),
      frame_count_(frame_times_s.size()) {
  constexpr auto kMax = std::size_t(std::numeric_limits<int32_t>::max());
  if (point_count == 0 || point_count > kMax / 3 || frame_count_ > kMax)
    throw file_error(path.string(), fmt::format("{} points x {} frames do not fit a point cache's 32-bit counts",
                                                point_count, frame_count_));
  std::vector<char> header;
  ByteWriter w(header, byte_order(format));
  if (format == PointCacheFormat::kPc2) {
    w.bytes(std::string_view("POINTCACHE2\0", 12));
    w.i32(1);
    w.i32(int32_t(point_count));
    w.f32(0.0f);  // start frame
    w.f32(1.0f);  // sample rate: one sample per frame
    w.i32(int32_t(frame_count_));
  } else {
    w.i32(int32_t(frame_count_));
    w.i32(int32_t(point_count));
    for (const double t : frame_times_s) w.f32(float(t));
  }
  file_ = std::fopen(partial_.c_str(), "wb");
  if (!file_) throw file_error(partial_.string(), fmt::format("cannot create: {}", std::strerror(errno)));
  write(header);
}

PointCacheWriter::~PointCacheWriter() {
  if (file_) {
    std::fclose(file_);
    std::error_code ec;
    std::filesystem::remove(partial_, ec);
  }
}

void PointCacheWriter::write(const std::vector<char>& bytes) {
  if (std::fwrite(bytes.data(), 1, bytes.size(), file_) != bytes.size())
    throw file_error(partial_.string(), fmt::format("write failed: {}", std::strerror(errno)));
}

void PointCacheWriter::append(const Eigen::Ref<const Eigen::Matrix3Xf>& points, float scale) {
  if (std::size_t(points.cols()) != point_count_)
    throw file_error(path_.string(), fmt::format("frame {} has {} points, the cache {}", frames_written_, points.cols(),
                                                 point_count_));
  if (frames_written_ == frame_count_)
    throw file_error(path_.string(), fmt::format("more than the {} frames announced", frame_count_));
  frame_bytes_.clear();
  ByteWriter w(frame_bytes_, byte_order(format_));
  for (Eigen::Index v = 0; v < points.cols(); ++v)
    for (int k = 0; k < 3; ++k) w.f32(points(k, v) * scale);
  write(frame_bytes_);
  ++frames_written_;
}

void PointCacheWriter::close() {
  if (frames_written_ != frame_count_)
    throw file_error(path_.string(), fmt::format("{} of {} frames written", frames_written_, frame_count_));
  const bool flushed = std::fflush(file_) == 0 && fsync(fileno(file_)) == 0;
  const int saved = errno;
  std::fclose(file_);
  file_ = nullptr;
  std::error_code ec;
  if (!flushed) {
    std::filesystem::remove(partial_, ec);
    throw file_error(partial_.string(), fmt::format("write failed: {}", std::strerror(saved)));
  }
  std::filesystem::rename(partial_, path_, ec);
  if (ec) {
    std::filesystem::remove(partial_, ec);
    throw file_error(path_.string(), fmt::format("cannot rename {} into place: {}", partial_.string(), ec.message()));
  }
}

}  // namespace facecap::formats
