#pragma once
// Thin C++ ownership wrapper over facecap_client.h: RAII, exceptions only from open().
#include <cstdint>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>

#include "client/facecap_client.h"

namespace facecap::client {

class Subscriber {
 public:
  // Maps the segment; throws std::runtime_error with the reason when it cannot.
  explicit Subscriber(const std::string& shm_name) {
    if (const int status = facecap_client_open(shm_name.c_str(), &client_); status != FACECAP_OK)
      throw std::runtime_error("cannot open shared memory '" + shm_name + "': " + facecap_status_string(status));
  }
  ~Subscriber() { facecap_client_close(client_); }
  Subscriber(const Subscriber&) = delete;
  Subscriber& operator=(const Subscriber&) = delete;
  Subscriber(Subscriber&& other) noexcept : client_(other.client_) { other.client_ = nullptr; }
  Subscriber& operator=(Subscriber&& other) noexcept {
    std::swap(client_, other.client_);
    return *this;
  }

  uint32_t shape_count() const noexcept { return facecap_client_shape_count(client_); }
  std::string_view shape_name(uint32_t index) const noexcept {
    const char* name = facecap_client_shape_name(client_, index);
    return name ? std::string_view(name) : std::string_view();
  }
  uint32_t vertex_count() const noexcept { return facecap_client_vertex_count(client_); }
  double nominal_rate_hz() const noexcept { return facecap_client_nominal_rate_hz(client_); }
  std::string_view rig_name() const noexcept { return facecap_client_rig_name(client_); }
  int32_t writer_pid() const noexcept { return facecap_client_writer_pid(client_); }

  // Each returns a facecap_status; `frame` views storage valid until the next read.
  int read_latest(facecap_frame& frame) noexcept { return facecap_client_read_latest(client_, &frame); }
  int read_next(facecap_frame& frame) noexcept { return facecap_client_read_next(client_, &frame); }
  int wait_next(facecap_frame& frame, int64_t timeout_ns) noexcept {
    return facecap_client_wait_next(client_, &frame, timeout_ns);
  }
  int check_writer(int64_t stale_after_ns) noexcept { return facecap_client_check_writer(client_, stale_after_ns); }

  static std::span<const float> weights(const facecap_frame& frame) noexcept { return {frame.weights, frame.shape_count}; }
  static std::span<const float> vertices(const facecap_frame& frame) noexcept {
    return {frame.vertices, frame.vertices ? std::size_t(frame.vertex_count) * 3 : 0};
  }

 private:
  facecap_client* client_ = nullptr;
};

}  // namespace facecap::client
