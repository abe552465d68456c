// loopgate run: replays a dataset through the streaming graph (src/pipeline) and writes the run outputs.
#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <atomic>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "app/commands.hpp"
#include "core/error.hpp"
#include "io/config.hpp"
#include "io/dataset.hpp"
#include "pipeline/pipeline.hpp"
#include "pipeline/two_sequence.hpp"

namespace loopgate::app {

namespace {

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
  std::string frames;
  std::vector<std::string> overrides;
};

std::atomic<bool> g_stop_requested{false};
static_assert(std::atomic<bool>::is_always_lock_free, "the SIGINT handler needs a lock-free flag");

extern "C" void on_sigint(int) {
  g_stop_requested.store(true);
  std::signal(SIGINT, SIG_DFL);  // a second Ctrl-C ends the process at once
}

// --reference DIR --query DIR: dird.md §5, appearance only (no odometry).
int run_two_sequence_command(const RunOptions& options, PipelineConfig config) {
  if (options.reference.empty() || options.query.empty()) {
    throw ConfigError("two-sequence mode needs both --reference DIR and --query DIR");
  }
  if (!options.dataset.empty()) {
    throw ConfigError("--dataset and --reference/--query exclude each other");
  }
  log_config_lines(config_to_lines(config));
  OpenOptions open_options;
  open_options.strict = config.run.strict;
  open_options.camera_index = config.run.camera_index;
  const auto reference = open_dataset(options.reference, open_options);
  const auto query = open_dataset(options.query, open_options);
  const TwoSequenceResult result = run_two_sequences(config, *reference, *query, options.out_dir);
  std::printf(
      "two-sequence run: %zu reference x %zu query frames, %zu loop closures in %.2f s; outputs in %s\n",
      result.reference_frames, result.query_frames, result.loops, result.wall_s, options.out_dir.c_str());
  std::fflush(stdout);
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
  PipelineConfig config = load_config<PipelineConfig>(options.config_file, options.overrides, flags);
  if (!options.reference.empty() || !options.query.empty()) return run_two_sequence_command(options, config);
  if (config.run.dataset.empty()) throw ConfigError("run.dataset: no dataset (pass --dataset DIR)");
  log_config_lines(config_to_lines(config));

  OpenOptions open_options;
  open_options.strict = config.run.strict;
  open_options.camera_index = config.run.camera_index;
  const auto dataset = open_dataset(config.run.dataset, open_options);
  if (!dataset->issues().empty()) {
    spdlog::warn("dataset {}: {} problems found while opening (lenient mode; listed in summary.json)",
                 config.run.dataset, dataset->issues().size());
  }

  g_stop_requested.store(false);
  auto* previous = std::signal(SIGINT, on_sigint);
  RunResult result;
  try {
    result = run_pipeline(config, *dataset, options.out_dir, &g_stop_requested);
  } catch (...) {
    std::signal(SIGINT, previous);
    throw;
  }
  std::signal(SIGINT, previous);

  std::fputs(result.profile_table.c_str(), stderr);
  std::printf(
      "%zu of %zu frames processed (%zu dropped, %zu deadline misses; %zu ok, %zu warning, %zu error) in "
      "%.2f s: real-time factor %.2f; outputs in %s\n",
      result.frames_processed, result.frames_in, result.frames_dropped, result.deadline_misses,
      result.frames_ok, result.frames_warning, result.frames_error, result.wall_s, result.realtime_factor,
      options.out_dir.c_str());
  std::fflush(stdout);
  if (result.failed) return kExitFailure;
  if (result.interrupted) {
    spdlog::warn("interrupted: outputs written for the {} frames processed", result.frames_processed);
    return kExitInterrupted;
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
  cmd->add_option("--dataset", options->dataset,
                  "dataset folder (EuRoC, KITTI or image folder); overrides run.dataset");
  cmd->add_option("--mode", options->mode,
                  "gated (default: the method only inside the pose gate's candidate areas), full (on every "
                  "frame) or odometry (no loop detection); overrides run.mode");
  cmd->add_option("--method", options->method,
                  "dird (default) or seqslam (the SeqSLAM baseline, gated or full as --mode says); overrides "
                  "run.method");
  cmd->add_option("--reference", options->reference,
                  "two-sequence mode (with --query): reference dataset folder, e.g. Nordland summer");
  cmd->add_option("--query", options->query, "two-sequence mode (with --reference): query dataset folder");
  cmd->add_option("--out", options->out_dir,
                  "output folder (frames.csv, trajectory.tum, timing.csv, summary.json)")
      ->required();
  cmd->add_option("--rate", options->rate, "replay rate: max (default) or R x real time, e.g. 1.0");
  cmd->add_option("--threads", options->threads, "worker threads of the graph (default 2)")
      ->check(CLI::Range(1, 256));
  cmd->add_flag("--trace", options->trace,
                "also write trace.json (Chrome trace-event format, opens in Perfetto)");
  cmd->add_option("--frames", options->frames, "frame range A:B (indices, B exclusive; A: or :B)");
  cmd->add_option("--set", options->overrides, "override any config key: section.key=value (repeatable)")
      ->allow_extra_args(false);
  cmd->callback([options, &exit_code] { exit_code = run_command(*options); });
}

}  // namespace loopgate::app
