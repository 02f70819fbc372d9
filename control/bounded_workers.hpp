#pragma once
// A few worker threads and a bounded queue of jobs for them: work many clients can ask for
// at once (the replay page's reads of recordings) runs at most `threads` at a time and
// waits in at most `queue_capacity` places, so it neither holds up the thread that hands it
// out nor grows memory with the number of clients. A full queue refuses the job at once.
// Not real-time code.
#include <condition_variable>
#include <cstddef>
#include <deque>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace facecap::control {

class BoundedWorkers {
 public:
  BoundedWorkers(std::size_t threads, std::size_t queue_capacity);
  // Jobs still queued are dropped (their `drop` runs here); running ones finish first.
  ~BoundedWorkers();
  BoundedWorkers(const BoundedWorkers&) = delete;
  BoundedWorkers& operator=(const BoundedWorkers&) = delete;

  // Queues `run` for a worker; false (neither function called) when the queue is full.
  // `drop` runs instead of `run` if the workers stop first. Any thread.
  bool try_submit(std::function<void()> run, std::function<void()> drop);

  // Jobs waiting (not yet running), for tests and status.
  std::size_t queued() const;

 private:
  struct Job {
    std::function<void()> run, drop;
  };
  void work();

  const std::size_t queue_capacity_;
  mutable std::mutex mutex_;
  std::condition_variable wake_;
  std::deque<Job> queue_;
  bool stopping_ = false;
  std::vector<std::thread> threads_;
};

}  // namespace facecap::control
