#include "drivers/api/marker_source.hpp"

namespace facecap::drivers {

void MailboxSource::configure_mailbox(const std::vector<std::string>& labels) {
  mailbox_ = std::make_unique<rt::LatestMailbox<MarkerFrame>>(make_marker_frame(labels));
}

bool MailboxSource::take_frame(int64_t /*now_ns*/, MarkerFrame& out) noexcept {
  const MarkerFrame* newest = mailbox_ ? mailbox_->take() : nullptr;
  if (!newest) return false;
  // Same marker count as `out` was sized for, so the vector copy reuses its storage.
  out = *newest;
  delivered_.fetch_add(1, std::memory_order_relaxed);
  return true;
}

SourceHealth MailboxSource::health() const noexcept {
  SourceHealth h;
  h.frames_delivered = delivered_.load(std::memory_order_relaxed);
  h.frames_overwritten = mailbox_ ? mailbox_->overwritten() : 0;
  h.frames_late = late_.load(std::memory_order_relaxed);
  h.errors = errors_.load(std::memory_order_relaxed);
  h.foreign = foreign_.load(std::memory_order_relaxed);
  h.reconnects = reconnects_.load(std::memory_order_relaxed);
  h.state = state_.get();
  h.finished = finished_.load(std::memory_order_relaxed);
  return h;
}

}  // namespace facecap::drivers
