// The end of a run's stream (pipeline_run.hpp): what follows the method's end-of-stream work.
#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <filesystem>
#include <string>
#include <vector>

#include "core/error.hpp"
#include "core/thread_cpu_time.hpp"
#include "io/writers.hpp"
#include "pipeline/graph/pipeline_run.hpp"
#include "pipeline/graph/run_checks.hpp"
#include "pipeline/outputs/run_summary.hpp"

namespace loopgate::pipeline_internal {

void PipelineRun::trace_end_of_stream(const char* name, std::int64_t start_ns, std::int64_t end_ns) {
  if (end_ns < 0) end_ns = clock_.now_ns();
  outputs_.trace().add(TraceEvent{name,
                                  "end_of_stream",
                                  1e-3 * static_cast<double>(start_ns),
                                  1e-3 * static_cast<double>(end_ns - start_ns),
                                  thread_index(),
                                  -1,
                                  -1,
                                  'X',
                                  {}});
}

// The method's end-of-stream work is matching (the matcher's flush, SeqSLAM's search) in the time
// accounting; loops.csv and the loop closure below are the rest.
void PipelineRun::close_run(RunResult& result, const EndOfStreamWork& work) {
  std::int64_t step_ns = clock_.now_ns();
  if (method_->detects()) write_output("loops.csv", [&] { loops_.close(); });
  const std::int64_t closer_start_ns = clock_.now_ns();
  closer_.finish();  // the last loops' verification and the final pose-graph solve
  const double loop_closure_ms = 1e-6 * static_cast<double>(clock_.now_ns() - closer_start_ns);
  const double end_of_stream_ms = 1e-6 * static_cast<double>(clock_.now_ns() - work.start_ns);
  const EndOfStreamTime end_of_stream_time{
      1e-6 * static_cast<double>(work.method_cpu_ns), 1e-6 * static_cast<double>(work.finish_parallel_ns),
      1e-6 * static_cast<double>(thread_cpu_ns() - work.cpu_start_ns - work.method_cpu_ns)};
  if (config_.output.trace) {
    trace_end_of_stream("end of stream: loops.csv", step_ns, closer_start_ns);
    if (closer_.active())
      trace_end_of_stream("end of stream: loop closure (verification, pose graph)", closer_start_ns);
  }
  step_ns = clock_.now_ns();
  {
    std::lock_guard failure_lock(failure_mutex_);
    result.failed = failed_.load();
    result.error = failed_.load() ? failure_ : work.aborted;
  }
  // The end-of-stream work is part of the run (SeqSLAM's search happens there).
  result.wall_s = 1e-9 * static_cast<double>(clock_.now_ns());
  result.cpu_s = cpu_seconds() - work.cpu_start_s;
  result.peak_rss_mb = peak_rss_mb();
  for (std::string& error : outputs_.finish(true)) output_errors_.push_back(std::move(error));
  write_output("the method's files", [&] { method_->write_files(out_dir_); });
  if (closer_.active()) {
    write_output("loop_edges.csv", [&] { closer_.write_edges(out_dir_); });
    write_output("pose_graph.g2o", [&] { closer_.write_graph(out_dir_); });
    write_output("loops.csv's verification", [&] { closer_.annotate_loops(loops_); });
    write_output("trajectory_corrected.tum",
                 [&] { closer_.write_corrected(out_dir_, outputs_.tracked_poses()); });
  }
  if (config_.output.trace)
    trace_end_of_stream("end of stream: outputs (csv, trajectories, method files)", step_ns);
  step_ns = clock_.now_ns();
  fill_counts(result, loop_closure_ms);
  RunParts parts{config_,          dataset_,     range_.first, range_.second,         *method_,
                 outputs_,         loops_,       images_,      steps_.synchronizer(), seqs_,
                 end_of_stream_ms, std::nullopt, &closer_,     end_of_stream_time};
  parts.truth_pairs = truth_pairs_ ? &*truth_pairs_ : nullptr;
  // The evaluation covers the frames the run got to: an interrupted run stops at the last frame presented, a
  // failed one at the last frame through the sink (not the ground truth of frames never seen).
  const std::size_t processed = outputs_.frames_through();
  parts.evaluated_end_frame =
      result.failed
          ? (processed > 0 ? seqs_.frame(static_cast<std::int64_t>(processed) - 1) + 1 : range_.first)
          : presented_end_;
  try {
    result.example_descriptor = method_->example_descriptor();
  } catch (const DataError& e) {
    spdlog::warn("run: no example descriptor for the plots: {}", e.what());
  }
  nlohmann::json evaluation = {{"available", false}};
  step_ns = clock_.now_ns();
  std::vector<std::pair<std::size_t, std::size_t>> truth_loops;
  write_output("the evaluation (ground_truth.tum, truth_loops.csv)",
               [&] { evaluation = evaluate_run(parts, out_dir_, &truth_loops); });
  if (config_.output.trace) trace_end_of_stream("end of stream: evaluation", step_ns);
  const std::vector<std::string> problems = check_run(result);
  result.summary = make_run_summary(parts, result, std::move(evaluation));
  result.summary["problems"] = problems;
  if (const auto start = steps_.odometry_source().start())
    result.summary["odometry_start"] = odometry_start_json(*start);
  add_loop_oracle(result, truth_loops);
  result.track = {range_.first,
                  range_.second,
                  outputs_.tracked_frames(),
                  outputs_.tracked_poses(),
                  outputs_.tracked_sigma_m(),
                  outputs_.tracked_step_cov(),
                  loops_.loops()};
  write_trace_and_summary(result);
}

// The counts of the run and the profiler table, from the sink's counters and the replay.
void PipelineRun::fill_counts(RunResult& result, double loop_closure_ms) const {
  const RunCounters& counters = outputs_.counters();
  result.frames_in = replay_.frames_in();
  result.frames_dropped = replay_.frames_dropped();
  result.frames_processed = counters.processed;
  result.deadline_misses = counters.deadline_misses;
  result.frames_ok = counters.frames_ok;
  result.frames_warning = counters.frames_warning;
  result.frames_error = counters.frames_error;
  result.data_s = counters.data_s();
  result.realtime_factor = result.wall_s > 0 ? result.data_s / result.wall_s : 0.0;
  result.profile_table =
      outputs_.profiler().table(result.wall_s) +
      fmt::format(
          "cpu {:.2f} s / wall {:.2f} s = {:.2f} cores busy; {} frames in, {} processed, {} dropped, {} "
          "deadline misses; real-time factor {:.2f}\n",
          result.cpu_s, result.wall_s, result.wall_s > 0 ? result.cpu_s / result.wall_s : 0.0,
          result.frames_in, result.frames_processed, result.frames_dropped, result.deadline_misses,
          result.realtime_factor) +
      closer_.profile_line() +
      (closer_.active() ? fmt::format("end of stream: loop closure {:.1f} ms\n", loop_closure_ms) : "");
}

// A run that went through its frames and got nothing usable fails loudly, outputs written; the problems
// found (also summary.json's "problems").
std::vector<std::string> PipelineRun::check_run(RunResult& result) const {
  // A run that went through its frames and got nothing usable fails loudly, outputs written.
  std::vector<std::string> problems;
  if (!result.failed && !result.interrupted) {
    problems =
        run_problems(run_check_input(config_, dataset_, outputs_.counters(), steps_.odometry_source().name(),
                                     method_->detects(), steps_.odometry_source().start()));
    if (!problems.empty()) {
      result.failed = true;
      result.error = fmt::format("{}", fmt::join(problems, "; "));
    }
  }
  // A final pose-graph solve that failed corrected nothing: the run fails, and says why (its other outputs
  // are written; trajectory_corrected.tum and pose_graph.g2o are not, and are listed as missing).
  if (!result.interrupted && closer_.active() && !closer_.solve_failure().empty()) {
    problems.push_back("pose graph: the final solve failed, the trajectory is not corrected: " +
                       closer_.solve_failure());
    result.failed = true;
    result.error = fmt::format("{}", fmt::join(problems, "; "));
  }
  return problems;
}

// The loop oracle against this run (after the stream: one more solve of the final graph).
void PipelineRun::add_loop_oracle(RunResult& result,
                                  const std::vector<std::pair<std::size_t, std::size_t>>& truth_loops) {
  if (closer_.active() && config_.posegraph.enabled && !result.interrupted) {
    nlohmann::json oracle = closer_.oracle_report(outputs_.tracked_poses(), truth_loops);
    if (oracle.value("available", false)) {
      const nlohmann::json& share = oracle["share_of_attainable_gain"];
      spdlog::info(
          "loop oracle: ATE odometry {:.3f} m, corrected {:.3f} m, oracle floor {:.3f} m: {} "
          "({} perfect loop edges, {:.0f} ms)",
          oracle["ate_odometry_m"].get<double>(), oracle["ate_corrected_m"].get<double>(),
          oracle["ate_oracle_m"].get<double>(),
          share.is_null() ? "share n/a, " + oracle["share_why"].get<std::string>()
                          : fmt::format("{:.0f}% of the attainable gain", 100.0 * share.get<double>()),
          oracle["oracle_loop_edges"].get<std::size_t>(), oracle["ms"].get<double>());
    }
    result.summary["loop_oracle"] = std::move(oracle);
  }
}

// trace.json, then summary.json last (it says which outputs are missing, when it can itself be written); a
// run with a missing output fails.
void PipelineRun::write_trace_and_summary(RunResult& result) {
  if (config_.output.trace) {
    outputs_.trace().name_process(fmt::format("loopgate run: {} ({}) on {}", method_->name(), method_->mode(),
                                              dataset_.root().string()));
    write_output("trace.json", [&] { outputs_.write_trace(out_dir_ / "trace.json", thread_index()); });
  }
  // Last: summary.json says which outputs are missing (when it can itself be written).
  result.output_errors = output_errors_;
  result.missing_outputs = missing_outputs();
  std::erase(result.missing_outputs, std::string("summary.json"));  // being written now
  result.summary["outputs_missing"] = result.missing_outputs;
  result.summary["output_errors"] = result.output_errors;
  write_output("summary.json", [&] { write_json_file(out_dir_ / "summary.json", result.summary); });
  result.output_errors = output_errors_;
  result.missing_outputs = missing_outputs();
  if (!result.missing_outputs.empty()) result.failed = true;
  if (result.failed) {
    if (result.error.empty())
      result.error = "outputs missing: " + fmt::format("{}", fmt::join(result.missing_outputs, ", "));
    spdlog::error("run failed: {}", result.error);
  }
}

std::vector<std::string> PipelineRun::missing_outputs() const {
  std::vector<std::string> expected = {"frames.csv", "timing.csv", "trajectory.tum", "summary.json"};
  if (method_->detects()) expected.emplace_back("loops.csv");
  if (config_.output.trace) expected.emplace_back("trace.json");
  std::vector<std::string> missing;
  std::error_code ec;
  for (const std::string& name : expected)
    if (!std::filesystem::is_regular_file(out_dir_ / name, ec)) missing.push_back(name);
  if (closer_.active() && !closer_.solve_failure().empty()) {
    for (const char* name : {"trajectory_corrected.tum", "pose_graph.g2o"})
      missing.push_back(std::string(name) + ": not written, the final pose-graph solve failed");
  }
  // Files of the method and of the evaluation are named by their errors.
  for (const std::string& error : output_errors_) {
    const std::string what = error.substr(0, error.find(':'));
    if (std::find(expected.begin(), expected.end(), what) == expected.end()) missing.push_back(error);
  }
  return missing;
}

}  // namespace loopgate::pipeline_internal
