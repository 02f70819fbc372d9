#include "control/bounded_workers.hpp"

namespace facecap::control {

BoundedWorkers::BoundedWorkers(std::size_t threads, std::size_t queue_capacity) : queue_capacity_(queue_capacity) {
  threads_.reserve(threads);
  for (std::size_t i = 0; i < threads; ++i) threads_.emplace_back([this] { work(); });
}

BoundedWorkers::~BoundedWorkers() {
  std::deque<Job> dropped;
  {
    const std::lock_guard lock(mutex_);
    stopping_ = true;
    dropped.swap(queue_);
  }
  wake_.notify_all();
  for (std::thread& thread : threads_) thread.join();
  for (Job& job : dropped) job.drop();
}

bool BoundedWorkers::try_submit(std::function<void()> run, std::function<void()> drop) {
  {
    const std::lock_guard lock(mutex_);
    if (stopping_ || queue_.size() >= queue_capacity_) return false;
    queue_.push_back({std::move(run), std::move(drop)});
  }
  wake_.notify_one();
  return true;
}

std::size_t BoundedWorkers::queued() const {
  const std::lock_guard lock(mutex_);
  return queue_.size();
}

void BoundedWorkers::work() {
  for (;;) {
    Job job;
    {
      std::unique_lock lock(mutex_);
      wake_.wait(lock, [this] { return stopping_ || !queue_.empty(); });
      if (stopping_) return;
      job = std::move(queue_.front());
      queue_.pop_front();
    }
    job.run();
  }
}

}  // namespace facecap::control
