#include "core/log.hpp"

namespace facecap {

void set_log_level(LogLevel level) {
  switch (level) {
    case LogLevel::kTrace: spdlog::set_level(spdlog::level::trace); return;
    case LogLevel::kDebug: spdlog::set_level(spdlog::level::debug); return;
    case LogLevel::kInfo: spdlog::set_level(spdlog::level::info); return;
    case LogLevel::kWarn: spdlog::set_level(spdlog::level::warn); return;
    case LogLevel::kError: spdlog::set_level(spdlog::level::err); return;
    case LogLevel::kOff: spdlog::set_level(spdlog::level::off); return;
  }
}

}  // namespace facecap
