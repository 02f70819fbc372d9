#include "tools/progress.hpp"

#include <cstdio>

#include <fmt/format.h>
#include <unistd.h>

namespace facecap::tools {

bool stderr_is_terminal() noexcept { return ::isatty(STDERR_FILENO) == 1; }

ProgressBar::ProgressBar(std::string label, bool enabled)
    : label_(std::move(label)), enabled_(enabled), terminal_(stderr_is_terminal()) {}

ProgressBar::~ProgressBar() { finish(); }

void ProgressBar::update(std::size_t done, std::size_t total) {
  if (!enabled_ || total == 0) return;
  const int percent = int(done * 100 / total);
  if (percent == last_percent_ || (!terminal_ && percent / 10 == last_percent_ / 10 && last_percent_ >= 0)) return;
  last_percent_ = percent;
  drawn_ = true;
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  if (terminal_) {
    constexpr int kWidth = 30;
    const int filled = percent * kWidth / 100;
    fmt::print(stderr, "\r{} [{}{}] {:3}% {}/{} frames {:.1f} s", label_, std::string(std::size_t(filled), '#'),
               std::string(std::size_t(kWidth - filled), ' '), percent, done, total, seconds);
  } else {
    fmt::print(stderr, "{}: {}% ({}/{} frames, {:.1f} s)\n", label_, percent, done, total, seconds);
  }
  std::fflush(stderr);
}

void ProgressBar::finish() {
  if (drawn_ && terminal_) fmt::print(stderr, "\n");
  drawn_ = false;
}

}  // namespace facecap::tools
