// The run of `loopgate run` over one dataset (pipeline.hpp): its objects and the node bodies, shared by the
// graph's wiring (pipeline.cpp, the one source that includes the flow graph) and the end of the stream
// (pipeline_finish.cpp). Internal to the pipeline.
#pragma once

#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>
#include <tbb/task_arena.h>

#include <array>
#include <atomic>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <unordered_map>

#include "io/dataset.hpp"
#include "parallel/parallel_handoff.hpp"
#include "pipeline/frame/frame_steps.hpp"
#include "pipeline/frame/gate_feedback.hpp"
#include "pipeline/frame/run_clock.hpp"
#include "pipeline/graph/run_resources.hpp"
#include "pipeline/loops/loop_closer.hpp"
#include "pipeline/loops/loops_writer.hpp"
#include "pipeline/methods/detection_method.hpp"
#include "pipeline/odometry_factory.hpp"
#include "pipeline/outputs/run_outputs.hpp"
#include "pipeline/outputs/run_result.hpp"
#include "pipeline/outputs/run_summary.hpp"
#include "pipeline/outputs/time_accounting.hpp"

namespace loopgate::pipeline_internal {

// What the method's end-of-stream work measured, for close_run().
struct EndOfStreamWork {
  std::int64_t start_ns = 0;  // run clock, when the end of the stream began
  std::int64_t method_cpu_ns = 0;
  std::int64_t finish_parallel_ns = 0;
  std::int64_t cpu_start_ns = 0;  // thread CPU time when the end of the stream began
  std::string aborted;            // why the end-of-stream work was not done (a second stop signal)
  double cpu_start_s = 0;         // process CPU time at the start of the run
};

// One run: the objects that do the work (frame steps, detection method, outputs, replay clock), built from
// the configuration, and the graph that wires them. Each node body is one call on one of them.
class PipelineRun {
 public:
  PipelineRun(const PipelineConfig& config, const Dataset& dataset, const std::filesystem::path& out_dir,
              const std::atomic<bool>* stop, bool keep_step_cov)
      : config_(config),
        dataset_(dataset),
        out_dir_(out_dir),
        stop_(stop),
        range_(config.run.frame_range(dataset.frame_count())),
        truth_pairs_(load_truth_pairs(config.eval, dataset)),
        seqs_(range_.second - range_.first),
        images_(dataset, seqs_),
        method_(make_detection_method({config, seqs_, images_, loops_, seqs_.capacity(),
                                       feedback_wanted(config) ? &feedback_ : nullptr},
                                      dataset.has_images(), dataset.root())),
        closer_(config, dataset, range_.first, range_.second, method_->detects()),
        steps_(config, dataset, make_odometry_source(config.odometry, config.ekf, dataset), images_,
               method_->needs_every_image()),
        outputs_(config, out_dir, *method_, seqs_, clock_, steps_.odometry_source().needs_images(),
                 seqs_.capacity(), &closer_, keep_step_cov),
        replay_(config.run, dataset, range_.first, clock_) {
    if (feedback_wanted(config)) {
      connect_gate_feedback();
    } else if (config.gate.feedback) {
      spdlog::info("gate.feedback: no effect: run.mode {} has no pose gate", enum_name(config.run.mode));
    }
    if (closer_.active()) {
      loops_.set_listener([this](const Detection& loop) {
        if (feedback_on_) feedback_.submitted(loop.query);  // before the closer can finish it
        closer_.submit(loop);
      });
    }
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
  // gate.feedback acts: a gated run (the config refuses it without verify.enabled and with SeqSLAM).
  static bool feedback_wanted(const PipelineConfig& config) {
    return config.gate.feedback && config.verify.enabled && config.run.mode == RunMode::kGated;
  }
  // gate.feedback: the lag L, the closer's results and the sink's final verdicts into feedback_.
  void connect_gate_feedback();
  void produce(const std::function<void(FrameMsg)>& put);  // the producer: replay clock, frame records
  std::vector<std::string> missing_outputs() const;
  // After the drain: the method's end-of-stream work in the arena (pipeline.cpp), then close_run().
  void finish_stream(tbb::task_arena& arena, RunResult& result, double cpu_start_s);
  // The rest of the end of the stream (pipeline_finish.cpp): loops.csv, the loop closer's last work, the
  // result's counters and profile, the method's files, the evaluation, the checks, trace.json and
  // summary.json.
  void close_run(RunResult& result, const EndOfStreamWork& work);
  // The steps of close_run(), in order.
  void fill_counts(RunResult& result, double loop_closure_ms) const;
  std::vector<std::string> check_run(RunResult& result) const;
  void add_loop_oracle(RunResult& result,
                       const std::vector<std::pair<std::size_t, std::size_t>>& truth_loops);
  void write_trace_and_summary(RunResult& result);
  // A span of the end-of-stream work on the producer's track of trace.json (output.trace), from start_ns to
  // end_ns (-1: now).
  void trace_end_of_stream(const char* name, std::int64_t start_ns, std::int64_t end_ns = -1);
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
  GateFeedback feedback_;     // gate.feedback: verified loops to the gate (gate_feedback.hpp)
  bool feedback_on_ = false;  // set by the constructor, before the run
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

}  // namespace loopgate::pipeline_internal
