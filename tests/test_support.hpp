#pragma once
// Helpers for tests: where the shared third-party data is, scratch directories.
#include <filesystem>
#include <string>

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

}  // namespace facecap::test

// Skips the current test (Catch2 v2 has no SKIP) with a message saying what is missing.
#define FACECAP_REQUIRE_SHARED_DATA(var, relative)                                \
  const auto var = ::facecap::test::shared_data(relative);                       \
  if (var.empty()) {                                                             \
    WARN(::facecap::test::missing_shared_data_message(relative));                \
    return;                                                                      \
  }
