#pragma once
// A progress bar on stderr for long-running commands (convert, later solve and bench).
#include <chrono>
#include <cstddef>
#include <string>

namespace facecap::tools {

bool stderr_is_terminal() noexcept;

class ProgressBar {
 public:
  // Draws only when enabled: redrawn in place on a terminal, one line per 10% otherwise
  // (so logs of --progress runs stay readable).
  ProgressBar(std::string label, bool enabled);
  ~ProgressBar();
  void update(std::size_t done, std::size_t total);
  void finish();  // ends the bar's line; called by the destructor if needed

 private:
  std::string label_;
  bool enabled_;
  bool terminal_;
  bool drawn_ = false;
  int last_percent_ = -1;
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
};

}  // namespace facecap::tools
