#include "outputs/net/net_sink.hpp"

#include <chrono>
#include <cmath>
#include <cstring>
#include <future>

#include <sys/eventfd.h>
#include <unistd.h>

#include <boost/asio/post.hpp>
#include <fmt/format.h>

#include "core/error.hpp"
#include "core/log.hpp"
#include "core/time.hpp"

namespace facecap::outputs {
namespace {

constexpr auto kStopTimeout = std::chrono::seconds(5);

SolvedFrame sized_frame(Eigen::Index shape_count, Eigen::Index vertex_count) {
  SolvedFrame frame;
  frame.resize(shape_count, vertex_count);
  return frame;
}

int make_eventfd() {
  const int fd = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
  if (fd < 0) throw Error(fmt::format("cannot create an eventfd: {}", std::strerror(errno)));
  return fd;
}

}  // namespace

uint32_t send_every_for(double loop_rate_hz, double max_rate_hz) noexcept {
  if (max_rate_hz <= 0.0 || loop_rate_hz <= max_rate_hz) return 1;
  return uint32_t(std::ceil(loop_rate_hz / max_rate_hz - 1e-9));
}

NetSink::NetSink(boost::asio::io_context& io, NetSinkSpec spec, std::unique_ptr<NetProtocol> protocol)
    : io_(io),
      spec_(std::move(spec)),
      protocol_(std::move(protocol)),
      sender_(io, spec_.destination, std::string(protocol_->name())),
      queue_(spec_.queue_frames, sized_frame(spec_.shape_count, spec_.vertex_count)),
      wake_fd_(make_eventfd()),
      wake_(io, wake_fd_),
      period_(io) {
  if (spec_.send_every == 0) spec_.send_every = 1;
  // Everything on the I/O thread from here on, in order: the first periodic message
  // (the UDP stream's schema) goes out before any frame.
  boost::asio::post(io_, [this] {
    protocol_->send_periodic(sender_, false);
    wait_for_wake();
    wait_for_period();
  });
}

NetSink::~NetSink() {
  try {
    stop();
  } catch (const std::exception& e) {
    spdlog::error("output {}: {}", protocol_->name(), e.what());
  }
}

std::string NetSink::description() const {
  return fmt::format("{} to {}{}", protocol_->description(), sender_.describe(),
                     spec_.send_every > 1 ? fmt::format(", every {} frames", spec_.send_every) : "");
}

void NetSink::offer(const MarkerFrame&, const SolvedFrame& solved) noexcept {
  offered_.store(offered_.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
  const bool due = phase_ == 0;
  phase_ = (phase_ + 1) % spec_.send_every;
  if (!due) return;
  SolvedFrame* slot = queue_.begin_push();
  if (!slot) {
    dropped_.fetch_add(1, std::memory_order_relaxed);  // the I/O thread adds to it too
    return;
  }
  copy_solved_frame(solved, *slot);  // the slot was sized like the frame: no allocation
  queue_.commit_push();
  const uint64_t one = 1;
  // Cannot block (EFD_NONBLOCK) and cannot fail short of 2^64 - 1 unread wake-ups.
  [[maybe_unused]] const ssize_t written = ::write(wake_fd_, &one, sizeof one);
}

SinkHealth NetSink::health() const noexcept {
  SinkHealth h;
  h.offered = offered_.load(std::memory_order_relaxed);
  h.delivered = delivered_.load(std::memory_order_relaxed);
  h.dropped = dropped_.load(std::memory_order_relaxed);
  h.errors = sender_.errors();
  h.bytes = sender_.bytes_sent();
  return h;
}

// I/O thread from here on.

void NetSink::wait_for_wake() {
  wake_.async_wait(boost::asio::posix::stream_descriptor::wait_read, [this](const boost::system::error_code& ec) {
    if (ec) return;  // closed by finish(): the sink may be gone, touch nothing
    uint64_t wakes = 0;
    [[maybe_unused]] const ssize_t read = ::read(wake_fd_, &wakes, sizeof wakes);
    // Only the frames this wake-up announced (each commit is followed by one write): a
    // frame queued meanwhile brings its own wake-up. Draining until empty would keep the
    // I/O thread on one output as long as its frames keep coming, and starve the others.
    drain(wakes);
    wait_for_wake();
  });
}

void NetSink::wait_for_period() {
  if (spec_.periodic_interval_ns <= 0) return;
  period_.expires_after(std::chrono::nanoseconds(spec_.periodic_interval_ns));
  period_.async_wait([this](const boost::system::error_code& ec) {
    if (ec) return;  // cancelled by finish()
    protocol_->send_periodic(sender_, false);
    wait_for_period();
  });
}

void NetSink::drain(uint64_t at_most) noexcept {
  for (uint64_t n = 0; n < at_most; ++n) {
    SolvedFrame* frame = queue_.front();
    if (!frame) return;
    bool sent = false;
    try {
      sent = protocol_->send_frame(*frame, sender_);
    } catch (const std::exception& e) {
      spdlog::error("output {}: {}", protocol_->name(), e.what());
    }
    if (sent) {
      delivery_.record(monotonic_now_ns() - frame->receive_time_ns);
      delivered_.fetch_add(1, std::memory_order_relaxed);
    } else {
      dropped_.fetch_add(1, std::memory_order_relaxed);
    }
    queue_.pop();
  }
}

void NetSink::finish() noexcept {
  drain(queue_.capacity());
  try {
    protocol_->send_periodic(sender_, true);
  } catch (const std::exception& e) {
    spdlog::error("output {}: {}", protocol_->name(), e.what());
  }
  boost::system::error_code ignored;
  wake_.close(ignored);
  period_.cancel();
  sender_.close();
}

void NetSink::stop() {
  if (stopped_.exchange(true)) return;
  if (io_.stopped()) {  // nothing runs the I/O thread's handlers any more: do it here
    finish();
    return;
  }
  auto done = std::make_shared<std::promise<void>>();
  std::future<void> finished = done->get_future();
  boost::asio::post(io_, [this, done] {
    finish();
    done->set_value();
  });
  if (finished.wait_for(kStopTimeout) != std::future_status::ready)
    throw Error(fmt::format("output {}: the I/O thread did not finish sending within 5 s", protocol_->name()));
}

}  // namespace facecap::outputs
