#include "control/commands.hpp"

#include <algorithm>

namespace facecap::control {

Reply error_reply(int status, std::string what) { return {status, {{"error", std::move(what)}}}; }

bool is_recording_read(const Request& request) noexcept {
  return std::holds_alternative<ListRecordings>(request) || std::holds_alternative<ReadRecording>(request);
}

bool CommandQueue::push(Command command) {
  const std::lock_guard lock(mutex_);
  const std::size_t room = is_recording_read(command.request) && capacity_ > kSlotsKeptForCommands
                               ? capacity_ - kSlotsKeptForCommands
                               : capacity_;
  if (commands_.size() >= room) return false;
  commands_.push_back(std::move(command));
  return true;
}

std::optional<Command> CommandQueue::pop() {
  const std::lock_guard lock(mutex_);
  if (commands_.empty()) return std::nullopt;
  auto next = std::find_if(commands_.begin(), commands_.end(),
                           [](const Command& c) { return !is_recording_read(c.request); });
  if (next == commands_.end()) next = commands_.begin();
  Command command = std::move(*next);
  commands_.erase(next);
  return command;
}

}  // namespace facecap::control
