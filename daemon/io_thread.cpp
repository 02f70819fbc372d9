#include "daemon/io_thread.hpp"

#include "core/log.hpp"

namespace facecap::daemon {

IoThread::IoThread() : work_(boost::asio::make_work_guard(context_)) {}

IoThread::~IoThread() { stop(); }

void IoThread::start() {
  if (thread_.joinable()) return;
  thread_ = std::thread([this] {
    try {
      context_.run();
    } catch (const std::exception& e) {
      // Handlers report their own errors; one escaping here is a bug worth a line.
      spdlog::error("I/O thread stopped: {}", e.what());
    }
  });
}

void IoThread::stop() noexcept {
  work_.reset();
  context_.stop();
  if (thread_.joinable()) thread_.join();
}

}  // namespace facecap::daemon
