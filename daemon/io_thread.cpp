#include "daemon/io_thread.hpp"

#include <future>

#include "core/log.hpp"

namespace facecap::daemon {

IoThread::IoThread() : work_(boost::asio::make_work_guard(context_)) {}

IoThread::~IoThread() { stop(); }

RealtimeReport IoThread::start(int fifo_priority) {
  if (thread_.joinable()) return {};
  std::promise<RealtimeReport> applied;
  std::future<RealtimeReport> report = applied.get_future();
  thread_ = std::thread([this, fifo_priority, &applied] {
    applied.set_value(fifo_priority > 0 ? apply_realtime({.fifo = true, .priority = fifo_priority})
                                        : RealtimeReport{});
    try {
      context_.run();
    } catch (const std::exception& e) {
      // Handlers report their own errors; one escaping here is a bug worth a line.
      spdlog::error("I/O thread stopped: {}", e.what());
    }
  });
  return report.get();
}

void IoThread::stop() noexcept {
  work_.reset();
  context_.stop();
  if (thread_.joinable()) thread_.join();
}

}  // namespace facecap::daemon
