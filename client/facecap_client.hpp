#pragma once
// Thin C++ ownership wrapper over facecap_client.h: RAII, exceptions only from the
// constructors. C++17 and later.
#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>

#include "facecap_client.h"

namespace facecap::client {

// A view of a frame's floats (weights or vertex coordinates), valid until the next read.
struct FloatView {
  const float* data = nullptr;
  std::size_t size = 0;
  const float* begin() const noexcept { return data; }
  const float* end() const noexcept { return data + size; }
  float operator[](std::size_t i) const noexcept { return data[i]; }
  bool empty() const noexcept { return size == 0; }
};

class Subscriber {
 public:
  // Maps the shared-memory segment; throws std::runtime_error with the reason when it cannot.
  explicit Subscriber(const std::string& shm_name) {
    if (const int status = facecap_client_open(shm_name.c_str(), &client_); status != FACECAP_OK)
      throw std::runtime_error("cannot open shared memory '" + shm_name + "': " + facecap_status_string(status));
  }
  // Receives the UDP stream on "ADDRESS:PORT" (facecap_client_open_udp); throws
  // std::runtime_error when it cannot.
  static Subscriber udp(const std::string& address, const std::string& interface_name = {}) {
    facecap_client* client = nullptr;
    const int status = facecap_client_open_udp(address.c_str(), interface_name.empty() ? nullptr : interface_name.c_str(), &client);
    if (status != FACECAP_OK)
      throw std::runtime_error("cannot receive UDP on '" + address + "': " + facecap_status_string(status));
    return Subscriber(client);
  }
  ~Subscriber() { facecap_client_close(client_); }
  Subscriber(const Subscriber&) = delete;
  Subscriber& operator=(const Subscriber&) = delete;
  Subscriber(Subscriber&& other) noexcept : client_(std::exchange(other.client_, nullptr)) {}
  Subscriber& operator=(Subscriber&& other) noexcept {
    std::swap(client_, other.client_);
    return *this;
  }

  uint32_t shape_count() const noexcept { return facecap_client_shape_count(client_); }
  std::string_view shape_name(uint32_t index) const noexcept { return view(facecap_client_shape_name(client_, index)); }
  // "" when the shape has no ARKit name.
  std::string_view arkit_name(uint32_t index) const noexcept { return view(facecap_client_arkit_name(client_, index)); }
  uint32_t vertex_count() const noexcept { return facecap_client_vertex_count(client_); }
  double nominal_rate_hz() const noexcept { return facecap_client_nominal_rate_hz(client_); }
  std::string_view rig_name() const noexcept { return view(facecap_client_rig_name(client_)); }
  uint64_t rig_hash() const noexcept { return facecap_client_rig_hash(client_); }
  int32_t writer_pid() const noexcept { return facecap_client_writer_pid(client_); }
  uint64_t incomplete_frames() const noexcept { return facecap_client_incomplete_frames(client_); }

  // Each returns a facecap_status; `frame` views storage valid until the next read.
  int read_latest(facecap_frame& frame) noexcept { return facecap_client_read_latest(client_, &frame); }
  int read_next(facecap_frame& frame) noexcept { return facecap_client_read_next(client_, &frame); }
  int wait_next(facecap_frame& frame, int64_t timeout_ns) noexcept {
    return facecap_client_wait_next(client_, &frame, timeout_ns);
  }
  int check_writer(int64_t stale_after_ns) noexcept { return facecap_client_check_writer(client_, stale_after_ns); }

  static FloatView weights(const facecap_frame& frame) noexcept { return {frame.weights, frame.shape_count}; }
  static FloatView vertices(const facecap_frame& frame) noexcept {
    return {frame.vertices, frame.vertices ? std::size_t(frame.vertex_count) * 3 : 0};
  }

 private:
  explicit Subscriber(facecap_client* client) noexcept : client_(client) {}
  static std::string_view view(const char* text) noexcept { return text ? std::string_view(text) : std::string_view(); }

  facecap_client* client_ = nullptr;
};

}  // namespace facecap::client
