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

// Whether `fd` is the stream systemd connected to the journal: $JOURNAL_STREAM holds that
// stream's "device:inode", which a redirected or inherited descriptor does not match
// (the check sd_journal's documentation gives).
bool is_journal_stream(int fd);

// Shapes the default logger's lines for where they go (it writes to standard output).
// Under journald each line starts with its sd-daemon priority ("<3>" error, "<4>"
// warning, "<6>" info, <sd-daemon.h>), so that `journalctl -p err` finds errors, and
// carries no time (journald adds it); elsewhere spdlog's default pattern is kept.
void configure_log_output();

}  // namespace facecap
