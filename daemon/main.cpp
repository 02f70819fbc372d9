// facecapd: the real-time facial capture daemon. See docs/daemon.md.
#include <cstdio>
#include <cstdlib>

#include <unistd.h>

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include "config/config_file.hpp"
#include "core/error.hpp"
#include "core/log.hpp"
#include "core/version.hpp"
#include "daemon/daemon.hpp"
#include "daemon/process_signals.hpp"
#include "drivers/table.hpp"

// Runs before every shared library's constructors: see prepare_process_signals. Only an
// executable can have a .preinit_array, so this entry lives here.
static void prepare_process(int, char**, char**) { facecap::daemon::prepare_process_signals(); }
__attribute__((section(".preinit_array"), used)) static void (*const kPrepareProcess)(int, char**, char**) = prepare_process;

int main(int argc, char** argv) {
  using namespace facecap;
  const std::string thread_pools = daemon::pin_library_thread_pools();
  CLI::App app{"facecapd: solves facial markers onto a blendshape rig in real time and publishes the face"};
  std::string config_file, check_file;
  std::vector<std::string> overrides;
  bool print_config = false, print_defaults = false, print_reference = false, list_drivers = false, allow_root = false;
  app.add_option("-c,--config", config_file, "Configuration file (TOML); without one, every key has its default")
      ->check(CLI::ExistingFile);
  app.add_option("--set", overrides, "Override one key, e.g. --set loop.rate_hz=240 (repeatable)");
  std::string kernels;
  app.add_option("--kernels", kernels,
                 "The solver's compiled kernels: auto, avx512, avx2 or portable (the same as --set solver.kernels=...)");
  app.add_option("--check-config", check_file, "Validate FILE and exit: 0 when valid, 1 with every problem listed");
  app.add_flag("--print-config", print_config, "Print the effective configuration and where each value came from");
  app.add_flag("--print-default-config", print_defaults, "Print the documented default configuration file");
  app.add_flag("--print-config-reference", print_reference, "Print the key reference (Markdown, as in docs/config.md)");
  app.add_flag("--list-drivers", list_drivers, "List the marker source drivers");
  app.add_flag("--allow-root", allow_root, "Run even as root (not recommended: see docs/daemon.md)");
  const std::string version = fmt::format("facecapd {}", version_string());
  app.set_version_flag("--version", version, "Print the version (and the git commit it was built from) and exit");
  CLI11_PARSE(app, argc, argv);
  if (!kernels.empty()) overrides.push_back("solver.kernels=" + kernels);

  configure_log_output();

  if (print_defaults) {
    std::fputs(config::render_documented_defaults().c_str(), stdout);
    return 0;
  }
  if (print_reference) {
    std::fputs(config::render_markdown_reference().c_str(), stdout);
    return 0;
  }
  if (list_drivers) {
    for (const auto& entry : drivers::kDriverIds.entries()) {
      const drivers::DriverEntry* built = drivers::find_driver(entry.value);
      fmt::print("{:<8} {}{}\n{:<8} needs: {}\n", entry.name, entry.description,
                 drivers::supports_lockstep(entry.value) ? " (lockstep capable)" : "", "",
                 built ? built->needs : "not built into this facecapd");
    }
    return 0;
  }
  // Loading files below (configuration, rig, calibrations) can take long: stoppable throughout.
  daemon::StartupSignalWatch startup_watch;
  if (!check_file.empty()) {
    try {
      const config::LoadedConfig checked = config::load_config(check_file, overrides);
      for (const std::string& warning : checked.warnings) fmt::print(stderr, "warning: {}\n", warning);
      // What the daemon would load next: the rig, and the calibration checked against it.
      fmt::print("{}: valid; {}\n", check_file, daemon::check_rig_and_calibration(checked.values));
      return 0;
    } catch (const Error& e) {
      fmt::print(stderr, "{}\n", e.what());
      return 1;
    }
  }

  config::LoadedConfig loaded;
  try {
    loaded = config::load_config(config_file, overrides);
  } catch (const Error& e) {
    fmt::print(stderr, "facecapd: invalid configuration, nothing started:\n{}\n", e.what());
    return 1;
  }
  if (print_config) {
    std::fputs(config::render_effective_config(loaded).c_str(), stdout);
    return 0;
  }

  // FACECAPD_ALLOW_ROOT=1 is the same for harnesses that start facecapd in many ways (a
  // test suite or a container running as root).
  if (const char* env = std::getenv("FACECAPD_ALLOW_ROOT"); env && std::string_view(env) == "1") allow_root = true;
  if (::geteuid() == 0 && !allow_root) {
    fmt::print(stderr,
               "facecapd: refusing to run as root. It parses files and network input and needs none of root's "
               "privileges (only CAP_SYS_NICE and CAP_IPC_LOCK for real-time scheduling); run it as the facecap "
               "user, as facecapd.service does, or pass --allow-root (or set FACECAPD_ALLOW_ROOT=1) if you must (a throwaway container).\n");
    return 1;
  }

  if (!thread_pools.empty()) spdlog::info("library thread pools: {}", thread_pools);
  try {
    daemon::Daemon d({.config_file = config_file, .overrides = overrides, .handle_signals = true, .version = version},
                     std::move(loaded));
    d.start();
    startup_watch.stop();
    return d.run();
  } catch (const Error& e) {
    spdlog::critical("{}", e.what());
    return 1;
  } catch (const std::exception& e) {
    spdlog::critical("unexpected error: {}", e.what());
    return 1;
  }
}
