#pragma once
// facecapd's one Boost.Asio I/O thread: the network outputs drain their queues on it and
// the control API serves HTTP and WebSocket on it. The solve thread never waits on it;
// outputs hand frames over through rt::SpscSlots. Owned by the supervisor, which gives
// its io_context to the outputs (outputs::SinkContext) and the control server.
#include <thread>

#include <boost/asio/executor_work_guard.hpp>
#include <boost/asio/io_context.hpp>

#include "core/realtime.hpp"

namespace facecap::daemon {

class IoThread {
 public:
  IoThread();
  // stop(). Not RT-safe.
  ~IoThread();
  IoThread(const IoThread&) = delete;
  IoThread& operator=(const IoThread&) = delete;

  // What sinks and servers schedule their work on; valid before start().
  boost::asio::io_context& context() noexcept { return context_; }
  // Runs the context on its own thread until stop(), at SCHED_FIFO `fifo_priority` when
  // it is above 0 (below the solve thread's, so that a frame received is sent without
  // waiting behind the machine's other work); returns how that went. Not RT-safe.
  RealtimeReport start(int fifo_priority = 0);
  // Stops the context (pending handlers are dropped) and joins the thread. Idempotent;
  // not RT-safe.
  void stop() noexcept;

 private:
  boost::asio::io_context context_{1};
  boost::asio::executor_work_guard<boost::asio::io_context::executor_type> work_;
  std::thread thread_;
};

}  // namespace facecap::daemon
