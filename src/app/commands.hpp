// Each subcommand lives in its own file src/app/cmd_<name>.cpp and registers itself here.
#pragma once

#include <CLI/CLI.hpp>

namespace loopgate::app {

// Exit codes shared by all subcommands.
constexpr int kExitOk = 0;
constexpr int kExitFailure = 1;        // the job failed (bad input, error during the run)
constexpr int kExitInterrupted = 130;  // SIGINT: outputs written for the frames processed
// SIGTERM and SIGHUP are handled like SIGINT and exit with 128 + signal: 143 and 129 (app/stop_signals.hpp).

// Each add_*_command adds its subcommand to `app`; its callback stores the exit code in `exit_code`.
void add_simulate_command(CLI::App& app, int& exit_code);
void add_describe_command(CLI::App& app, int& exit_code);
void add_calibrate_command(CLI::App& app, int& exit_code);
void add_run_command(CLI::App& app, int& exit_code);
void add_compare_command(CLI::App& app, int& exit_code);
void add_aggregate_command(CLI::App& app, int& exit_code);
void add_config_reference_command(CLI::App& app, int& exit_code);

}  // namespace loopgate::app
