#pragma once
// The one shape of every network output (the UDP stream, OSC/VMC, Live Link): a queued sink
// whose sending happens on facecapd's I/O thread (daemon/io_thread.hpp). What differs
// between them, the bytes, is a NetProtocol.
//
// On the solve thread, offer() copies the frame into a pre-sized rt::SpscSlots slot and
// wakes the I/O thread with a non-blocking write to an eventfd, which the io_context
// waits on through a posix::stream_descriptor: no lock, no allocation, no waiting. The
// I/O thread then encodes and sends every queued frame. docs/outputs.md says why an
// eventfd rather than a polling timer (bench/bench_net_wake.cpp measures both).
#include <atomic>
#include <cstdint>
#include <memory>
#include <span>
#include <string>

#include <boost/asio/io_context.hpp>
#include <boost/asio/posix/stream_descriptor.hpp>
#include <boost/asio/steady_timer.hpp>

#include "core/frame.hpp"
#include "core/latency_histogram.hpp"
#include "core/rt/spsc_slots.hpp"
#include "outputs/api/sink.hpp"
#include "outputs/net/udp_sender.hpp"

namespace facecap::outputs {

// What a network output sends. Called on the I/O thread only; not RT-safe (encodes).
class NetProtocol {
 public:
  virtual ~NetProtocol() = default;
  virtual std::string_view name() const noexcept = 0;  // the output table's name
  virtual std::string description() const = 0;         // what it sends, for logs and STATUS
  // Encodes one frame and sends its datagrams; false when any could not be sent (the
  // sender counted the error).
  virtual bool send_frame(const SolvedFrame& frame, UdpSender& out) = 0;
  // Once at start, then every NetSinkSpec::periodic_interval_ns, and with stopping set
  // when the sink stops: what receivers need besides frames (the UDP stream's schema).
  virtual void send_periodic(UdpSender& /*out*/, bool /*stopping*/) {}
};

struct NetSinkSpec {
  UdpDestination destination;
  Eigen::Index shape_count = 0;
  Eigen::Index vertex_count = 0;  // copied into the queue only when > 0 (wants_vertices)
  uint32_t send_every = 1;        // rate limit: every n-th offered frame is sent
  std::size_t queue_frames = 16;  // how far the I/O thread may fall behind before frames are dropped
  int64_t periodic_interval_ns = 0;  // 0: send_periodic only at start and stop
};

// Every n-th frame of a loop at loop_rate_hz so as to send at most max_rate_hz (0: all).
uint32_t send_every_for(double loop_rate_hz, double max_rate_hz) noexcept;

class NetSink final : public OutputSink {
 public:
  // Opens the socket and the eventfd, sizes the queue, and schedules the first
  // send_periodic on `io`. Not RT-safe; throws Error.
  NetSink(boost::asio::io_context& io, NetSinkSpec spec, std::unique_ptr<NetProtocol> protocol);
  // stop(). Not RT-safe.
  ~NetSink() override;
  NetSink(const NetSink&) = delete;
  NetSink& operator=(const NetSink&) = delete;

  std::string_view name() const noexcept override { return protocol_->name(); }
  std::string description() const override;
  bool wants_vertices() const noexcept override { return spec_.vertex_count > 0; }
  // Copies the frame into the queue and wakes the I/O thread; a frame the rate limit skips
  // is only counted as offered, one that finds the queue full is dropped. RT-safe: no
  // allocation, no lock; one non-blocking write(2).
  void offer(const MarkerFrame& markers, const SolvedFrame& solved) noexcept override;
  // Whether offer() would queue now. Producer side only. RT-safe.
  bool ready() noexcept override { return queue_.begin_push() != nullptr; }
  SinkHealth health() const noexcept override;
  // Received -> last datagram sent, per frame delivered. Written on the I/O thread.
  const LatencyHistogram* delivery_latency() const noexcept override { return &delivery_; }
  // Sends what is queued and the protocol's last words on the I/O thread, closes the
  // socket, and waits for that (at most 5 s; then throws Error). Not RT-safe; idempotent.
  void stop() override;

  const UdpSender& sender() const noexcept { return sender_; }

 private:
  void wait_for_wake();
  void wait_for_period();
  void drain(uint64_t at_most) noexcept;  // sends up to at_most queued frames
  void finish() noexcept;

  boost::asio::io_context& io_;
  NetSinkSpec spec_;
  std::unique_ptr<NetProtocol> protocol_;
  UdpSender sender_;
  rt::SpscSlots<SolvedFrame> queue_;
  int wake_fd_ = -1;  // eventfd, owned by wake_
  boost::asio::posix::stream_descriptor wake_;
  boost::asio::steady_timer period_;
  LatencyHistogram delivery_;
  uint32_t phase_ = 0;  // solve thread: frames offered since the last one queued
  std::atomic<uint64_t> offered_{0}, delivered_{0}, dropped_{0};
  std::atomic<bool> stopped_{false};
};

}  // namespace facecap::outputs
