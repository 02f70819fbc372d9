#pragma once
// The solve settings of `facecap solve` and `facecap eval`: the same [solver] section (and
// calibration.stabilise_head) as facecapd reads, from --config FILE and --set KEY=VALUE, so
// that a live solve can be reproduced offline. A recording's stored settings are the
// starting point when solving a recording, unless --config names another file.
#include <optional>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "config/daemon_config.hpp"

namespace facecap::tools {

struct SolveConfigOptions {
  std::string file;               // --config
  std::vector<std::string> sets;  // --set solver.KEY=VALUE
};

// Adds --config and --set to a command.
void add_solve_config_options(CLI::App& command, SolveConfigOptions& options);

// Where the settings came from, for the command's summary ("defaults", "facecapd.toml",
// "the recording's stored settings", each "with --set").
struct SolveConfig {
  config::DaemonConfig values;
  std::string origin;
};

// The configuration --config and --set give, on top of `stored` (a recording's stored
// settings, as TOML, named `stored_name` in errors) when there is no --config. Throws Error
// for an invalid file or value, and for --set of keys a solve does not use.
SolveConfig load_solve_config(const SolveConfigOptions& options, const std::optional<std::string>& stored = std::nullopt,
                              const std::string& stored_name = {});

}  // namespace facecap::tools
