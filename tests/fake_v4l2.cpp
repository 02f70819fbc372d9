#include "tests/fake_v4l2.hpp"

#include <algorithm>
#include <cerrno>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <vector>

#include <dlfcn.h>
#include <fcntl.h>
#include <linux/videodev2.h>
#include <poll.h>
#include <sys/mman.h>
#include <time.h>
#include <unistd.h>
// After <cstdio>: jpeglib.h wants FILE and size_t declared.
#include <jpeglib.h>

namespace facecap::test::fake_v4l2 {
namespace {

constexpr unsigned kMaxBuffers = 8;

int64_t now_ns() {
  timespec t{};
  clock_gettime(CLOCK_MONOTONIC, &t);
  return int64_t(t.tv_sec) * 1'000'000'000 + t.tv_nsec;
}

struct Registered {
  Device device;
  bool present = true;
};

struct OpenDevice {
  Registered* registered = nullptr;
  std::size_t buffer_stride = 0;  // bytes between buffers in the memfd (page-aligned)
  unsigned buffers = 0;
  uint8_t* mapped = nullptr;      // the fake's own view of every buffer
  std::deque<unsigned> queued;
  bool streaming = false;
  bool gone = false;
  int64_t next_sequence = 0;
};

struct Fake {
  std::mutex mutex;
  std::map<std::string, Registered> devices;
  std::map<int, OpenDevice> open;  // by descriptor
  int64_t grid_start_ns = 0;       // 0 until the first STREAMON
  uint64_t dequeued = 0, dropped = 0;
};

Fake& fake() {
  static Fake instance;
  return instance;
}

template <typename F>
F real(const char* name) {
  static_assert(sizeof(F) == sizeof(void*));
  return reinterpret_cast<F>(dlsym(RTLD_NEXT, name));
}

uint32_t fourcc_of(const Device& d) { return d.fourcc ? d.fourcc : V4L2_PIX_FMT_GREY; }
// MJPEG has no lines (0, as drivers say); its buffers hold up to 2 bytes a pixel.
uint32_t bytes_per_line(const Device& d) {
  return fourcc_of(d) == V4L2_PIX_FMT_MJPEG ? 0 : uint32_t(d.width) * (fourcc_of(d) == V4L2_PIX_FMT_YUYV ? 2 : 1);
}
uint32_t image_bytes(const Device& d) {
  return uint32_t(d.width) * uint32_t(d.height) * (fourcc_of(d) == V4L2_PIX_FMT_GREY ? 1 : 2);
}

// `grey` as a baseline JPEG of one component (quality 95) into `out`: its size, or 0 when
// it is larger than `capacity`.
uint32_t encode_jpeg(const uint8_t* grey, int width, int height, uint8_t* out, uint32_t capacity) {
  jpeg_compress_struct c{};
  jpeg_error_mgr errors{};
  c.err = jpeg_std_error(&errors);
  jpeg_create_compress(&c);
  unsigned char* encoded = nullptr;
  unsigned long size = 0;
  jpeg_mem_dest(&c, &encoded, &size);
  c.image_width = JDIMENSION(width);
  c.image_height = JDIMENSION(height);
  c.input_components = 1;
  c.in_color_space = JCS_GRAYSCALE;
  jpeg_set_defaults(&c);
  jpeg_set_quality(&c, 95, TRUE);
  jpeg_start_compress(&c, TRUE);
  while (c.next_scanline < c.image_height) {
    JSAMPROW row = const_cast<uint8_t*>(grey + std::size_t(c.next_scanline) * std::size_t(width));
    jpeg_write_scanlines(&c, &row, 1);
  }
  jpeg_finish_compress(&c);
  jpeg_destroy_compress(&c);
  const uint32_t written = size <= capacity ? uint32_t(size) : 0;
  if (written > 0) std::memcpy(out, encoded, written);
  std::free(encoded);
  return written;
}

int64_t due_ns(const Fake& f, const OpenDevice& o) {
  const Device& d = o.registered->device;
  return f.grid_start_ns + d.offset_ns + o.next_sequence * d.period_ns;
}

// Frames whose time has passed with no buffer to take them are dropped, as a driver does.
void drop_overdue(Fake& f, OpenDevice& o, int64_t now) {
  const Device& d = o.registered->device;
  if (!o.streaming || d.period_ns <= 0) return;
  const int64_t latest = (now - f.grid_start_ns - d.offset_ns) / d.period_ns;
  if (latest > o.next_sequence) {
    f.dropped += uint64_t(latest - o.next_sequence);
    o.next_sequence = latest;
  }
}

void fill_format(const Device& d, v4l2_pix_format& pix) {
  pix.width = uint32_t(d.width);
  pix.height = uint32_t(d.height);
  pix.pixelformat = fourcc_of(d);
  pix.field = V4L2_FIELD_NONE;
  pix.bytesperline = bytes_per_line(d);
  pix.sizeimage = image_bytes(d);
  pix.colorspace = V4L2_COLORSPACE_RAW;
}

int fail(int error) {
  errno = error;
  return -1;
}

void release_buffers(OpenDevice& o) {
  if (o.mapped) munmap(o.mapped, o.buffer_stride * o.buffers);
  o.mapped = nullptr;
  o.buffers = 0;
  o.queued.clear();
}

int handle_ioctl(Fake& f, int fd, OpenDevice& o, unsigned long request, void* arg) {
  Device& d = o.registered->device;
  if (o.gone) return fail(ENODEV);
  switch (request) {
    case VIDIOC_QUERYCAP: {
      auto* caps = static_cast<v4l2_capability*>(arg);
      *caps = {};
      std::strncpy(reinterpret_cast<char*>(caps->driver), "facecap-fake", sizeof caps->driver - 1);
      std::strncpy(reinterpret_cast<char*>(caps->card), d.card.c_str(), sizeof caps->card - 1);
      std::strncpy(reinterpret_cast<char*>(caps->bus_info), "platform:fake", sizeof caps->bus_info - 1);
      caps->device_caps = V4L2_CAP_VIDEO_CAPTURE | V4L2_CAP_STREAMING;
      caps->capabilities = caps->device_caps | V4L2_CAP_DEVICE_CAPS;
      return 0;
    }
    case VIDIOC_ENUM_FMT: {
      auto* desc = static_cast<v4l2_fmtdesc*>(arg);
      if (desc->type != V4L2_BUF_TYPE_VIDEO_CAPTURE || desc->index != 0) return fail(EINVAL);
      desc->pixelformat = fourcc_of(d);
      return 0;
    }
    case VIDIOC_G_FMT:
    case VIDIOC_S_FMT: {  // the size and format are the sensor's: a request is adjusted to them
      auto* format = static_cast<v4l2_format*>(arg);
      if (format->type != V4L2_BUF_TYPE_VIDEO_CAPTURE) return fail(EINVAL);
      if (request == VIDIOC_S_FMT && o.buffers > 0) return fail(EBUSY);
      fill_format(d, format->fmt.pix);
      return 0;
    }
    case VIDIOC_S_PARM:
    case VIDIOC_G_PARM: {
      auto* parm = static_cast<v4l2_streamparm*>(arg);
      if (parm->type != V4L2_BUF_TYPE_VIDEO_CAPTURE) return fail(EINVAL);
      v4l2_fract& tpf = parm->parm.capture.timeperframe;
      if (request == VIDIOC_S_PARM && tpf.numerator > 0 && tpf.denominator > 0)
        d.period_ns = int64_t(tpf.numerator) * 1'000'000'000 / int64_t(tpf.denominator);
      parm->parm.capture.capability = V4L2_CAP_TIMEPERFRAME;
      tpf = {1000, uint32_t(1'000'000'000'000 / std::max<int64_t>(d.period_ns, 1))};
      return 0;
    }
    case VIDIOC_REQBUFS: {
      auto* request_buffers = static_cast<v4l2_requestbuffers*>(arg);
      if (request_buffers->type != V4L2_BUF_TYPE_VIDEO_CAPTURE || request_buffers->memory != V4L2_MEMORY_MMAP)
        return fail(EINVAL);
      if (o.streaming) return fail(EBUSY);
      release_buffers(o);
      const unsigned count = std::min(request_buffers->count, kMaxBuffers);
      const std::size_t page = std::size_t(sysconf(_SC_PAGESIZE));
      o.buffer_stride = (image_bytes(d) + page - 1) / page * page;
      if (ftruncate(fd, off_t(o.buffer_stride * count)) != 0) return -1;
      if (count > 0) {
        void* view = mmap(nullptr, o.buffer_stride * count, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
        if (view == MAP_FAILED) return -1;
        o.mapped = static_cast<uint8_t*>(view);
      }
      o.buffers = request_buffers->count = count;
      return 0;
    }
    case VIDIOC_QUERYBUF:
    case VIDIOC_QBUF: {
      auto* buf = static_cast<v4l2_buffer*>(arg);
      if (buf->type != V4L2_BUF_TYPE_VIDEO_CAPTURE || buf->memory != V4L2_MEMORY_MMAP || buf->index >= o.buffers)
        return fail(EINVAL);
      if (request == VIDIOC_QUERYBUF) {
        buf->length = image_bytes(d);
        buf->m.offset = uint32_t(buf->index * o.buffer_stride);
        buf->flags = V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC;
        return 0;
      }
      if (std::find(o.queued.begin(), o.queued.end(), buf->index) != o.queued.end()) return fail(EINVAL);
      o.queued.push_back(buf->index);
      return 0;
    }
    case VIDIOC_DQBUF: {
      auto* buf = static_cast<v4l2_buffer*>(arg);
      if (!o.streaming) return fail(EINVAL);
      const int64_t now = now_ns();
      drop_overdue(f, o, now);
      if (o.queued.empty() || now < due_ns(f, o)) return fail(EAGAIN);
      const unsigned index = o.queued.front();
      o.queued.pop_front();
      uint8_t* image = o.mapped + index * o.buffer_stride;
      uint32_t bytes = image_bytes(d);
      if (fourcc_of(d) == V4L2_PIX_FMT_GREY) {
        d.render(o.next_sequence, image, d.width);
      } else {
        std::vector<uint8_t> grey(std::size_t(d.width) * std::size_t(d.height));
        d.render(o.next_sequence, grey.data(), d.width);
        if (fourcc_of(d) == V4L2_PIX_FMT_MJPEG) {
          bytes = encode_jpeg(grey.data(), d.width, d.height, image, image_bytes(d));
          if (bytes == 0) return fail(EIO);
        } else {
          for (std::size_t i = 0; i < grey.size(); ++i) {
            image[2 * i] = grey[i];
            image[2 * i + 1] = 128;  // U and V alternate: no colour
          }
        }
      }
      const int64_t stamp = due_ns(f, o);
      *buf = {};
      buf->type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
      buf->memory = V4L2_MEMORY_MMAP;
      buf->index = index;
      buf->bytesused = bytes;
      buf->length = image_bytes(d);
      buf->field = V4L2_FIELD_NONE;
      buf->sequence = uint32_t(o.next_sequence);
      buf->flags = V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC | V4L2_BUF_FLAG_TSTAMP_SRC_SOE | V4L2_BUF_FLAG_DONE;
      buf->timestamp.tv_sec = stamp / 1'000'000'000;
      buf->timestamp.tv_usec = (stamp % 1'000'000'000) / 1000;
      if (d.dequeued) d.dequeued(o.next_sequence, buf->timestamp.tv_sec * 1'000'000'000 + buf->timestamp.tv_usec * 1000);
      ++o.next_sequence;
      ++f.dequeued;
      return 0;
    }
    case VIDIOC_STREAMON: {
      if (o.buffers == 0) return fail(EINVAL);
      if (d.period_ns <= 0) return fail(EINVAL);
      const int64_t now = now_ns();
      if (f.grid_start_ns == 0) f.grid_start_ns = now;
      o.streaming = true;
      o.next_sequence = std::max<int64_t>(0, (now - f.grid_start_ns - d.offset_ns) / d.period_ns + 1);
      return 0;
    }
    case VIDIOC_STREAMOFF:
      o.streaming = false;
      o.queued.clear();
      return 0;
    default: return fail(ENOTTY);
  }
}

int open_fake(const char* path, bool& handled) {
  Fake& f = fake();
  std::lock_guard lock(f.mutex);
  const auto it = f.devices.find(path);
  handled = it != f.devices.end();
  if (!handled) return -1;
  if (!it->second.present) return fail(ENOENT);
  const int fd = memfd_create("fake-v4l2", MFD_CLOEXEC);
  if (fd < 0) return -1;
  f.open[fd] = OpenDevice{&it->second};
  return fd;
}

}  // namespace

void add(Device device) {
  Fake& f = fake();
  std::lock_guard lock(f.mutex);
  std::ofstream(device.path).flush();
  const std::string path = device.path;
  f.devices[path] = Registered{std::move(device)};
}

void unplug(const std::string& path) {
  Fake& f = fake();
  std::lock_guard lock(f.mutex);
  f.devices.at(path).present = false;
  for (auto& [fd, o] : f.open)
    if (o.registered->device.path == path) o.gone = true;
  std::error_code ec;
  std::filesystem::remove(path, ec);
}

void plug(const std::string& path) {
  Fake& f = fake();
  std::lock_guard lock(f.mutex);
  f.devices.at(path).present = true;
  std::ofstream(path).flush();
}

int64_t grid_start_ns() {
  std::lock_guard lock(fake().mutex);
  return fake().grid_start_ns;
}

uint64_t frames_dequeued() {
  std::lock_guard lock(fake().mutex);
  return fake().dequeued;
}

uint64_t frames_dropped() {
  std::lock_guard lock(fake().mutex);
  return fake().dropped;
}

void clear() {
  Fake& f = fake();
  std::lock_guard lock(f.mutex);
  for (auto& [fd, o] : f.open) release_buffers(o);
  f.open.clear();
  for (const auto& [path, registered] : f.devices) {
    std::error_code ec;
    std::filesystem::remove(path, ec);
  }
  f.devices.clear();
  f.grid_start_ns = 0;
  f.dequeued = f.dropped = 0;
}

}  // namespace facecap::test::fake_v4l2

// The interposed libc entry points: the fake's paths and descriptors, else libc's own.
using namespace facecap::test::fake_v4l2;

namespace {

// open and open64 alike: the fake's paths, else libc's `name`.
int interposed_open(const char* name, const char* path, int flags, va_list args) {
  const mode_t mode = (flags & (O_CREAT | O_TMPFILE)) ? mode_t(va_arg(args, int)) : 0;
  bool handled = false;
  const int fd = open_fake(path, handled);
  if (handled) return fd;
  return real<int (*)(const char*, int, ...)>(name)(path, flags, mode);
}

}  // namespace

extern "C" int open(const char* path, int flags, ...) {
  va_list args;
  va_start(args, flags);
  const int fd = interposed_open("open", path, flags, args);
  va_end(args);
  return fd;
}

extern "C" int open64(const char* path, int flags, ...) {
  va_list args;
  va_start(args, flags);
  const int fd = interposed_open("open64", path, flags, args);
  va_end(args);
  return fd;
}

extern "C" int close(int fd) {
  {
    Fake& f = fake();
    std::lock_guard lock(f.mutex);
    if (const auto it = f.open.find(fd); it != f.open.end()) {
      release_buffers(it->second);
      f.open.erase(it);
    }
  }
  static const auto libc_close = real<int (*)(int)>("close");
  return libc_close(fd);
}

extern "C" int ioctl(int fd, unsigned long request, ...) {
  va_list args;
  va_start(args, request);
  void* arg = va_arg(args, void*);
  va_end(args);
  {
    Fake& f = fake();
    std::lock_guard lock(f.mutex);
    if (const auto it = f.open.find(fd); it != f.open.end()) return handle_ioctl(f, fd, it->second, request, arg);
  }
  static const auto libc_ioctl = real<int (*)(int, unsigned long, ...)>("ioctl");
  return libc_ioctl(fd, request, arg);
}

// A fake descriptor is readable once its next frame is due and a buffer is queued for it,
// and in error once its device is gone; other descriptors are asked of libc.
extern "C" int poll(pollfd* fds, nfds_t count, int timeout_ms) {
  static const auto libc_poll = real<int (*)(pollfd*, nfds_t, int)>("poll");
  Fake& f = fake();
  {
    std::lock_guard lock(f.mutex);
    bool any = false;
    for (nfds_t i = 0; i < count && !any; ++i) any = f.open.count(fds[i].fd) > 0;
    if (!any) return libc_poll(fds, count, timeout_ms);
  }
  const int64_t deadline = timeout_ms < 0 ? INT64_MAX : now_ns() + int64_t(timeout_ms) * 1'000'000;
  while (true) {
    int ready = 0;
    int64_t wake = deadline;
    {
      std::lock_guard lock(f.mutex);
      const int64_t now = now_ns();
      for (nfds_t i = 0; i < count; ++i) {
        pollfd& p = fds[i];
        p.revents = 0;
        const auto it = f.open.find(p.fd);
        if (it == f.open.end()) {
          pollfd single = p;
          if (libc_poll(&single, 1, 0) > 0) p.revents = single.revents;
        } else if (it->second.gone) {
          p.revents = POLLERR;
        } else if (it->second.streaming && !it->second.queued.empty()) {
          drop_overdue(f, it->second, now);
          const int64_t due = due_ns(f, it->second);
          if (now >= due) p.revents = short(p.events & POLLIN);
          else wake = std::min(wake, due);
        }
        ready += p.revents != 0;
      }
      if (ready > 0 || now >= deadline) return ready;
    }
    wake = std::min(wake, now_ns() + 1'000'000);  // other descriptors: look again within 1 ms
    const timespec until{time_t(wake / 1'000'000'000), long(wake % 1'000'000'000)};
    clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &until, nullptr);
  }
}
