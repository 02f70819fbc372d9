// facecap: the command-line tool (inspect, convert, synth, bench, eval, calibrate, ...).
#include <cstdio>
#include <exception>
#include <new>

#include <CLI/CLI.hpp>

#include "core/error.hpp"
#include "core/log.hpp"
#include "core/version.hpp"
#include "tools/commands.hpp"

int main(int argc, char** argv) {
  CLI::App app{"facecap: facial performance-capture tools"};
  app.require_subcommand(1);
  std::string log_level = "warn";
  app.add_option("--log-level", log_level, "trace, debug, info, warn, error, off")->capture_default_str();
  app.set_version_flag("--version", "facecap " + std::string(facecap::version_string()),
                       "Print the version (and the git commit it was built from) and exit");

  int exit_code = 0;
  // The ordered command table.
  facecap::tools::add_demo_command(app, exit_code);
  facecap::tools::add_inspect_rig_command(app, exit_code);
  facecap::tools::add_inspect_command(app, exit_code);
  facecap::tools::add_convert_command(app, exit_code);
  facecap::tools::add_export_command(app, exit_code);
  facecap::tools::add_synth_command(app, exit_code);
  facecap::tools::add_bench_command(app, exit_code);
  facecap::tools::add_calibrate_command(app, exit_code);
  facecap::tools::add_solve_command(app, exit_code);
  facecap::tools::add_eval_command(app, exit_code);
  facecap::tools::add_subscribe_command(app, exit_code);
  facecap::tools::add_daemon_demo_command(app, exit_code);
  facecap::tools::add_loopcheck_command(app, exit_code);
  facecap::tools::add_diff_command(app, exit_code);
#if FACECAP_WITH_NATNET
  facecap::tools::add_natnet_serve_command(app, exit_code);
#endif
  facecap::tools::add_ctl_command(app, exit_code);

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int status = app.exit(e);
    // diff answers as diff(1) does: 1 means "they differ", so its usage errors are 2.
    return status != 0 && app.get_subcommand("diff")->parsed() ? 2 : status;
  } catch (const facecap::Error& e) {
    std::fprintf(stderr, "facecap: error: %s\n", e.what());
    return 1;
  } catch (const std::bad_alloc&) {
    // Readers bound every size by their input's, so this is a machine short of memory.
    std::fprintf(stderr, "facecap: error: out of memory\n");
    return 1;
  } catch (const std::exception& e) {
    // A library's own exception (std::filesystem, Eigen, CLI11 callbacks): still exit 1
    // with its message rather than abort.
    std::fprintf(stderr, "facecap: error: %s\n", e.what());
    return 1;
  } catch (...) {
    std::fprintf(stderr, "facecap: error: unknown exception\n");
    return 1;
  }
  return exit_code;
}
