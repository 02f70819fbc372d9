#include "control/commands.hpp"

namespace facecap::control {

Reply error_reply(int status, std::string what) { return {status, {{"error", std::move(what)}}}; }

bool CommandQueue::push(Command command) {
  const std::lock_guard lock(mutex_);
  if (commands_.size() >= capacity_) return false;
  commands_.push_back(std::move(command));
  return true;
}

std::optional<Command> CommandQueue::pop() {
  const std::lock_guard lock(mutex_);
  if (commands_.empty()) return std::nullopt;
  Command command = std::move(commands_.front());
  commands_.pop_front();
  return command;
}

}  // namespace facecap::control
