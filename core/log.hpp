#pragma once
// Logging through spdlog. Never call from the solve thread: real-time code reports
// through counters that a non-real-time thread turns into text.
#include <string_view>

#include <spdlog/spdlog.h>

namespace facecap {

// Sets the default logger's level from a name (trace, debug, info, warn, error, off).
// Returns false for an unknown name.
bool set_log_level(std::string_view level);

}  // namespace facecap
