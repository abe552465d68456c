// loopgate compare: the same dataset and configuration through the methods of kCompareMethods (DIRD raw and
// standardised, SeqSLAM, each full and gated; --methods picks), one after the other (each run alone on the
// machine), side by side: a table on stdout, compare.json (one object per
// method holding that run's summary.json, plus the ratios), each run's outputs in OUT/<method>, and the
// plots of scripts/plot.py in OUT/plots.
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
#include "app/compare_methods.hpp"
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
#include "pipeline/loop_closer.hpp"
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
  int threads = 0;
  bool no_plots = false;
  bool force = false;
  std::string plot_script;
  std::vector<std::string> overrides;
};

// The methods of a two-sequence compare (no poses: no gate).
constexpr const char* kTwoSequenceMethods = "full,std-full,seqslam,dird-seqslam";

// What a compare writes into its folder: compare.json, the plots and one run folder per method.
std::vector<std::string> compare_output_names() {
  std::vector<std::string> names = {"compare.json", "plots"};
  for (const CompareMethod& m : kCompareMethods) names.emplace_back(m.name);
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
}

// Before a compare writes anything (issue 15): no output over an input (compare.json, each method's run
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
  std::string out;
  for (const CompareMethod& m : kCompareMethods) out += (out.empty() ? "" : ",") + std::string(m.name);
  return out;
}

const CompareMethod& find_method(const std::string& name) {
  for (const CompareMethod& m : kCompareMethods) {
    if (name == m.name) return m;
  }
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
PipelineConfig method_config(const PipelineConfig& base, const std::string& method) {
  const CompareMethod& m = find_method(method);
  PipelineConfig config = base;
  config.run.mode = m.mode;
  config.run.method = m.detector;
  config.standardize.mode = m.standardize;
  // Standardised codes take the fixed standardised scale (docs/standardize.md: the online rule's 1% cut-off
  // keeps too few entries across conditions); scale.mode online is for raw DIRD (full, gated refuses it).
  if (config.standardize.enabled() || m.mode == RunMode::kGated) config.scale.mode = "off";
  // Geometric verification and the pose graph (issue 13) compare the trajectory, not the detectors: off here,
  // so every column times the same loop-detection work (a full method's thousands of loops would each be
  // verified); `run` with the config runs them.
  config.verify.enabled = false;
  // gate.feedback needs the verified loops while the run streams: off with verification.
  config.gate.feedback = false;
  config.validate();
  return config;
}

// The run's time by kind of work (summary.json "time_accounting", pipeline/time_accounting.hpp): thread
// CPU time in ms, images decoded inside describe booked as decode, the method's end-of-stream work as match,
// so that each row holds the same work in every column and decode + describe + match + rest = total.
struct TimeParts {
  double decode_ms = 0, describe_ms = 0, match_ms = 0, rest_ms = 0, total_ms = 0;
  double describe_and_match_ms() const { return describe_ms + match_ms; }
  double with_decode_ms() const { return decode_ms + describe_ms + match_ms; }
};
TimeParts time_parts(const json& summary) {
  TimeParts t;
  const json* a = summary.contains("time_accounting") ? &summary.at("time_accounting") : nullptr;
  if (a == nullptr) return t;
  t.decode_ms = a->value("decode_ms", 0.0);
  t.describe_ms = a->value("describe_ms", 0.0);
  t.match_ms = a->value("match_ms", 0.0);
  t.rest_ms = a->value("rest_ms", 0.0);
  t.total_ms = a->value("total_ms", 0.0);
  return t;
}
json time_parts_json(const TimeParts& t) {
  return {{"decode_ms", t.decode_ms},
          {"describe_ms", t.describe_ms},
          {"match_ms", t.match_ms},
          {"rest_ms", t.rest_ms},
          {"total_ms", t.total_ms}};
}

// The paper's Fig. 8 (KITTI 00): "the total time of loop-closure detection", 182 763.66 ms for pure DIRD and
// 28 329.93 ms with the pose constraint: feature extraction (its Fig. 7) and similarity, i.e. describe +
// match here. The paper does not say whether reading the images is in it; decode + describe + match is
// printed beside it.
constexpr const char* kTimeNote =
    "time: CPU time of the threads that did the work, summed over frames (a node body's thread and the "
    "threads of its parallel loops; a loaded machine does not inflate it); decode includes the images read "
    "inside describe, match the similarities full DIRD computes inside describe and the end-of-stream work, "
    "rest = sync, odometry, gate, sink; decode + describe + "
    "match + rest = total\n";
constexpr double kPaperFullMs = 182763.66;
constexpr double kPaperGatedMs = 28329.93;

std::string number(const json& value, int decimals = 0) {
  if (value.is_null()) return "-";
  if (value.is_number_integer() || value.is_number_unsigned()) return std::to_string(value.get<long long>());
  return fmt::format("{:.{}f}", value.get<double>(), decimals);
}

std::string table(const std::vector<std::string>& methods, const std::map<std::string, json>& summaries,
                  bool two_sequence) {
  struct Row {
    std::string label;
    std::function<std::string(const json&)> cell;
  };
  const auto at = [](std::vector<std::string> path, int decimals = 0) {
    return [path, decimals](const json& s) {
      const json* v = find_path(s, path);
      return v ? number(*v, decimals) : std::string("-");
    };
  };
  const auto ms = [](double (*part)(const TimeParts&)) {
    return [part](const json& s) { return fmt::format("{:.1f}", part(time_parts(s))); };
  };
  // Precision and recall are undefined (n/a, not 0) when the range holds no true loop.
  const auto pr = [&at](const char* key) {
    return [cell = at({"evaluation", "precision_recall", key}, 3)](const json& s) {
      const json* positives = find_path(s, {"evaluation", "precision_recall", "positives"});
      if (positives && positives->is_number() && positives->get<double>() <= 0) return std::string("n/a");
      return cell(s);
    };
  };
  const Row wall = {"wall time (s)", at({"wall_s"}, 2)};
  const Row rss = {"peak RSS (MiB)", at({"peak_rss_mb"}, 0)};
  const std::vector<Row> quality = {
      {"loops", at({"loops"})},
      {"loops true", at({"evaluation", "loop_truth", "loops_true"})},
      {"loops false", at({"evaluation", "loop_truth", "loops_false"})},
      {"loops without travel", at({"evaluation", "loop_truth", "loops_without_travel"})},
      {"positive query frames", at({"evaluation", "precision_recall", "positives"})},
      {"average precision", pr("average_precision")},
      {"recall at 1 (top match)", pr("recall_at_1")},
      {"recall at 100% precision", pr("recall_at_100")},
      {"recall at 99% precision", pr("recall_at_99")},
      {"recall at 95% precision", pr("recall_at_95")},
  };
  // With verify.enabled: the loop correction after each run (outside its timing).
  const bool corrected = std::any_of(methods.begin(), methods.end(), [&](const std::string& m) {
    return summaries.at(m).contains("loop_correction");
  });
  const std::vector<Row> correction = {
      {"loops verified (geometry)", at({"loop_correction", "loops_verified"})},
      {"ATE odometry (m)", at({"trajectory_accuracy", "rmse_m"}, 3)},
      {"ATE corrected (m)", at({"loop_correction", "trajectory_accuracy_corrected", "rmse_m"}, 3)},
      {"loop correction (ms)", at({"loop_correction", "ms"}, 0)},
  };
  std::vector<Row> rows;
  if (two_sequence) {
    rows = {wall,
            rss,
            {"images decoded", at({"images_decoded"})},
            {"similarities computed", at({"similarities_computed"})}};
  } else {
    rows = {
        wall,
        {"cpu time (s)", at({"cpu_s"}, 2)},
        {"real-time factor", at({"realtime_factor"}, 1)},
        {"time (ms, thread CPU):", [](const json&) { return std::string(); }},
        {"  decode", ms([](const TimeParts& t) { return t.decode_ms; })},
        {"  describe", ms([](const TimeParts& t) { return t.describe_ms; })},
        {"  match", ms([](const TimeParts& t) { return t.match_ms; })},
        {"  rest", ms([](const TimeParts& t) { return t.rest_ms; })},
        {"  total", ms([](const TimeParts& t) { return t.total_ms; })},
        {"  describe + match", ms([](const TimeParts& t) { return t.describe_and_match_ms(); })},
        {"  decode+describe+match", ms([](const TimeParts& t) { return t.with_decode_ms(); })},
        {"  of rest: odometry", at({"time_accounting", "stages_cpu_ms", "odometry"}, 1)},
        {"  of rest: gate", at({"time_accounting", "stages_cpu_ms", "gate"}, 1)},
        {"  of decode: in describe", at({"time_accounting", "decode_in_describe_ms"}, 1)},
        {"  of match: in describe", at({"time_accounting", "match_in_describe_ms"}, 1)},
        rss,
        {"images decoded", at({"images_decoded"})},
        {"descriptors computed", at({"descriptors_computed"})},
        {"similarities computed", at({"similarities_computed"})},
        {"candidate areas", at({"candidate_areas"})},
    };
  }
  rows.insert(rows.end(), quality.begin(), quality.end());
  if (corrected) rows.insert(rows.end(), correction.begin(), correction.end());
  // Columns as wide as the longest method name.
  std::size_t width = 12;
  for (const auto& m : methods) width = std::max(width, m.size());
  width += 2;
  std::string out = fmt::format("{:<26}", "");
  for (const auto& m : methods) out += fmt::format("{:>{}}", m, width);
  out += "\n";
  for (const Row& row : rows) {
    out += fmt::format("{:<26}", row.label);
    for (const auto& m : methods) out += fmt::format("{:>{}}", row.cell(summaries.at(m)), width);
    out += "\n";
  }
  return out;
}

// Loop correction (issue 13) of one method, after its timed run and outside its timing: the run's loops
// verified and its pose graph solved (what `run` does with verify.enabled), trajectory_corrected.tum and
// loop_edges.csv into its folder, the fields into its summary as "loop_correction". Only when the config
// enables verification; a failure is reported there, it does not stop the compare.
void correct_trajectory(const PipelineConfig& base, const std::string& method, const Dataset& dataset,
                        const RunResult& result, const fs::path& run_dir, json& summary) {
  PipelineConfig config = method_config(base, method);
  config.verify.enabled = true;
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
      load_config<PipelineConfig>(options.config_file, options.overrides, flags, ConfigPaths::kMustExist);
  log_config_lines(config_to_lines(base));
  const OpenOptions open_options = base.open_options();
  const fs::path out_dir = options.out_dir;
  std::optional<OutputLock> lock;
  claim_output_folder(options, base, methods, lock, "loopgate compare --reference --query");
  // SIGINT, SIGTERM, SIGHUP: the current method stops describing and writes its outputs, compare.json is
  // written (issue 15, as for the single-sequence compare).
  const StopSignals signals;
  const auto reference = open_dataset(options.reference, open_options);
  const auto query = open_dataset(options.query, open_options);

  std::map<std::string, json> summaries;
  json compare = json::object();
  std::vector<std::string> ran;
  for (const std::string& method : methods) {
    const PipelineConfig config = method_config(base, method);
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
  std::printf("%s\n%s", header.c_str(), table(ran, summaries, true).c_str());
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
      load_config<PipelineConfig>(options.config_file, options.overrides, flags, ConfigPaths::kMustExist);
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
  // No poses (odometry.source none, or auto on a dataset without any): the gated methods need the pose gate;
  // by default they are left out, asked for by name they are an error.
  if (resolve_odometry_source(base.odometry, base.ekf, *dataset) == "none") {
    std::vector<std::string> full;
    for (const std::string& method : methods) {
      if (find_method(method).mode != RunMode::kGated) {
        full.push_back(method);
      } else if (options.methods_given) {
        throw ConfigError("--methods: '" + method +
                          "' runs inside the pose gate's candidate areas, and this run has no poses "
                          "(odometry.source " +
                          base.odometry.source + " for " + base.run.dataset +
                          "): choose full methods (full, seqslam, std-full, dird-seqslam)");
      }
    }
    spdlog::info("compare: no poses (odometry.source {} for {}): the full methods only ({})",
                 base.odometry.source, base.run.dataset, fmt::format("{}", fmt::join(full, ", ")));
    methods = full;
  }

  std::map<std::string, json> summaries;
  json compare = json::object();
  bool failed = false;
  for (const std::string& method : methods) {
    const PipelineConfig config = method_config(base, method);
    spdlog::info("compare: running {} into {}", method, (out_dir / method).string());
    const OutputLock method_lock(out_dir / method, "loopgate compare, method " + method);
    const RunResult result =
        run_pipeline(config, *dataset, out_dir / method, signals.flag(), base.verify.enabled);
    std::fputs(fmt::format("[{}]\n{}", method, result.profile_table).c_str(), stderr);
    summaries[method] = result.summary;
    if (base.verify.enabled && !result.failed && !result.interrupted)
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
  if (summaries.count("full") && summaries.count("gated")) {
    const json& f = summaries.at("full");
    const json& g = summaries.at("gated");
    const TimeParts ft = time_parts(f);
    const TimeParts gt = time_parts(g);
    const auto ratio = [](double a, double b) { return b > 0 ? a / b : 0.0; };
    comparison.update({
        {"full_over_gated_decode_time", ratio(ft.decode_ms, gt.decode_ms)},
        {"full_over_gated_describe_time", ratio(ft.describe_ms, gt.describe_ms)},
        {"full_over_gated_match_time", ratio(ft.match_ms, gt.match_ms)},
        {"full_over_gated_describe_and_match_time",
         ratio(ft.describe_and_match_ms(), gt.describe_and_match_ms())},
        {"full_over_gated_decode_describe_and_match_time", ratio(ft.with_decode_ms(), gt.with_decode_ms())},
        {"full_over_gated_total_time", ratio(ft.total_ms, gt.total_ms)},
        {"full_over_gated_wall_time", ratio(f.value("wall_s", 0.0), g.value("wall_s", 0.0))},
        {"full_over_gated_descriptors",
         ratio(f.value("descriptors_computed", 0.0), g.value("descriptors_computed", 0.0))},
        {"full_over_gated_similarities",
         ratio(f.value("similarities_computed", 0.0), g.value("similarities_computed", 0.0))},
        {"paper_ratio", kPaperFullMs / kPaperGatedMs},
        {"paper_ratio_compares_with", "full_over_gated_describe_and_match_time"},
    });
    if (const json* cov = find_path(g, {"evaluation", "gate_coverage", "covered_fraction"}))
      comparison["gated_true_loop_frames_in_candidate_areas"] = *cov;
    // The paper's ratio is over a drive with loops; over a range without a true loop the ratio says nothing
    // about the paper's.
    const json* positives = find_path(g, {"evaluation", "precision_recall", "positives"});
    const bool loops_in_range = !positives || !positives->is_number() || positives->get<double>() > 0;
    const std::string paper =
        loops_in_range
            ? fmt::format(
                  ": the paper's {:.2f}x (KITTI 00, {:.1f} s -> {:.1f} s, its Fig. 8 \"total time of "
                  "loop-closure detection\": feature extraction + similarity) compares with this one",
                  kPaperFullMs / kPaperGatedMs, kPaperFullMs / 1000.0, kPaperGatedMs / 1000.0)
            : std::string(" (no true loop in the range: not comparable with the paper's ratio)");
    if (!loops_in_range) comparison.erase("paper_ratio_compares_with");
    ratios = fmt::format(
        "full / gated, thread CPU time: decode {:.2f}x, describe {:.2f}x, match {:.2f}x, total {:.2f}x\n"
        "  describe + match {:.2f}x{}\n"
        "  decode + describe + match {:.2f}x (the paper does not say whether its time includes reading the "
        "images); wall {:.2f}x; descriptors {:.2f}x, similarities {:.1f}x\n",
        ratio(ft.decode_ms, gt.decode_ms), ratio(ft.describe_ms, gt.describe_ms),
        ratio(ft.match_ms, gt.match_ms), ratio(ft.total_ms, gt.total_ms),
        ratio(ft.describe_and_match_ms(), gt.describe_and_match_ms()), paper,
        ratio(ft.with_decode_ms(), gt.with_decode_ms()),
        comparison["full_over_gated_wall_time"].get<double>(),
        comparison["full_over_gated_descriptors"].get<double>(),
        comparison["full_over_gated_similarities"].get<double>());
    if (comparison.contains("gated_true_loop_frames_in_candidate_areas")) {
      const json& cov = g.at("evaluation").at("gate_coverage");
      ratios += fmt::format("true-loop query frames inside candidate areas: {} of {} ({:.1f}%)\n",
                            cov.at("covered_query_frames").get<std::size_t>(),
                            cov.at("positive_query_frames").get<std::size_t>(),
                            100.0 * cov.at("covered_fraction").get<double>());
    }
  }
  // The ground truth's loop query frames in 3-D and in the ground plane, and before eval.min_travel_m (issue
  // 14): how much the counts depend on the rule (a drone's flight differs in 3-D; hovering is not a loop).
  std::string truth_counts;
  if (!ran.empty()) {
    if (const json* truth = find_path(summaries.at(ran.front()), {"evaluation", "truth"});
        truth && truth->contains("positives_3d")) {
      compare["truth_counts"] = {{"plane", truth->at("plane")},
                                 {"positives", truth->at("positives")},
                                 {"positives_3d", truth->at("positives_3d")},
                                 {"horizontal_plane", truth->at("horizontal_plane")},
                                 {"positives_horizontal", truth->at("positives_horizontal")},
                                 {"min_travel_m", truth->at("min_travel_m")},
                                 {"positives_without_min_travel", truth->at("positives_without_min_travel")}};
      truth_counts = fmt::format(
          "ground-truth loop query frames: {} in 3-D, {} horizontal ({}); {} in the evaluation's plane ({}), "
          "{} "
          "before eval.min_travel_m = {} m took out revisits without travel\n",
          number(truth->at("positives_3d")), number(truth->at("positives_horizontal")),
          truth->at("horizontal_plane").get<std::string>(), number(truth->at("positives")),
          truth->at("plane").get<std::string>(), number(truth->at("positives_without_min_travel")),
          number(truth->at("min_travel_m"), 1));
    }
  }
  compare["comparison"] = comparison;
  compare["methods"] = ran;
  compare["recommended"] = recommended_method(ran);
  compare["provenance"] = provenance_json(config_to_json(base));
  write_json_file(out_dir / "compare.json", compare);

  if (!ran.empty()) {
    const json& any = summaries.at(ran.front());
    std::string header =
        fmt::format("compare on {} ({} frames)", base.run.dataset, any.value("frames_processed", 0));
    if (const json* truth = find_path(any, {"evaluation", "truth"})) {
      if (truth->contains("pairs_file")) {
        header += fmt::format("; ground-truth loops: the {} pairs of {} ({} in the run's frames)",
                              number(truth->at("pairs")), truth->at("pairs_file").get<std::string>(),
                              number(truth->at("pairs_in_run")));
      } else {
        header += fmt::format(
            "; ground-truth loops within {} m ({}), gap {} frames, {} m of travel, detections true "
            "within {} m",
            number(truth->at("radius_m"), 2), truth->at("plane").get<std::string>(),
            number(truth->at("gap_frames")), number(truth->value("min_travel_m", json(0.0)), 1),
            number(truth->at("accept_radius_m"), 2));
      }
    }
    std::printf("%s\n%s%s%s%s", header.c_str(), truth_counts.c_str(), table(ran, summaries, false).c_str(),
                kTimeNote, ratios.c_str());
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
  cmd->add_option("--reference", options->reference,
                  "two-sequence compare (with --query): reference dataset folder, e.g. Nordland summer; the "
                  "methods default to " +
                      std::string(kTwoSequenceMethods));
  cmd->add_option("--query", options->query, "two-sequence compare (with --reference): query dataset folder");
  cmd->add_option("--out", options->out_dir,
                  "output folder: compare.json, plots/, and one run folder per method")
      ->required();
  std::string methods_help = "comma-separated subset of:";
  for (const CompareMethod& m : kCompareMethods) methods_help += fmt::format("\n  {:<14} {}", m.name, m.what);
  CLI::Option* methods_option =
      cmd->add_option("--methods", options->methods, methods_help)->capture_default_str();
  cmd->add_option("--frames", options->frames, "frame range A:B (indices, B exclusive; A: or :B)");
  cmd->add_option("--threads", options->threads, "worker threads of each run (default 2)")
      ->check(CLI::Range(1, 256));
  cmd->add_flag("--no-plots", options->no_plots, "do not call scripts/plot.py");
  cmd->add_flag("--force", options->force,
                "replace another compare's outputs in --out (without it such a folder is refused)");
  cmd->add_option("--plot-script", options->plot_script,
                  "path of plot.py (default: the source tree's scripts/plot.py)");
  cmd->add_option("--set", options->overrides, "override any config key: section.key=value (repeatable)")
      ->allow_extra_args(false);
  cmd->callback([options, methods_option, &exit_code] {
    options->methods_given = methods_option->count() > 0;
    exit_code = compare_command(*options);
  });
}

}  // namespace loopgate::app
