// loopgate: illumination-robust, pose-gated visual loop-closure detection.
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <csignal>
#include <exception>
#include <iostream>

#include "app/commands.hpp"
#include "io/provenance.hpp"

int main(int argc, char** argv) {
  loopgate::record_invocation(argc, argv);  // summary.json provenance: the command line and start time
  // Logs go to stderr: stdout carries results (CSV lines, tables) that users pipe into files.
  spdlog::set_default_logger(spdlog::stderr_color_mt("loopgate"));
  // A file-size limit reached (ulimit -f) becomes a write error, reported like a full disk, instead of
  // killing the process with outputs cut mid-line.
  std::signal(SIGXFSZ, SIG_IGN);
  CLI::App app{"loopgate: pose-gated, illumination-robust visual loop-closure detection (DIRD)"};
  app.set_version_flag("--version", std::string("loopgate ") + loopgate::build_version());
  app.require_subcommand(1);
  std::string log_level = "info";
  app.add_option("--log-level", log_level, "trace|debug|info|warn|error|off")
      ->capture_default_str()
      ->check(CLI::IsMember({"trace", "debug", "info", "warn", "error", "off"}))
      ->each([](const std::string& level) { spdlog::set_level(spdlog::level::from_str(level)); });

  int exit_code = loopgate::app::kExitOk;
  // subcommands are registered below (one line each)
  loopgate::app::add_simulate_command(app, exit_code);
  loopgate::app::add_describe_command(app, exit_code);
  loopgate::app::add_calibrate_command(app, exit_code);
  loopgate::app::add_run_command(app, exit_code);
  loopgate::app::add_compare_command(app, exit_code);
  loopgate::app::add_aggregate_command(app, exit_code);
  loopgate::app::add_config_reference_command(app, exit_code);

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return loopgate::app::kExitFailure;
  }
  return exit_code;
}
