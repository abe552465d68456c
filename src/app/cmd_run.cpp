// loopgate run: replays a dataset through the streaming graph (src/pipeline) and writes the run outputs.
#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "app/commands.hpp"
#include "app/result_block.hpp"
#include "app/stop_signals.hpp"
#include "core/error.hpp"
#include "io/config.hpp"
#include "io/dataset.hpp"
#include "io/file_guard.hpp"
#include "pipeline/methods/method_registry.hpp"
#include "pipeline/pipeline.hpp"
#include "pipeline/two_sequence.hpp"

namespace loopgate::app {

namespace {

// The registry's methods, one per line, for --method's help.
std::string method_help() {
  std::string out;
  for (const MethodEntry& m : kMethods) out += fmt::format("\n  {:<19} {}", m.name, m.what);
  return out;
}

struct RunOptions {
  std::string config_file;
  std::string dataset;
  std::string mode;
  std::string method;
  std::string reference;
  std::string query;
  std::string out_dir;
  std::string rate;
  int threads = 0;
  bool trace = false;
  bool force = false;
  std::string frames;
  std::string calibration;
  std::vector<std::string> overrides;
};

// The problems lenient opening collected: when the run stops before summary.json (which lists them) is
// written, they are the likely cause and must be seen.
void log_dataset_problems(const Dataset& dataset) {
  constexpr std::size_t kShown = 20;
  const auto& issues = dataset.issues();
  if (issues.empty()) return;
  spdlog::error(
      "the run stopped before summary.json; the {} problem(s) found while opening {} (lenient mode):",
      issues.size(), dataset.root().string());
  for (std::size_t i = 0; i < std::min(issues.size(), kShown); ++i)
    spdlog::error("  {}", issues[i].to_string());
  if (issues.size() > kShown) spdlog::error("  ... and {} more", issues.size() - kShown);
}

// The outputs a failed write left out (each file is whole or absent).
void log_missing_outputs(const std::vector<std::string>& missing, const std::vector<std::string>& errors,
                         const std::string& out_dir) {
  if (missing.empty()) return;
  spdlog::error("outputs missing from {}: {}", out_dir, fmt::format("{}", fmt::join(missing, ", ")));
  for (const std::string& error : errors) spdlog::error("  {}", error);
}

// A previous run's outputs, or a compare's compare.json, refused without --force; with it, compare.json goes
// too (aggregate would otherwise report the old compare beside this run's outputs).
void refuse_previous_run_or_compare(const RunOptions& options) {
  std::vector<std::string> previous = run_output_file_names();
  previous.emplace_back("compare.json");
  refuse_previous_outputs(options.out_dir, previous, options.force, "run");
  std::error_code ec;
  std::filesystem::remove(std::filesystem::path(options.out_dir) / "compare.json", ec);
}

// OUT/config.yaml: the effective configuration (YAML, --set and flags applied), loadable again as --config.
// A failure to write it is a warning: summary.json echoes the configuration as well.
void write_run_config(const PipelineConfig& config, const RunOptions& options) {
  const std::filesystem::path file = std::filesystem::path(options.out_dir) / "config.yaml";
  try {
    write_config_yaml(file, config_to_json(config),
                      "effective configuration of `loopgate run`" +
                          (options.config_file.empty() ? std::string(" (built-in defaults)")
                                                       : " from " + options.config_file) +
                          " with the command-line overrides applied");
  } catch (const std::exception& e) {
    spdlog::warn("{}", e.what());
  }
}

// --reference DIR --query DIR: docs/detection.md § Two sequences, appearance only (no odometry).
int run_two_sequence_command(const RunOptions& options, PipelineConfig config) {
  if (options.reference.empty() || options.query.empty()) {
    throw ConfigError("two-sequence mode needs both --reference DIR and --query DIR");
  }
  if (!options.dataset.empty()) {
    throw ConfigError("--dataset and --reference/--query exclude each other");
  }
  log_config_lines(config_to_lines(config));
  refuse_outputs_over_inputs(config, options.out_dir, {options.config_file});
  const OutputLock lock(options.out_dir, "loopgate run --reference --query");
  refuse_previous_run_or_compare(options);
  write_run_config(config, options);
  const OpenOptions open_options = config.open_options();
  const StopSignals signals;
  const auto reference = open_dataset(options.reference, open_options);
  const auto query = open_dataset(options.query, open_options);
  TwoSequenceResult result;
  try {
    result = run_two_sequences(config, *reference, *query, options.out_dir, signals.flag());
  } catch (...) {
    log_dataset_problems(*reference);
    log_dataset_problems(*query);
    throw;
  }
  std::printf(
      "two-sequence run: %zu reference x %zu query frames, %zu loop closures in %.2f s; outputs in %s\n",
      result.reference_frames, result.query_frames, result.loops, result.wall_s, options.out_dir.c_str());
  std::fflush(stdout);
  if (result.interrupted) {
    spdlog::warn("interrupted ({}): outputs written for the {} query frames processed", signals.signal_name(),
                 result.query_frames);
    return signals.exit_code();
  }
  return kExitOk;
}

int run_command(const RunOptions& options) {
  // YAML, then --set in order, then the dedicated flags (each names the key it sets).
  std::vector<FlagValue> flags;
  if (!options.dataset.empty()) flags.push_back({"run.dataset", options.dataset, "--dataset"});
  if (!options.mode.empty()) flags.push_back({"run.mode", options.mode, "--mode"});
  if (!options.method.empty()) flags.push_back({"run.method", options.method, "--method"});
  if (!options.rate.empty()) flags.push_back({"run.rate", options.rate, "--rate"});
  if (options.threads > 0) flags.push_back({"run.threads", std::to_string(options.threads), "--threads"});
  if (options.trace) flags.push_back({"output.trace", "true", "--trace"});
  if (!options.frames.empty()) flags.push_back({"run.frames", options.frames, "--frames"});
  if (!options.calibration.empty())
    flags.push_back({"dataset.calibration", options.calibration, "--calibration"});
  PipelineConfig config =
      load_pipeline_config(options.config_file, options.overrides, flags, ConfigPaths::kMustExist);
  if (!options.reference.empty() || !options.query.empty()) return run_two_sequence_command(options, config);
  if (config.run.dataset.empty())
    throw ConfigError("run.dataset: no dataset (pass --dataset DIR or --dataset FILE.bag)");
  log_config_lines(config_to_lines(config));
  // Before anything is written: no output over an input, and one command at a time in the folder.
  refuse_outputs_over_inputs(config, options.out_dir, {options.config_file});
  const OutputLock lock(options.out_dir, "loopgate run");
  refuse_previous_run_or_compare(options);
  write_run_config(config, options);

  // From here a stop signal (SIGINT, SIGTERM, SIGHUP) drains the run and writes every output.
  const StopSignals signals;
  const OpenOptions open_options = config.open_options();
  const auto dataset = open_dataset(config.run.dataset, open_options);
  if (!dataset->issues().empty()) {
    spdlog::warn("dataset {}: {} problems found while opening (lenient mode; listed in summary.json)",
                 config.run.dataset, dataset->issues().size());
  }

  RunResult result;
  try {
    result = run_pipeline(config, *dataset, options.out_dir, signals.flag());
  } catch (...) {
    log_dataset_problems(*dataset);
    throw;
  }

  std::fputs(result.profile_table.c_str(), stderr);
  std::fflush(stderr);
  spdlog::info(
      "{} of {} frames processed ({} dropped, {} deadline misses; {} ok, {} warning, {} error) in {:.2f} s",
      result.frames_processed, result.frames_in, result.frames_dropped, result.deadline_misses,
      result.frames_ok, result.frames_warning, result.frames_error, result.wall_s);
  for (const std::string& line : run_result_lines(result.summary, options.out_dir))
    std::printf("%s\n", line.c_str());
  std::fflush(stdout);
  log_missing_outputs(result.missing_outputs, result.output_errors, options.out_dir);
  if (result.failed) return kExitFailure;
  if (result.interrupted) {
    spdlog::warn("interrupted ({}): outputs written for the {} frames processed", signals.signal_name(),
                 result.frames_processed);
    return signals.exit_code() != 0 ? signals.exit_code() : kExitInterrupted;
  }
  return kExitOk;
}

}  // namespace

void add_run_command(CLI::App& app, int& exit_code) {
  auto options = std::make_shared<RunOptions>();
  CLI::App* cmd =
      app.add_subcommand("run", "Replay a dataset through the streaming pipeline and write the run outputs");
  cmd->add_option("--config", options->config_file, "YAML configuration (configs/*.yaml)")
      ->check(CLI::ExistingFile);
  cmd->add_option(
      "--dataset", options->dataset,
      "dataset folder (EuRoC, KITTI or image folder) or ROS1 .bag file (section dataset); overrides "
      "run.dataset");
  cmd->add_option("--calibration", options->calibration,
                  "Kalibr camera-IMU chain (camchain-imucam-BAG.yaml, kalibr_imucam_chain.yaml) for an EuRoC "
                  "/ TUM-VI tree or a bag, instead of the one found there; overrides dataset.calibration");
  cmd->add_option("--mode", options->mode,
                  "gated (default: the method only inside the pose gate's candidate areas), full (on every "
                  "frame) or odometry (no loop detection); overrides run.mode");
  cmd->add_option(
      "--method", options->method,
      "a detector, gated or full as --mode says: dird-seqslam (the shipped configs' choice: DIRD matched by "
      "contrast and sequence, robust across day/night and seasons), dird (the paper's matcher; the default "
      "without a config) or seqslam (the baseline); or one of the methods below, which sets the mode too. "
      "Overrides run.method" +
          method_help());
  cmd->add_option("--reference", options->reference,
                  "two-sequence mode (with --query): reference dataset folder, e.g. Nordland summer");
  cmd->add_option("--query", options->query, "two-sequence mode (with --reference): query dataset folder");
  cmd->add_option("--out", options->out_dir,
                  "output folder (frames.csv, trajectory.tum, timing.csv, summary.json)")
      ->required();
  cmd->add_option("--rate", options->rate, "replay rate: max (default) or R x real time, e.g. 1.0");
  cmd->add_option("--threads", options->threads, "worker threads of the graph (default 2)")
      ->check(CLI::Range(1, 256));
  cmd->add_flag("--force", options->force,
                "replace another run's outputs in --out (without it such a folder is refused)");
  cmd->add_flag("--trace", options->trace,
                "also write trace.json (Chrome trace-event format, opens in Perfetto)");
  cmd->add_option("--frames", options->frames, "frame range A:B (indices, B exclusive; A: or :B)");
  cmd->add_option("--set", options->overrides, "override any config key: section.key=value (repeatable)")
      ->allow_extra_args(false);
  cmd->callback([options, &exit_code] { exit_code = run_command(*options); });
}

}  // namespace loopgate::app
