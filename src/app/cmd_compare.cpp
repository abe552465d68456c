// loopgate compare: the same dataset and configuration through the registry's methods (DIRD raw and
// standardised, SeqSLAM, each full and gated; --methods picks), one after the other (each run alone on the
// machine), side by side: a table on stdout, compare.json (one object per
// method holding that run's summary.json, plus the ratios), each run's outputs in OUT/<method>, and the
// plots of scripts/plot.py in OUT/plots.
// GCC 12 at -O3 reports a "potential null pointer dereference" inside nlohmann::json::value() as inlined
// into this file's functions (a false positive: the object is a reference to a live summary).
#pragma GCC diagnostic ignored "-Wnull-dereference"

#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "app/commands.hpp"
#include "app/compare_report.hpp"
#include "app/plot_script.hpp"
#include "app/result_block.hpp"
#include "app/stop_signals.hpp"
#include "app/summary_fields.hpp"
#include "core/error.hpp"
#include "io/config.hpp"
#include "io/dataset.hpp"
#include "io/file_guard.hpp"
#include "io/provenance.hpp"
#include "io/writers.hpp"
#include "pipeline/loops/correct_after_run.hpp"
#include "pipeline/loops/loop_closer.hpp"
#include "pipeline/loops/loop_correction_policy.hpp"
#include "pipeline/methods/method_registry.hpp"
#include "pipeline/odometry_factory.hpp"
#include "pipeline/pipeline.hpp"
#include "pipeline/two_sequence.hpp"

namespace loopgate::app {

namespace {

namespace fs = std::filesystem;
using nlohmann::json;

struct CompareOptions {
  std::string config_file;
  std::string dataset;
  std::string reference, query;  // two-sequence compare
  bool methods_given = false;
  std::string out_dir;
  std::string methods = "full,gated,seqslam,seqslam-gated,std-full,std-gated,dird-seqslam,dird-seqslam-gated";
  std::string frames;
  std::string calibration;
  int threads = 0;
  bool no_plots = false;
  bool force = false;
  std::string plot_script;
  std::vector<std::string> overrides;
};

// The methods of a two-sequence compare: the registry's rows with a two-sequence form (no poses: no gate).
const std::string kTwoSequenceMethods = method_entry_names(true);

// What a compare writes into its folder: compare.json, the plots and one run folder per method.
std::vector<std::string> compare_output_names() {
  std::vector<std::string> names = {"compare.json", "plots"};
  for (const MethodEntry& m : kMethods) names.emplace_back(m.name);
  return names;
}

void remove_compare_outputs(const fs::path& out_dir) {
  std::error_code ec;
  for (const std::string& name : compare_output_names()) fs::remove_all(out_dir / name, ec);
}

// --threads and --frames as the keys they set (besides the command's own flags).
void add_run_flags(const CompareOptions& options, std::vector<FlagValue>& flags) {
  if (options.threads > 0) flags.push_back({"run.threads", std::to_string(options.threads), "--threads"});
  if (!options.frames.empty()) flags.push_back({"run.frames", options.frames, "--frames"});
  if (!options.calibration.empty())
    flags.push_back({"dataset.calibration", options.calibration, "--calibration"});
}

// Before a compare writes anything: no output over an input (compare.json, each method's run
// files), one command at a time in the folder (`lock`, taken here for `command`), and no earlier compare's
// outputs unless --force, whose folders then go (none is taken for this one's).
void claim_output_folder(const CompareOptions& options, const PipelineConfig& base,
                         const std::vector<std::string>& methods, std::optional<OutputLock>& lock,
                         const char* command) {
  const fs::path out_dir = options.out_dir;
  refuse_outputs_over_inputs({{"the output", out_dir / "compare.json"}}, {{"--config", options.config_file}});
  for (const std::string& method : methods)
    refuse_outputs_over_inputs(base, out_dir / method, {options.config_file});
  lock.emplace(out_dir, command);
  // A single run's outputs in the folder count too: aggregate would read them beside the compare's.
  std::vector<std::string> previous = compare_output_names();
  previous.insert(previous.end(), run_output_file_names().begin(), run_output_file_names().end());
  refuse_previous_outputs(out_dir, previous, options.force, "compare");
  remove_compare_outputs(out_dir);
  std::error_code ec;
  for (const std::string& name : run_output_file_names()) fs::remove(out_dir / name, ec);
}

std::string method_names() {
  return method_entry_names();
}

const MethodEntry& find_method(const std::string& name) {
  if (const MethodEntry* m = find_method_entry(name)) return *m;
  throw ConfigError("--methods: '" + name + "' is not one of " + method_names());
}

std::vector<std::string> split_methods(const std::string& text) {
  std::vector<std::string> out;
  std::size_t start = 0;
  while (start <= text.size()) {
    const std::size_t comma = text.find(',', start);
    const std::string name =
        text.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
    find_method(name);
    for (const auto& seen : out) {
      if (seen == name) throw ConfigError("--methods: '" + name + "' listed twice");
    }
    out.push_back(name);
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  return out;
}

// The shared configuration made into one method's (validated again: the mode changes what must hold).
PipelineConfig method_config(const PipelineConfig& base, const std::string& method,
                             LoopCorrection correction) {
  const MethodEntry& m = find_method(method);
  PipelineConfig config = base;
  config.run.mode = m.mode;
  config.run.method = m.detector;
  config.standardize.mode = m.standardize;
  config.run.method_row = m.name;
  // Standardised codes take the fixed standardised scale (docs/standardize.md: the online rule's 1% cut-off
  // keeps too few entries across conditions); scale.mode online is for raw DIRD (full, gated refuses it).
  if (config.standardize.enabled() || m.mode == RunMode::kGated) config.scale.mode = ScaleMode::kOff;
  // Geometric verification and the pose graph compare the trajectory, not the detectors: the stream runs
  // without them unless the policy verifies while streaming (compare's, LoopCorrection::kAfterRun, does not),
  // so every column times the same loop-detection work (a full method's thousands of loops would each be
  // verified); the loops are verified after the run (correct_trajectory).
  config.verify.enabled = verifies_while_streaming(correction);
  // gate.feedback needs the verified loops while the run streams.
  if (!config.verify.enabled) config.gate.feedback = false;
  config.validate();
  return config;
}

// Loop correction of one method, after its timed run and outside its timing: the run's loops
// verified and its pose graph solved (what `run` does with verify.enabled), trajectory_corrected.tum and
// loop_edges.csv into its folder, the fields into its summary as "loop_correction". Only when the config
// enables verification; a failure is reported there, it does not stop the compare.
void correct_trajectory(const PipelineConfig& base, const std::string& method, const Dataset& dataset,
                        const RunResult& result, const fs::path& run_dir, json& summary) {
  const PipelineConfig config = method_config(base, method, LoopCorrection::kAfterRun);
  try {
    json fields = correct_after_run(config, dataset, result.track, run_dir);
    const json* before = find_path(summary, {"trajectory_accuracy", "rmse_m"});
    const json* after = find_path(fields, {"trajectory_accuracy_corrected", "rmse_m"});
    spdlog::info("compare: {} loop correction: {} loops, {} verified, ATE {} -> {} m ({:.0f} ms)", method,
                 result.track.loops.size(), fields.at("loops_verified").get<std::size_t>(),
                 before ? number(*before, 3) : "-", after ? number(*after, 3) : "-",
                 fields.at("ms").get<double>());
    summary["loop_correction"] = std::move(fields);
  } catch (const std::exception& e) {
    spdlog::error("compare: the {} loop correction failed: {}", method, e.what());
    summary["loop_correction"] = {{"error", e.what()}};
  }
}

// The console note of a compare stopped by a signal: which methods ran (the last one only over the frames
// it reached) and which did not; empty when not stopped.
std::string interrupted_note(const StopSignals& signals, const std::vector<std::string>& ran,
                             const std::vector<std::string>& methods) {
  if (!signals.stopped()) return "";
  std::vector<std::string> not_run;
  for (const std::string& m : methods)
    if (std::find(ran.begin(), ran.end(), m) == ran.end()) not_run.push_back(m);
  return fmt::format(
      "interrupted by {}: {} stopped early (its column covers the frames it reached){}\n",
      signals.signal_name(), ran.empty() ? std::string("the first method") : ran.back(),
      not_run.empty() ? std::string() : fmt::format("; not run: {}", fmt::join(not_run, ", ")));
}

// The run's example descriptor (DIRD: its first loop's query frame, else the middle frame) for the plots.
void write_descriptor_example(const RunResult& result, const fs::path& run_dir) {
  if (!result.example_descriptor) return;
  const auto& [frame, d] = *result.example_descriptor;
  std::ofstream out(run_dir / "descriptor.csv");
  out << frame;
  for (const std::uint8_t v : d) out << ',' << static_cast<int>(v);
  out << '\n';
}

// scripts/plot.py compare OUT --out OUT/plots; a failure is a warning (the runs' outputs stand).
void write_plots(const CompareOptions& options, const fs::path& out_dir) {
  if (run_plot_script(options.plot_script,
                      {"compare", out_dir.string(), "--out", (out_dir / "plots").string()}, "compare"))
    std::printf("plots in %s\n", (out_dir / "plots").c_str());
}

// Two sequences (--reference A --query B): the cross-condition methods, each run_two_sequences() with its
// configuration, one table and the PR plot. The gated methods need poses, which two sequences do not have.
int compare_two_sequences(const CompareOptions& options) {
  if (options.reference.empty() || options.query.empty()) {
    throw ConfigError("two-sequence compare needs both --reference DIR and --query DIR");
  }
  if (!options.dataset.empty()) throw ConfigError("--dataset and --reference/--query exclude each other");
  const std::vector<std::string> methods =
      split_methods(options.methods_given ? options.methods : kTwoSequenceMethods);
  for (const std::string& method : methods) {
    if (find_method(method).mode == RunMode::kGated) {
      throw ConfigError(
          "--methods: '" + method +
          "' runs inside the pose gate's candidate areas, and two sequences have no poses (choose "
          "from " +
          std::string(kTwoSequenceMethods) + ")");
    }
  }
  std::vector<FlagValue> flags;
  add_run_flags(options, flags);
  const PipelineConfig base =
      load_pipeline_config(options.config_file, options.overrides, flags, ConfigPaths::kMustExist);
  log_config_lines(config_to_lines(base));
  const OpenOptions open_options = base.open_options();
  const fs::path out_dir = options.out_dir;
  std::optional<OutputLock> lock;
  claim_output_folder(options, base, methods, lock, "loopgate compare --reference --query");
  // SIGINT, SIGTERM, SIGHUP: the current method stops describing and writes its outputs, compare.json is
  // written (as for the single-sequence compare).
  const StopSignals signals;
  const auto reference = open_dataset(options.reference, open_options);
  const auto query = open_dataset(options.query, open_options);

  std::map<std::string, json> summaries;
  json compare = json::object();
  std::vector<std::string> ran;
  for (const std::string& method : methods) {
    const PipelineConfig config =
        method_config(base, method, LoopCorrection::kOff);  // two sequences: no loop correction
    spdlog::info("compare: running {} into {}", method, (out_dir / method).string());
    const OutputLock method_lock(out_dir / method, "loopgate compare, method " + method);
    const TwoSequenceResult result =
        run_two_sequences(config, *reference, *query, out_dir / method, signals.flag());
    summaries[method] = result.summary;
    compare[method] = result.summary;
    ran.push_back(method);
    if (result.interrupted) break;
  }
  compare["comparison"] = json::object();
  compare["methods"] = ran;
  compare["provenance"] = provenance_json(config_to_json(base));
  compare["two_sequence"] = {{"reference", options.reference}, {"query", options.query}};
  write_json_file(out_dir / "compare.json", compare);

  std::string header = fmt::format("compare on reference {} vs query {} ({} query frames)", options.reference,
                                   options.query, summaries.at(ran.front()).value("query_frames", 0));
  if (const json* tolerance = find_path(summaries.at(ran.front()), {"aligned", "tolerance_frames"})) {
    header += fmt::format("; aligned sequences, a match is true within +-{} frames", number(*tolerance));
  }
  std::printf("%s\n%s%s", header.c_str(), table(ran, summaries, true).c_str(),
              interrupted_note(signals, ran, methods).c_str());
  if (!options.no_plots) write_plots(options, out_dir);
  std::printf("outputs in %s (compare.json, %s/)\n", out_dir.c_str(),
              fmt::format("{}", fmt::join(ran, "/, ")).c_str());
  std::fflush(stdout);
  if (signals.stopped()) return signals.exit_code();
  return kExitOk;
}

int compare_command(const CompareOptions& options) {
  if (!options.reference.empty() || !options.query.empty()) return compare_two_sequences(options);
  std::vector<std::string> methods = split_methods(options.methods);
  std::vector<FlagValue> flags;
  if (!options.dataset.empty()) flags.push_back({"run.dataset", options.dataset, "--dataset"});
  add_run_flags(options, flags);
  const PipelineConfig base =
      load_pipeline_config(options.config_file, options.overrides, flags, ConfigPaths::kMustExist);
  if (base.run.dataset.empty()) throw ConfigError("run.dataset: no dataset (pass --dataset DIR)");
  log_config_lines(config_to_lines(base));
  const OpenOptions open_options = base.open_options();
  const fs::path out_dir = options.out_dir;
  std::optional<OutputLock> lock;
  claim_output_folder(options, base, methods, lock, "loopgate compare");
  try {
    write_config_yaml(out_dir / "config.yaml", config_to_json(base),
                      "effective base configuration of `loopgate compare` (each method's own in "
                      "<method>/summary.json)");
  } catch (const std::exception& e) {
    spdlog::warn("{}", e.what());
  }
  const StopSignals signals;  // SIGINT, SIGTERM, SIGHUP: the current method drains, compare.json is written
  const auto dataset = open_dataset(base.run.dataset, open_options);
  if (!dataset->has_images()) {  // compare has no --mode: say what it needs, not what `run` would take
    throw DataError(dataset->root(),
                    "compare: every method describes images, and this dataset has none; for its odometry "
                    "alone use `loopgate run --mode odometry`");
  }
  // No poses (odometry.source none, or auto on a dataset without any): the gated methods need the pose gate;
  // by default they are left out, asked for by name they are an error.
  if (resolve_odometry_source(base.odometry, base.ekf, *dataset) == OdometrySourceKind::kNone) {
    std::vector<std::string> full;
    for (const std::string& method : methods) {
      if (find_method(method).mode != RunMode::kGated) {
        full.push_back(method);
      } else if (options.methods_given) {
        throw ConfigError("--methods: '" + method +
                          "' runs inside the pose gate's candidate areas, and this run has no poses "
                          "(odometry.source " +
                          std::string(enum_name(base.odometry.source)) + " for " + base.run.dataset +
                          "): choose full methods (full, seqslam, std-full, dird-seqslam)");
      }
    }
    spdlog::info("compare: no poses (odometry.source {} for {}): the full methods only ({})",
                 enum_name(base.odometry.source), base.run.dataset, fmt::format("{}", fmt::join(full, ", ")));
    methods = full;
  }

  // The loop-correction policy compare hands to its runs: verified and corrected after each run.
  const LoopCorrection correction = compare_loop_correction(base.verify.enabled);
  std::map<std::string, json> summaries;
  json compare = json::object();
  bool failed = false;
  for (const std::string& method : methods) {
    const PipelineConfig config = method_config(base, method, correction);
    spdlog::info("compare: running {} into {}", method, (out_dir / method).string());
    const OutputLock method_lock(out_dir / method, "loopgate compare, method " + method);
    const RunResult result =
        run_pipeline(config, *dataset, out_dir / method, signals.flag(), corrects_after_run(correction));
    std::fputs(fmt::format("[{}]\n{}", method, result.profile_table).c_str(), stderr);
    summaries[method] = result.summary;
    if (corrects_after_run(correction) && !result.failed && !result.interrupted)
      correct_trajectory(base, method, *dataset, result, out_dir / method, summaries[method]);
    compare[method] = summaries[method];
    if (result.failed) {
      spdlog::error("compare: the {} run failed: {}", method, result.error);
      failed = true;
      break;
    }
    if (result.interrupted) break;
    if (method == "gated" || method == "std-gated") write_descriptor_example(result, out_dir / method);
  }

  std::vector<std::string> ran;
  for (const auto& m : methods)
    if (summaries.count(m)) ran.push_back(m);
  json comparison = json::object();
  std::string ratios;
  // Every method's time parts (also in its summary's "time_accounting"): decode + describe + match + rest =
  // total in each.
  json parts = json::object();
  for (const auto& m : ran) parts[m] = time_parts_json(time_parts(summaries.at(m)));
  comparison["time_parts_ms"] = parts;
  if (summaries.count("full") && summaries.count("gated"))
    ratios = full_over_gated(summaries.at("full"), summaries.at("gated"), comparison);
  const std::string truth_counts =
      ran.empty() ? std::string() : truth_counts_text(summaries.at(ran.front()), compare);
  compare["comparison"] = comparison;
  compare["methods"] = ran;
  compare["recommended"] = recommended_method(ran);
  compare["provenance"] = provenance_json(config_to_json(base));
  write_json_file(out_dir / "compare.json", compare);

  if (!ran.empty()) {
    const std::string header = compare_header(base.run.dataset, summaries.at(ran.front()));
    std::printf("%s\n%s%s%s%s%s", header.c_str(), truth_counts.c_str(), table(ran, summaries, false).c_str(),
                kTimeNote, ratios.c_str(), interrupted_note(signals, ran, methods).c_str());
  }

  if (!options.no_plots && !ran.empty()) write_plots(options, out_dir);
  for (const std::string& line : compare_result_lines(ran, summaries, out_dir.string()))
    std::printf("%s\n", line.c_str());
  std::fflush(stdout);
  if (failed) return kExitFailure;
  if (signals.stopped()) return signals.exit_code();
  return kExitOk;
}

}  // namespace

void add_compare_command(CLI::App& app, int& exit_code) {
  auto options = std::make_shared<CompareOptions>();
  CLI::App* cmd = app.add_subcommand("compare",
                                     "Run the detection methods (DIRD full and gated, SeqSLAM, standardised "
                                     "DIRD, dird-seqslam) on one dataset, "
                                     "or the cross-condition ones on two sequences (--reference A --query "
                                     "B), and compare them side by side");
  cmd->add_option("--config", options->config_file, "YAML configuration (configs/*.yaml)")
      ->check(CLI::ExistingFile);
  cmd->add_option("--dataset", options->dataset, "dataset folder or ROS1 .bag file; overrides run.dataset");
  cmd->add_option(
      "--calibration", options->calibration,
      "Kalibr camera-IMU chain for an EuRoC / TUM-VI tree or a bag; overrides dataset.calibration");
  cmd->add_option("--reference", options->reference,
                  "two-sequence compare (with --query): reference dataset folder, e.g. Nordland summer; the "
                  "methods default to " +
                      std::string(kTwoSequenceMethods));
  cmd->add_option("--query", options->query, "two-sequence compare (with --reference): query dataset folder");
  cmd->add_option("--out", options->out_dir,
                  "output folder: compare.json, plots/, and one run folder per method")
      ->required();
  std::string methods_help = "comma-separated subset of:";
  for (const MethodEntry& m : kMethods) methods_help += fmt::format("\n  {:<14} {}", m.name, m.what);
  CLI::Option* methods_option =
      cmd->add_option("--methods", options->methods, methods_help)->capture_default_str();
  cmd->add_option("--frames", options->frames, "frame range A:B (indices, B exclusive; A: or :B)");
  cmd->add_option("--threads", options->threads, "worker threads of each run (default 2)")
      ->check(CLI::Range(1, 256));
  cmd->add_flag("--no-plots", options->no_plots, "do not call scripts/plot.py");
  cmd->add_flag("--force", options->force,
                "replace another compare's outputs in --out (without it such a folder is refused)");
  cmd->add_option("--plot-script", options->plot_script,
                  "path of plot.py (default: scripts/plot.py of the installed or source tree)");
  cmd->add_option("--set", options->overrides, "override any config key: section.key=value (repeatable)")
      ->allow_extra_args(false);
  cmd->callback([options, methods_option, &exit_code] {
    options->methods_given = methods_option->count() > 0;
    exit_code = compare_command(*options);
  });
}

}  // namespace loopgate::app
