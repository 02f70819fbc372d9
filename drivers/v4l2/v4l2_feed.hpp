#pragma once
// Cameras streamed through V4L2 with memory-mapped buffers (the kernel's video capture
// interface, linux/videodev2.h): GREY is used in place, YUYV gives its luma, MJPEG is
// decoded to greyscale (OpenCV's imdecode). One thread (the driver's) polls every camera's
// descriptor and takes whichever frame is ready.
#include <string>
#include <vector>

#include <poll.h>

#include "drivers/api/source_config.hpp"
#include "drivers/v4l2/camera_feed.hpp"

namespace facecap::drivers::v4l2 {

struct V4l2CameraSpec {
  std::string device;      // /dev/video0, /dev/v4l/by-id/...
  std::string name;        // the calibration's name, for messages
  int width = 0, height = 0;  // the calibrated size; 0 keeps the camera's
};

class V4l2Feed final : public CameraFeed {
 public:
  V4l2Feed(std::vector<V4l2CameraSpec> cameras, PixelFormat format, double frame_rate_hz);
  ~V4l2Feed() override;

  std::size_t cameras() const override;
  void open() override;
  void start() override;
  bool next(CameraImage& out, int timeout_ms) override;
  void stop() noexcept override;
  std::string description() const override;

 private:
  struct Camera;
  void open_camera(Camera& camera);
  void close_all() noexcept;

  std::vector<Camera> cameras_;
  std::vector<pollfd> polls_;  // one per camera
  PixelFormat format_;
  double frame_rate_hz_;
  std::size_t next_camera_ = 0;      // round robin among ready cameras
  int held_camera_ = -1;             // whose buffer out.grey points into, requeued at the next call
  bool streaming_ = false;
};

}  // namespace facecap::drivers::v4l2
