#include "drivers/v4l2/v4l2_feed.hpp"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>

#include <fcntl.h>
#include <fmt/format.h>
#include <fmt/ranges.h>
#include <linux/videodev2.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <unistd.h>

#include "core/error.hpp"
#include "core/time.hpp"

namespace facecap::drivers::v4l2 {
namespace {

constexpr unsigned kBuffers = 4;

int xioctl(int fd, unsigned long request, void* arg) {
  int r;
  do r = ioctl(fd, request, arg);
  while (r == -1 && errno == EINTR);
  return r;
}

std::string fourcc_text(uint32_t f) {
  return {char(f & 0xFF), char((f >> 8) & 0xFF), char((f >> 16) & 0xFF), char((f >> 24) & 0xFF)};
}

uint32_t fourcc_of(PixelFormat format) {
  switch (format) {
    case PixelFormat::kGrey: return V4L2_PIX_FMT_GREY;
    case PixelFormat::kYuyv: return V4L2_PIX_FMT_YUYV;
    case PixelFormat::kMjpeg: return V4L2_PIX_FMT_MJPEG;
    case PixelFormat::kAuto: break;
  }
  return 0;
}

}  // namespace

struct V4l2Feed::Camera {
  V4l2CameraSpec spec;
  std::size_t index = 0;
  int fd = -1;
  uint32_t fourcc = 0;
  int width = 0, height = 0, stride = 0;
  double rate_hz = 0;
  struct Buffer {
    void* start = MAP_FAILED;
    std::size_t length = 0;
  };
  std::vector<Buffer> buffers;
  cv::Mat grey;          // converted image (YUYV, MJPEG)
  int dequeued = -1;     // buffer index lent out to the caller (GREY in place)

  std::string label() const { return fmt::format("camera {} ({}) at {}", index, spec.name, spec.device); }
  [[noreturn]] void fail(std::string what) const { throw Error(fmt::format("{}: {}", label(), what)); }
  [[noreturn]] void fail_errno(std::string_view call) const {
    const int e = errno;
    fail(fmt::format("{} failed: {}{}", call, std::strerror(e),
                     e == EACCES ? " (the facecap user needs the video group, or a udev rule for the camera)" : ""));
  }
};

V4l2Feed::V4l2Feed(std::vector<V4l2CameraSpec> cameras, PixelFormat format, double frame_rate_hz)
    : format_(format), frame_rate_hz_(frame_rate_hz) {
  for (std::size_t i = 0; i < cameras.size(); ++i) {
    Camera& c = cameras_.emplace_back();
    c.spec = std::move(cameras[i]);
    c.index = i;
  }
}

V4l2Feed::~V4l2Feed() { stop(); }

std::size_t V4l2Feed::cameras() const { return cameras_.size(); }

void V4l2Feed::open() {
  try {
    for (Camera& c : cameras_) open_camera(c);
  } catch (...) {
    close_all();
    throw;
  }
}

void V4l2Feed::open_camera(Camera& c) {
  std::error_code ec;
  if (!std::filesystem::exists(c.spec.device, ec))
    c.fail("does not exist. The v4l2 driver needs one V4L2 capture device per calibrated camera, named in "
           "source.v4l2.devices in the calibration's order (`v4l2-ctl --list-devices` lists the cameras present)");
  c.fd = ::open(c.spec.device.c_str(), O_RDWR | O_NONBLOCK | O_CLOEXEC);
  if (c.fd < 0) c.fail_errno("open");

  v4l2_capability caps{};
  if (xioctl(c.fd, VIDIOC_QUERYCAP, &caps) < 0) c.fail("is not a V4L2 device (VIDIOC_QUERYCAP refused)");
  const uint32_t device_caps = (caps.capabilities & V4L2_CAP_DEVICE_CAPS) ? caps.device_caps : caps.capabilities;
  if (!(device_caps & V4L2_CAP_VIDEO_CAPTURE) || !(device_caps & V4L2_CAP_STREAMING))
    c.fail(fmt::format("({}) cannot stream video capture: the driver needs V4L2_CAP_VIDEO_CAPTURE and "
                       "V4L2_CAP_STREAMING", reinterpret_cast<const char*>(caps.card)));

  // The formats it offers; ours in order of preference unless one is asked for.
  std::vector<uint32_t> offered;
  v4l2_fmtdesc desc{};
  desc.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  while (xioctl(c.fd, VIDIOC_ENUM_FMT, &desc) == 0) {
    offered.push_back(desc.pixelformat);
    ++desc.index;
  }
  uint32_t chosen = 0;
  if (format_ != PixelFormat::kAuto) {
    if (std::find(offered.begin(), offered.end(), fourcc_of(format_)) != offered.end()) chosen = fourcc_of(format_);
  } else {
    for (const uint32_t f : {V4L2_PIX_FMT_GREY, V4L2_PIX_FMT_YUYV, V4L2_PIX_FMT_MJPEG})
      if (!chosen && std::find(offered.begin(), offered.end(), f) != offered.end()) chosen = f;
  }
  if (!chosen) {
    std::vector<std::string> names;
    for (const uint32_t f : offered) names.push_back(fourcc_text(f));
    c.fail(fmt::format("offers {} but not {}", names.empty() ? "no format" : fmt::format("{}", fmt::join(names, ", ")),
                       format_ == PixelFormat::kAuto ? "GREY, YUYV or MJPEG" : fourcc_text(fourcc_of(format_))));
  }

  v4l2_format fmt{};
  fmt.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  if (xioctl(c.fd, VIDIOC_G_FMT, &fmt) < 0) c.fail_errno("VIDIOC_G_FMT");
  fmt.fmt.pix.pixelformat = chosen;
  if (c.spec.width > 0) {
    fmt.fmt.pix.width = uint32_t(c.spec.width);
    fmt.fmt.pix.height = uint32_t(c.spec.height);
  }
  fmt.fmt.pix.field = V4L2_FIELD_NONE;
  if (xioctl(c.fd, VIDIOC_S_FMT, &fmt) < 0) c.fail_errno("VIDIOC_S_FMT");
  if (fmt.fmt.pix.pixelformat != chosen) c.fail(fmt::format("would not take {}", fourcc_text(chosen)));
  if (c.spec.width > 0 && (int(fmt.fmt.pix.width) != c.spec.width || int(fmt.fmt.pix.height) != c.spec.height))
    c.fail(fmt::format("was calibrated at {}x{} but gives {}x{}: calibrate it at the size it streams", c.spec.width,
                       c.spec.height, fmt.fmt.pix.width, fmt.fmt.pix.height));
  c.fourcc = chosen;
  c.width = int(fmt.fmt.pix.width);
  c.height = int(fmt.fmt.pix.height);
  c.stride = int(fmt.fmt.pix.bytesperline);
  if (c.stride == 0) c.stride = chosen == V4L2_PIX_FMT_YUYV ? 2 * c.width : c.width;

  v4l2_streamparm parm{};
  parm.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  if (frame_rate_hz_ > 0) {
    parm.parm.capture.timeperframe = {1000, uint32_t(std::lround(frame_rate_hz_ * 1000))};
    if (xioctl(c.fd, VIDIOC_S_PARM, &parm) < 0) c.fail_errno("VIDIOC_S_PARM (frame rate)");
  } else {
    xioctl(c.fd, VIDIOC_G_PARM, &parm);  // for the description only
  }
  const v4l2_fract tpf = parm.parm.capture.timeperframe;
  c.rate_hz = tpf.numerator ? double(tpf.denominator) / tpf.numerator : 0;

  v4l2_requestbuffers request{};
  request.count = kBuffers;
  request.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  request.memory = V4L2_MEMORY_MMAP;
  if (xioctl(c.fd, VIDIOC_REQBUFS, &request) < 0) c.fail_errno("VIDIOC_REQBUFS (memory-mapped streaming)");
  if (request.count < 2) c.fail(fmt::format("gave {} buffers; at least 2 are needed", request.count));
  for (unsigned i = 0; i < request.count; ++i) {
    v4l2_buffer buf{};
    buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    buf.memory = V4L2_MEMORY_MMAP;
    buf.index = i;
    if (xioctl(c.fd, VIDIOC_QUERYBUF, &buf) < 0) c.fail_errno("VIDIOC_QUERYBUF");
    Camera::Buffer& b = c.buffers.emplace_back();
    b.length = buf.length;
    b.start = mmap(nullptr, buf.length, PROT_READ | PROT_WRITE, MAP_SHARED, c.fd, buf.m.offset);
    if (b.start == MAP_FAILED) c.fail_errno("mmap of a capture buffer");
  }
  if (c.fourcc != V4L2_PIX_FMT_GREY) c.grey.create(c.height, c.width, CV_8UC1);
}

void V4l2Feed::start() {
  for (Camera& c : cameras_) {
    for (std::size_t i = 0; i < c.buffers.size(); ++i) {
      v4l2_buffer buf{};
      buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
      buf.memory = V4L2_MEMORY_MMAP;
      buf.index = uint32_t(i);
      if (xioctl(c.fd, VIDIOC_QBUF, &buf) < 0) c.fail_errno("VIDIOC_QBUF");
    }
    v4l2_buf_type type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    if (xioctl(c.fd, VIDIOC_STREAMON, &type) < 0) c.fail_errno("VIDIOC_STREAMON");
  }
  streaming_ = true;
}

bool V4l2Feed::next(CameraImage& out, int timeout_ms) {
  // The buffer lent out last time goes back to its camera.
  if (held_camera_ >= 0) {
    Camera& c = cameras_[std::size_t(held_camera_)];
    v4l2_buffer buf{};
    buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    buf.memory = V4L2_MEMORY_MMAP;
    buf.index = uint32_t(c.dequeued);
    if (xioctl(c.fd, VIDIOC_QBUF, &buf) < 0) c.fail_errno("VIDIOC_QBUF");
    c.dequeued = -1;
    held_camera_ = -1;
  }
  std::vector<pollfd>& fds = polls_;
  fds.resize(cameras_.size());
  for (std::size_t i = 0; i < cameras_.size(); ++i) fds[i] = {cameras_[i].fd, POLLIN, 0};
  const int ready = poll(fds.data(), fds.size(), timeout_ms);
  if (ready < 0 && errno != EINTR) throw Error(fmt::format("v4l2: poll failed: {}", std::strerror(errno)));
  for (std::size_t k = 0; ready > 0 && k < cameras_.size(); ++k) {
    const std::size_t i = (next_camera_ + k) % cameras_.size();
    if (fds[i].revents & (POLLERR | POLLHUP)) cameras_[i].fail("stopped streaming (unplugged?)");
    if (!(fds[i].revents & POLLIN)) continue;
    Camera& c = cameras_[i];
    v4l2_buffer buf{};
    buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    buf.memory = V4L2_MEMORY_MMAP;
    if (xioctl(c.fd, VIDIOC_DQBUF, &buf) < 0) {
      if (errno == EAGAIN) continue;
      c.fail_errno("VIDIOC_DQBUF");
    }
    next_camera_ = i + 1;
    if (buf.index >= c.buffers.size() || buf.bytesused > c.buffers[buf.index].length)
      c.fail(fmt::format("returned buffer {} with {} bytes, beyond what was mapped", buf.index, buf.bytesused));
    auto* data = static_cast<uint8_t*>(c.buffers[buf.index].start);
    out.camera = i;
    out.sequence = buf.sequence;
    out.timestamp_ns = (buf.flags & V4L2_BUF_FLAG_TIMESTAMP_MASK) == V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC
                           ? int64_t(buf.timestamp.tv_sec) * kNsPerSecond + int64_t(buf.timestamp.tv_usec) * kNsPerUs
                           : monotonic_now_ns();  // a clock we cannot compare: when it reached us
    bool requeue_now = true;
    if (c.fourcc == V4L2_PIX_FMT_GREY) {
      if (buf.bytesused < std::size_t(c.stride) * std::size_t(c.height)) c.fail("sent a short GREY frame");
      out.grey = cv::Mat(c.height, c.width, CV_8UC1, data, std::size_t(c.stride));  // in place, lent until the next call
      c.dequeued = int(buf.index);
      held_camera_ = int(i);
      requeue_now = false;
    } else if (c.fourcc == V4L2_PIX_FMT_YUYV) {
      if (buf.bytesused < std::size_t(c.stride) * std::size_t(c.height)) c.fail("sent a short YUYV frame");
      cv::extractChannel(cv::Mat(c.height, c.width, CV_8UC2, data, std::size_t(c.stride)), c.grey, 0);
      out.grey = c.grey;
    } else {
      const cv::Mat jpeg(1, int(buf.bytesused), CV_8UC1, data);
      cv::imdecode(jpeg, cv::IMREAD_GRAYSCALE, &c.grey);
      if (c.grey.rows != c.height || c.grey.cols != c.width) c.fail("sent an MJPEG frame that does not decode at its size");
      out.grey = c.grey;
    }
    if (requeue_now && xioctl(c.fd, VIDIOC_QBUF, &buf) < 0) c.fail_errno("VIDIOC_QBUF");
    return true;
  }
  return false;
}

void V4l2Feed::stop() noexcept {
  if (streaming_) {
    for (Camera& c : cameras_) {
      v4l2_buf_type type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
      xioctl(c.fd, VIDIOC_STREAMOFF, &type);
    }
    streaming_ = false;
  }
  held_camera_ = -1;
  close_all();
}

void V4l2Feed::close_all() noexcept {
  for (Camera& c : cameras_) {
    for (const Camera::Buffer& b : c.buffers)
      if (b.start != MAP_FAILED) munmap(b.start, b.length);
    c.buffers.clear();
    if (c.fd >= 0) ::close(c.fd);
    c.fd = -1;
  }
}

std::string V4l2Feed::description() const {
  std::vector<std::string> parts;
  for (const Camera& c : cameras_)
    parts.push_back(c.fd >= 0 ? fmt::format("{} {}x{} {} at {:g} Hz", c.label(), c.width, c.height, fourcc_text(c.fourcc), c.rate_hz)
                              : c.label());
  return fmt::format("{}", fmt::join(parts, "; "));
}

}  // namespace facecap::drivers::v4l2
