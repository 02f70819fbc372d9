#pragma once
// Logging through spdlog. Never call from the solve thread: real-time code reports
// through counters that a non-real-time thread turns into text.
#include <array>
#include <cstdint>

#include <spdlog/spdlog.h>

#include "core/enum_table.hpp"

namespace facecap {

enum class LogLevel : uint8_t { kTrace, kDebug, kInfo, kWarn, kError, kOff };

inline constexpr EnumTable kLogLevels{std::array{
    EnumEntry{LogLevel::kTrace, "trace", "everything, including per-request detail"},
    EnumEntry{LogLevel::kDebug, "debug", "diagnostics for developers"},
    EnumEntry{LogLevel::kInfo, "info", "what the daemon does and its figures"},
    EnumEntry{LogLevel::kWarn, "warn", "only what needs attention"},
    EnumEntry{LogLevel::kError, "error", "only failures"},
    EnumEntry{LogLevel::kOff, "off", "nothing"},
}};

// Sets the default logger's level.
void set_log_level(LogLevel level);

}  // namespace facecap
