#pragma once
// Where the v4l2 driver's images come from: the seam below V4L2. V4l2Feed streams real
// cameras (memory-mapped V4L2 buffers); tests put a feed of rendered images in its place,
// so that everything above it (blobs, matching by time, triangulation, the frames handed
// on) is the driver's own code.
#include <cstdint>
#include <string>

#include <opencv2/core.hpp>

namespace facecap::drivers::v4l2 {

struct CameraImage {
  std::size_t camera = 0;     // index into the calibration's cameras
  int64_t timestamp_ns = 0;   // CLOCK_MONOTONIC, as the camera's driver stamped it
  int64_t sequence = 0;       // the camera's own frame counter
  cv::Mat grey;               // CV_8UC1; valid until the next call to next()
};

class CameraFeed {
 public:
  virtual ~CameraFeed() = default;

  virtual std::size_t cameras() const = 0;
  // Opens and configures every camera. Throws Error naming the camera, its device and
  // what the driver needs. Not RT-safe.
  virtual void open() = 0;
  // Starts streaming. Throws Error. Not RT-safe.
  virtual void start() = 0;
  // The next image of any camera, waiting up to timeout_ms; false on timeout. The
  // driver's thread only. Not RT-safe.
  virtual bool next(CameraImage& out, int timeout_ms) = 0;
  // Stops streaming and releases the cameras. Idempotent. Not RT-safe.
  virtual void stop() noexcept = 0;
  // "/dev/video0 (left) 640x480 GREY at 120 Hz, ..." Not RT-safe.
  virtual std::string description() const = 0;
};

}  // namespace facecap::drivers::v4l2
