#include "core/log.hpp"

#include <cstdio>
#include <cstdlib>
#include <memory>

#include <spdlog/pattern_formatter.h>
#include <sys/stat.h>
#include <unistd.h>

#include "core/printable.hpp"

namespace facecap {
namespace {

// "%*": the sd-daemon priority prefix of the message's level.
class JournalPriorityFlag final : public spdlog::custom_flag_formatter {
 public:
  void format(const spdlog::details::log_msg& msg, const std::tm&, spdlog::memory_buf_t& dest) override {
    const std::string_view prefix = priority_prefix(msg.level);
    dest.append(prefix.data(), prefix.data() + prefix.size());
  }
  std::unique_ptr<custom_flag_formatter> clone() const override { return std::make_unique<JournalPriorityFlag>(); }

 private:
  // LOG_ERR is 3, LOG_WARNING 4, ... (syslog.h), as SD_ERR ("<3>") etc. spell them.
  static std::string_view priority_prefix(spdlog::level::level_enum level) {
    switch (level) {
      case spdlog::level::critical: return "<2>";
      case spdlog::level::err: return "<3>";
      case spdlog::level::warn: return "<4>";
      case spdlog::level::info: return "<6>";
      default: return "<7>";
    }
  }
};

// "%v": the message with control characters and bytes that are not UTF-8 escaped
// (core/printable.hpp), so that text from outside in a message can neither start a line of
// its own (with a journald priority such as "<0>") nor drive the terminal.
class PrintableMessageFlag final : public spdlog::custom_flag_formatter {
 public:
  void format(const spdlog::details::log_msg& msg, const std::tm&, spdlog::memory_buf_t& dest) override {
    text_.clear();
    append_printable(std::string_view(msg.payload.data(), msg.payload.size()), text_);
    dest.append(text_.data(), text_.data() + text_.size());
  }
  std::unique_ptr<custom_flag_formatter> clone() const override { return std::make_unique<PrintableMessageFlag>(); }

 private:
  std::string text_;
};

}  // namespace

bool is_journal_stream(int fd) {
  const char* stream = std::getenv("JOURNAL_STREAM");
  struct stat st {};
  if (!stream || fstat(fd, &st) != 0) return false;
  unsigned long long device = 0, inode = 0;
  return std::sscanf(stream, "%llu:%llu", &device, &inode) == 2 && device == st.st_dev && inode == st.st_ino;
}

void configure_log_output() {
  auto formatter = std::make_unique<spdlog::pattern_formatter>();
  formatter->add_flag<PrintableMessageFlag>('v');
  if (is_journal_stream(STDOUT_FILENO)) formatter->add_flag<JournalPriorityFlag>('*').set_pattern("%*%l: %v");
  else formatter->set_pattern("[%Y-%m-%d %H:%M:%S.%e] [%^%l%$] %v");  // spdlog's default, its message escaped
  spdlog::set_formatter(std::move(formatter));
}

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
