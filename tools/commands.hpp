#pragma once
// Each facecap subcommand lives in its own file and registers itself here; main.cpp
// holds the one ordered table of them.
#include <CLI/CLI.hpp>

namespace facecap::tools {

// Each adds its subcommand to app; the callback runs it and sets exit_code.
void add_demo_command(CLI::App& app, int& exit_code);
void add_inspect_rig_command(CLI::App& app, int& exit_code);
void add_inspect_command(CLI::App& app, int& exit_code);
void add_convert_command(CLI::App& app, int& exit_code);
void add_export_command(CLI::App& app, int& exit_code);
void add_synth_command(CLI::App& app, int& exit_code);
void add_bench_command(CLI::App& app, int& exit_code);
void add_calibrate_command(CLI::App& app, int& exit_code);
void add_solve_command(CLI::App& app, int& exit_code);
void add_eval_command(CLI::App& app, int& exit_code);
void add_subscribe_command(CLI::App& app, int& exit_code);
void add_daemon_demo_command(CLI::App& app, int& exit_code);
void add_loopcheck_command(CLI::App& app, int& exit_code);
void add_diff_command(CLI::App& app, int& exit_code);
#if FACECAP_WITH_NATNET
void add_natnet_serve_command(CLI::App& app, int& exit_code);
#endif
void add_ctl_command(CLI::App& app, int& exit_code);

}  // namespace facecap::tools
