#pragma once
// Helpers for tests: where the shared third-party data is, scratch directories.
#include <filesystem>
#include <string>
#include <vector>

namespace facecap::test {

// ../shared/data beside the checkout (FACECAP_SHARED_DATA overrides).
std::filesystem::path shared_data_dir();

// Path under shared data, or empty when absent; tests then SKIP with this message.
std::filesystem::path shared_data(const std::string& relative);
std::string missing_shared_data_message(const std::string& relative);

// A fresh, empty directory unique to this test process.
std::filesystem::path scratch_dir(const std::string& name);

// Writes text to a file, creating directories.
void write_text(const std::filesystem::path& path, const std::string& text);

// A whole file as text (empty when absent).
std::string slurp(const std::filesystem::path& path);

// Runs a shell command, returning its standard output; *status gets pclose's status.
std::string run_and_capture(const std::string& command, int* status);

// The built facecap binary run with arguments (each single-quoted), its output captured
// into files under dir.
struct Run {
  int exit_code = -1;
  std::string out, err;
};
// Runs a program of the build tree (relative to it: "tools/facecap", "daemon/facecapd") with
// args, its output captured in dir.
Run run_built(const std::string& program, const std::filesystem::path& dir, const std::vector<std::string>& args);
inline Run run_facecap(const std::filesystem::path& dir, const std::vector<std::string>& args) {
  return run_built("tools/facecap", dir, args);
}

}  // namespace facecap::test

// Skips the current test (Catch2 v2 has no SKIP) with a message saying what is missing.
#define FACECAP_REQUIRE_SHARED_DATA(var, relative)                                \
  const auto var = ::facecap::test::shared_data(relative);                       \
  if (var.empty()) {                                                             \
    WARN(::facecap::test::missing_shared_data_message(relative));                \
    return;                                                                      \
  }
