#pragma once
// A V4L2 capture device faked in the test process, so that the v4l2 driver's own
// streaming code (open, VIDIOC_QUERYCAP ... REQBUFS, mmap, QBUF/DQBUF, poll, STREAMON/OFF)
// runs end to end without a camera or a kernel module (vivid needs one). The test binary
// that links fake_v4l2.cpp interposes open, ioctl and poll: a registered path opens as a
// memfd holding the capture buffers, so the driver's mmap of them is the kernel's own;
// every other path and descriptor goes to libc. Frames come due at the device's rate on
// CLOCK_MONOTONIC, as a camera's would, and a frame not taken in time is dropped (its
// sequence number skipped), as V4L2 drivers do. Not thread-safe across devices' owners:
// one driver thread uses them, the test thread registers and plugs. Built also as a module
// that another process (facecapd) loads with LD_PRELOAD (fake_v4l2_preload.cpp).
#include <cstdint>
#include <functional>
#include <string>

namespace facecap::test::fake_v4l2 {

struct Device {
  std::string path;                  // created as an empty file, so that it exists
  std::string card = "facecap fake IR camera";
  uint32_t fourcc = 0;               // V4L2_PIX_FMT_GREY, _YUYV or _MJPEG (0: GREY)
  int width = 640, height = 480;
  int64_t period_ns = 0;             // frame interval; VIDIOC_S_PARM may change it
  int64_t offset_ns = 0;             // this camera's frames come this long after the grid
  // Draws frame `sequence` as 8-bit grey, `stride` bytes a row (the fake expands it to
  // YUYV, or encodes it as a one-component JPEG, when that is the format).
  std::function<void(int64_t sequence, uint8_t* grey, int stride)> render;
  // Told of each frame handed out, with its V4L2 sequence number and timestamp (as the
  // buffer carries it: whole microseconds). Optional.
  std::function<void(int64_t sequence, int64_t timestamp_ns)> dequeued;
};

// Registers a device at d.path. The grid of frame times starts at the first STREAMON of any
// device, so that the cameras' frames line up as genlocked cameras' do.
void add(Device device);
// The device goes away: an open descriptor polls POLLERR and DQBUF fails with ENODEV, and
// the path disappears. plug() brings the path back (a new open streams again).
void unplug(const std::string& path);
void plug(const std::string& path);
// When frame 0 of every device was due (its first STREAMON); 0 before.
int64_t grid_start_ns();
// Frames handed out (DQBUF) and dropped (not taken in time) so far, over every device.
uint64_t frames_dequeued();
uint64_t frames_dropped();
// Forgets every device (the test's end).
void clear();

}  // namespace facecap::test::fake_v4l2
