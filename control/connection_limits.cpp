#include "control/connection_limits.hpp"

#include <algorithm>

namespace facecap::control {

std::optional<ConnectionTable::Id> ConnectionTable::oldest_anonymous(const std::string* address) const {
  for (const Id id : anonymous_order_)
    if (!address || connections_.at(id).address == *address) return id;
  return std::nullopt;
}

ConnectionTable::Admission ConnectionTable::admit(const std::string& address) {
  Admission admission;
  const auto count = anonymous_per_address_.find(address);
  const std::size_t anonymous_from_address = count == anonymous_per_address_.end() ? 0 : count->second;
  const std::size_t anonymous_room =
      limits_.max_connections - std::min(limits_.kept_for_authenticated, limits_.max_connections);
  if (anonymous_from_address >= limits_.max_per_address) {
    admission.evicted = oldest_anonymous(&address);
  } else if (connections_.size() >= limits_.max_connections || anonymous_order_.size() >= anonymous_room) {
    admission.evicted = oldest_anonymous(nullptr);
    if (!admission.evicted) return admission;
  }
  if (admission.evicted) remove(*admission.evicted);
  const Id id = next_id_++;
  anonymous_order_.push_back(id);
  connections_.emplace(id, Connection{address, false, std::prev(anonymous_order_.end()), true});
  ++anonymous_per_address_[address];
  admission.admitted = id;
  return admission;
}

void ConnectionTable::no_longer_anonymous(Connection& connection) {
  anonymous_order_.erase(connection.anonymous_at);
  connection.anonymous = false;
  const auto count = anonymous_per_address_.find(connection.address);
  if (--count->second == 0) anonymous_per_address_.erase(count);
}

void ConnectionTable::authenticated(Id id) {
  const auto found = connections_.find(id);
  if (found != connections_.end() && found->second.anonymous) no_longer_anonymous(found->second);
}

bool ConnectionTable::become_stream_client(Id id) {
  const auto found = connections_.find(id);
  if (found == connections_.end()) return false;
  if (found->second.stream_client) return true;
  // Stream clients leave the kept slots to HTTP requests (commands, /status).
  const std::size_t room = std::min(limits_.max_stream_clients,
                                    limits_.max_connections - std::min(limits_.kept_for_authenticated, limits_.max_connections));
  if (stream_clients_ >= room) return false;
  found->second.stream_client = true;
  ++stream_clients_;
  return true;
}

void ConnectionTable::remove(Id id) {
  const auto found = connections_.find(id);
  if (found == connections_.end()) return;
  if (found->second.anonymous) no_longer_anonymous(found->second);
  if (found->second.stream_client) --stream_clients_;
  connections_.erase(found);
}

AcceptBackoff::Step AcceptBackoff::failed(int64_t now_ns) noexcept {
  delay_ns_ = delay_ns_ == 0 ? kFirstDelayNs : std::min(2 * delay_ns_, kMaxDelayNs);
  ++unreported_;
  Step step{delay_ns_, 0};
  if (!warned_ || now_ns - last_warning_ns_ >= kWarningIntervalNs) {
    step.warn_with_count = unreported_;
    unreported_ = 0;
    last_warning_ns_ = now_ns;
    warned_ = true;
  }
  return step;
}

}  // namespace facecap::control
