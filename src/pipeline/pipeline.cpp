#include "pipeline/pipeline.hpp"

#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>
#include <tbb/flow_graph.h>
#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <mutex>
#include <unordered_map>

#include "core/error.hpp"
#include "core/stop_request.hpp"
#include "io/dataset.hpp"
#include "io/file_guard.hpp"
#include "pipeline/detection_method.hpp"
#include "pipeline/frame_steps.hpp"
#include "pipeline/loop_closer.hpp"
#include "pipeline/loops_writer.hpp"
#include "pipeline/odometry_factory.hpp"
#include "pipeline/parallel_handoff.hpp"
#include "pipeline/run_checks.hpp"
#include "pipeline/run_clock.hpp"
#include "pipeline/run_outputs.hpp"
#include "pipeline/run_resources.hpp"
#include "pipeline/run_summary.hpp"

namespace loopgate {

namespace {

// One run: the objects that do the work (frame steps, detection method, outputs, replay clock), built from
// the configuration, and the graph that wires them. Each node body is one call on one of them.
class PipelineRun {
 public:
  PipelineRun(const PipelineConfig& config, const Dataset& dataset, const std::filesystem::path& out_dir,
              const std::atomic<bool>* stop)
      : config_(config),
        dataset_(dataset),
        out_dir_(out_dir),
        stop_(stop),
        range_(config.run.frame_range(dataset.frame_count())),
        truth_pairs_(load_truth_pairs(config.eval, dataset)),
        seqs_(range_.second - range_.first),
        images_(dataset, seqs_),
        method_(make_detection_method({config, seqs_, images_, loops_, seqs_.capacity()},
                                      dataset.has_images(), dataset.root())),
        closer_(config, dataset, range_.first, range_.second, method_->detects()),
        steps_(config, dataset, make_odometry_source(config.odometry, config.ekf, dataset), images_,
               method_->needs_every_image()),
        outputs_(config, out_dir, *method_, seqs_, clock_, steps_.odometry_source().needs_images(),
                 seqs_.capacity(), &closer_),
        replay_(config.run, dataset, range_.first, clock_) {
    if (closer_.active()) loops_.set_listener([this](const Detection& loop) { closer_.submit(loop); });
  }

  RunResult run();

 private:
  // A node body: the stamps, the hand-over, one call; an exception is recorded once (stage, seq, frame)
  // and cancels the graph. Serial nodes also hold their stage's mutex (the order TSan can see).
  template <class Call>
  auto body(Stage stage, bool serial, Call call) {
    return [this, stage, serial, call](FrameMsg message) -> FrameMsg {
      FrameRecord& r = *message.record;
      r.acquire();
      std::unique_lock lock(stage_mutex_[stage], std::defer_lock);
      if (serial) lock.lock();
      r.stamps[stage].enter_ns = clock_.now_ns();
      r.stamps[stage].thread = thread_index();
      const std::int64_t cpu_start_ns = thread_cpu_ns();
      try {
        const ParallelTimeScope parallel_time(&r.parallel_cpu_ns[stage]);
        call(r);
      } catch (const std::exception& e) {
        fail(fmt::format("stage '{}' failed on seq {} (frame {}, t = {:.6f} s): {}", kStageNames[stage],
                         r.seq, r.label, ns_to_s(r.t_ns), e.what()));
        r.release();
        throw;
      }
      if (stage != kSink) {  // the sink stamps itself before it writes the frame's timing
        r.stamps[stage].exit_ns = clock_.now_ns();
        r.cpu_ns[stage] = thread_cpu_ns() - cpu_start_ns;
      }
      r.release();
      return message;
    };
  }
  void fail(const std::string& what) {
    {
      std::lock_guard lock(failure_mutex_);
      if (!failed_.load()) failure_ = what;
      failed_.store(true);
    }
    replay_.wake();
  }
  bool stop_requested() const { return (stop_ && stop_->load()) || failed_.load(); }
  void produce(tbb::flow::queue_node<FrameMsg>& queue);
  std::vector<std::string> missing_outputs() const;
  void finish_stream(tbb::task_arena& arena, RunResult& result, double cpu_start_s);
  // Runs `write`, one output step after the drain: a failure (a full disk) is recorded, naming the file, and
  // the next outputs are still written.
  template <class Write>
  void write_output(const char* what, Write&& write) {
    try {
      write();
    } catch (const std::exception& e) {
      output_errors_.push_back(std::string(what) + ": " + e.what());
      spdlog::error("run: {}: {}", what, e.what());
    }
  }

  const PipelineConfig& config_;
  const Dataset& dataset_;
  std::filesystem::path out_dir_;
  const std::atomic<bool>* stop_;
  std::pair<std::size_t, std::size_t> range_;  // dataset frames [first, last)
  std::optional<TruthPairs> truth_pairs_;      // eval.truth_pairs_file, read before the run starts
  RunClock clock_;
  SeqIndex seqs_;
  ImageSource images_;
  LoopsWriter loops_;
  std::unique_ptr<DetectionMethod> method_;
  LoopCloser closer_;  // verification + pose graph of the accepted loops, on its own thread
  FrameSteps steps_;
  RunOutputs outputs_;
  ReplayClock replay_;
  std::array<std::mutex, kStageCount> stage_mutex_;
  std::mutex live_mutex_;  // frames inside the graph, by seq (created by the producer, freed by the sink)
  std::unordered_map<std::uint64_t, std::unique_ptr<FrameRecord>> live_;
  std::mutex failure_mutex_;  // the first failure wins
  std::atomic<bool> failed_{false};
  std::string failure_;
  std::size_t presented_end_ = 0;           // the dataset frame after the last one presented (producer)
  std::vector<std::string> output_errors_;  // outputs that could not be written, and why
};

void PipelineRun::produce(tbb::flow::queue_node<FrameMsg>& queue) {
  std::uint64_t next_seq = 0;
  presented_end_ = range_.first;
  for (std::size_t frame = range_.first; frame < range_.second; ++frame) {
    const auto release = replay_.wait_for(frame, [this] { return stop_requested(); });
    if (!release) break;
    presented_end_ = frame + 1;
    if (!release->go) continue;  // dropped (rate mode)
    auto owned = std::make_unique<FrameRecord>();
    FrameRecord* record = owned.get();
    {
      std::lock_guard lock(live_mutex_);
      live_.emplace(next_seq, std::move(owned));
    }
    const std::size_t label = dataset_.source_index(frame);
    seqs_.set(next_seq, frame, dataset_.frame_t_ns(frame), label);
    record->seq = next_seq++;
    record->frame = frame;
    record->label = label;
    record->t_ns = dataset_.frame_t_ns(frame);
    record->release_ns = clock_.now_ns();
    record->deadline_ns = release->deadline_ns;
    record->release();
    replay_.frame_entered();
    queue.try_put(FrameMsg{record->seq, record});
  }
}

RunResult PipelineRun::run() {
  // A previous run's outputs in the folder go first: an output this run fails to write must be absent, not
  // an older one beside the new others (the folder is locked by the command; inputs were checked not to be
  // among these names).
  std::error_code ec;
  for (const std::string& name : run_output_file_names()) {
    std::filesystem::remove(out_dir_ / name, ec);
    std::filesystem::remove(partial_path(out_dir_ / name), ec);
  }
  outputs_.open();
  const auto label = [this](std::size_t frame) { return dataset_.source_index(frame); };
  if (method_->detects()) loops_.open(out_dir_ / "loops.csv", label, label);
  const int threads = config_.run.threads;
  spdlog::info("run: {} frames [{}, {}) of {} ({}), rate {}, {} worker threads, at most {} in flight",
               range_.second - range_.first, range_.first, range_.second, dataset_.root().string(),
               dataset_.layout(), config_.run.rate, threads, config_.run.max_in_flight);
  // `threads` workers run the nodes; the calling thread produces outside the arena and joins it to drain.
  tbb::global_control parallelism(tbb::global_control::max_allowed_parallelism,
                                  static_cast<std::size_t>(threads) + 1);
  tbb::task_arena arena(threads + 1, 1);
  arena.initialize();
  WorkerExitObserver workers(arena);
  using namespace tbb::flow;
  using Node = function_node<FrameMsg, FrameMsg>;
  using Sequencer = sequencer_node<FrameMsg>;
  std::unique_ptr<graph> g;
  std::unique_ptr<queue_node<FrameMsg>> queue;
  std::unique_ptr<limiter_node<FrameMsg, int>> limiter;
  std::vector<std::unique_ptr<Sequencer>> seq;
  std::unique_ptr<Node> sync, decode, odometry, gate, describe, match;
  std::unique_ptr<function_node<FrameMsg, int>> sink;
  arena.execute([&] {
    g = std::make_unique<graph>();
    queue = std::make_unique<queue_node<FrameMsg>>(*g);
    limiter = std::make_unique<limiter_node<FrameMsg, int>>(
        *g, static_cast<std::size_t>(config_.run.max_in_flight));
    for (int k = 0; k < 5; ++k)
      seq.push_back(
          std::make_unique<Sequencer>(*g, [](const FrameMsg& m) { return static_cast<std::size_t>(m.seq); }));
    sync = std::make_unique<Node>(*g, serial, body(kSync, true, [this](FrameRecord& r) { steps_.sync(r); }));
    decode = std::make_unique<Node>(*g, unlimited,
                                    body(kDecode, false, [this](FrameRecord& r) { steps_.decode(r); }));
    odometry = std::make_unique<Node>(*g, serial, body(kOdometry, true, [this](FrameRecord& r) {
      steps_.odometry(r);
      closer_.record_pose(r.frame, r.usable_pose() ? std::optional(r.odometry.pose.T_w_b) : std::nullopt);
    }));
    gate =
        std::make_unique<Node>(*g, serial, body(kGate, true, [this](FrameRecord& r) { method_->gate(r); }));
    describe = std::make_unique<Node>(
        *g, unlimited, body(kDescribe, false, [this](FrameRecord& r) { method_->describe(r); }));
    match =
        std::make_unique<Node>(*g, serial, body(kMatch, true, [this](FrameRecord& r) { method_->match(r); }));
    const auto sink_body = body(kSink, true, [this](FrameRecord& r) { outputs_.sink(r); });
    sink = std::make_unique<function_node<FrameMsg, int>>(*g, serial,
                                                          [this, sink_body](FrameMsg message) -> int {
                                                            sink_body(message);
                                                            {
                                                              std::lock_guard lock(live_mutex_);
                                                              live_.erase(message.seq);
                                                            }
                                                            replay_.frame_left();
                                                            return 1;
                                                          });
    // A serial node's outputs can overtake each other (its next body may start before the previous output
    // is put), so every serial node that needs its frames in order sits behind a sequencer.
    make_edge(*queue, *limiter);
    make_edge(*limiter, *seq[0]);
    make_edge(*seq[0], *sync);
    make_edge(*sync, *decode);
    make_edge(*decode, *seq[1]);
    make_edge(*seq[1], *odometry);
    make_edge(*odometry, *seq[2]);
    make_edge(*seq[2], *gate);
    make_edge(*gate, *describe);
    make_edge(*describe, *seq[3]);
    make_edge(*seq[3], *match);
    make_edge(*match, *seq[4]);
    make_edge(*seq[4], *sink);
    make_edge(*sink, limiter->decrementer());
  });

  sanitizer_suppressions_anchor();  // sanitizer builds: links the oneTBB suppressions (parallel_handoff.hpp)
  RunResult result;
  const double cpu_start_s = cpu_seconds();
  clock_.restart();
  produce(*queue);
  result.interrupted = stop_ && stop_->load();
  try {
    g->wait_for_all();
  } catch (const std::exception& e) {
    fail(e.what());
  }
  if (!workers.wait_until_all_left(kWorkerLeaveTimeout)) spdlog::debug("run: TBB workers still in the arena");
  finish_stream(arena, result, cpu_start_s);
  // The method's finish() may have run parallel work in the arena (SeqSLAM's search): wait for those workers
  // too, so that none leaves after the observer is gone. Its exit would never be counted, and every later run
  // in this process (compare, tests) would wait kWorkerLeaveTimeout above, inside its wall time.
  if (!workers.wait_until_all_left(kWorkerLeaveTimeout)) spdlog::debug("run: TBB workers still in the arena");
  return result;
}

// After the drain: the method's end-of-stream work (matcher flush, SeqSLAM's search) inside the arena, the
// held rows, the method's files, the summary.
void PipelineRun::finish_stream(tbb::task_arena& arena, RunResult& result, double cpu_start_s) {
  std::scoped_lock lock(stage_mutex_[kGate], stage_mutex_[kMatch], stage_mutex_[kSink]);
  const std::int64_t start_ns = clock_.now_ns();
  std::string aborted;
  std::atomic<std::int64_t> finish_parallel_ns{0};
  const std::int64_t cpu_start_ns = thread_cpu_ns();
  if (method_->detects()) {
    try {
      arena.execute([&] {
        const ParallelTimeScope parallel_time(&finish_parallel_ns);
        method_->finish();
      });
    } catch (const Interrupted& e) {
      // A second stop signal during the end-of-stream work (SeqSLAM's search): no detections from it; every
      // output is still written, and the run is interrupted, not failed.
      result.interrupted = true;
      aborted = std::string("end-of-stream work not done: ") + e.what();
      spdlog::warn("run: {}", aborted);
    } catch (const std::exception& e) {
      fail(std::string("match flush at the end of the stream: ") + e.what());
    }
  }
  // The method's end-of-stream work is matching (the matcher's flush, SeqSLAM's search) in the time
  // accounting; loops.csv and the loop closure below are the rest.
  const std::int64_t method_cpu_ns = thread_cpu_ns() - cpu_start_ns;
  if (method_->detects()) write_output("loops.csv", [&] { loops_.close(); });
  const std::int64_t closer_start_ns = clock_.now_ns();
  closer_.finish();  // the last loops' verification and the final pose-graph solve
  const double loop_closure_ms = 1e-6 * static_cast<double>(clock_.now_ns() - closer_start_ns);
  const double end_of_stream_ms = 1e-6 * static_cast<double>(clock_.now_ns() - start_ns);
  const EndOfStreamTime end_of_stream_time{
      1e-6 * static_cast<double>(method_cpu_ns), 1e-6 * static_cast<double>(finish_parallel_ns.load()),
      1e-6 * static_cast<double>(thread_cpu_ns() - cpu_start_ns - method_cpu_ns)};
  {
    std::lock_guard failure_lock(failure_mutex_);
    result.failed = failed_.load();
    result.error = failed_.load() ? failure_ : aborted;
  }
  // The end-of-stream work is part of the run (SeqSLAM's search happens there).
  result.wall_s = 1e-9 * static_cast<double>(clock_.now_ns());
  result.cpu_s = cpu_seconds() - cpu_start_s;
  result.peak_rss_mb = peak_rss_mb();
  for (std::string& error : outputs_.finish(true)) output_errors_.push_back(std::move(error));
  write_output("the method's files", [&] { method_->write_files(out_dir_); });
  if (closer_.active()) {
    write_output("loop_edges.csv", [&] { closer_.write_edges(out_dir_); });
    write_output("loops.csv's verification", [&] { closer_.annotate_loops(loops_); });
    write_output("trajectory_corrected.tum",
                 [&] { closer_.write_corrected(out_dir_, outputs_.tracked_poses()); });
  }
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
  RunParts parts{config_,          dataset_,     range_.first, range_.second,         *method_,
                 outputs_,         loops_,       images_,      steps_.synchronizer(), seqs_,
                 end_of_stream_ms, std::nullopt, &closer_,     end_of_stream_time};
  parts.truth_pairs = truth_pairs_ ? &*truth_pairs_ : nullptr;
  // The evaluation covers the frames the run got to: an interrupted run stops at the last frame presented, a
  // failed one at the last frame through the sink (issue 15: not the ground truth of frames never seen).
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
  write_output("the evaluation (ground_truth.tum, truth_loops.csv)",
               [&] { evaluation = evaluate_run(parts, out_dir_); });
  // A run that went through its frames and got nothing usable fails loudly (issue 14), outputs written.
  std::vector<std::string> problems;
  if (!result.failed && !result.interrupted) {
    problems = run_problems(run_check_input(config_, dataset_, outputs_.counters(),
                                            steps_.odometry_source().name(), method_->detects()));
    if (!problems.empty()) {
      result.failed = true;
      result.error = fmt::format("{}", fmt::join(problems, "; "));
    }
  }
  result.summary = make_run_summary(parts, result, std::move(evaluation));
  result.summary["problems"] = problems;
  result.track = {range_.first, range_.second, outputs_.tracked_frames(), outputs_.tracked_poses(),
                  loops_.loops()};
  if (config_.output.trace) {
    write_output("trace.json", [&] { outputs_.write_trace(out_dir_ / "trace.json", config_.run.threads); });
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
  // Files of the method and of the evaluation are named by their errors.
  for (const std::string& error : output_errors_) {
    const std::string what = error.substr(0, error.find(':'));
    if (std::find(expected.begin(), expected.end(), what) == expected.end()) missing.push_back(error);
  }
  return missing;
}

}  // namespace

RunResult run_pipeline(const PipelineConfig& config, const Dataset& dataset,
                       const std::filesystem::path& out_dir, const std::atomic<bool>* stop) {
  if (dataset.frame_count() == 0) throw DataError(dataset.root(), "dataset has no frames");
  require_poses_if_needed(config, dataset);
  refuse_outputs_over_inputs(config, out_dir);
  PipelineRun run(config, dataset, out_dir, stop);
  return run.run();
}

}  // namespace loopgate
