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
#include "parallel/parallel_handoff.hpp"
#include "pipeline/frame/frame_steps.hpp"
#include "pipeline/frame/run_clock.hpp"
#include "pipeline/graph/pipeline_run.hpp"
#include "pipeline/graph/run_checks.hpp"
#include "pipeline/graph/run_resources.hpp"
#include "pipeline/loops/loop_closer.hpp"
#include "pipeline/loops/loops_writer.hpp"
#include "pipeline/methods/detection_method.hpp"
#include "pipeline/odometry_factory.hpp"
#include "pipeline/outputs/run_outputs.hpp"
#include "pipeline/outputs/run_summary.hpp"

namespace loopgate {

namespace pipeline_internal {

void PipelineRun::produce(const std::function<void(FrameMsg)>& put) {
  std::uint64_t next_seq = 0;
  presented_end_ = range_.first;
  for (std::size_t frame = range_.first; frame < range_.second; ++frame) {
    const auto release = replay_.wait_for(frame, [this] { return stop_requested(); });
    if (!release) break;
    presented_end_ = frame + 1;
    if (!release->go) {  // dropped (rate mode)
      if (config_.output.trace) {
        outputs_.trace().add(TraceEvent{"dropped frame", "replay",
                                        1e-3 * static_cast<double>(clock_.now_ns()), 0, thread_index(), -1,
                                        static_cast<std::int64_t>(dataset_.source_index(frame)), 'i',
                                        "rate mode: the in-flight limit was reached"});
      }
      continue;
    }
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
    put(FrameMsg{record->seq, record});
  }
}

void PipelineRun::connect_gate_feedback() {
  const std::optional<int> delay = method_->verdict_delay_frames();
  if (!delay || !closer_.active()) {
    throw ConfigError("gate.feedback: run.method " + method_->name() + " (" + method_->mode() +
                      ") gives no verified loop while the stream runs: set gate.feedback=false");
  }
  // The rule (gate_feedback.hpp): frame i's gate uses the verified loops of query frames <= frame(i - L).
  const auto lag = static_cast<std::size_t>(config_.run.max_in_flight + *delay);
  feedback_.set_lag(lag);
  closer_.set_result_listener([this](const Detection& loop, const VerifyResult& result) {
    if (!result.verified) {
      feedback_.done(loop.query, nullptr);
      return;
    }
    FeedbackLoop verified;
    verified.query = loop.query;
    verified.reference = loop.reference;
    verified.T_r_q = result.T_j_i;
    verified.P_loop_r_m2 = result.cov.topLeftCorner<3, 3>();
    feedback_.done(loop.query, &verified);
  });
  outputs_.set_final_listener([this](std::size_t frame) { feedback_.final_through(frame); });
  feedback_on_ = true;
  spdlog::info(
      "gate.feedback: on: the gate of frame i is re-anchored through the latest loop verified among the "
      "query frames <= i - {} (run.max_in_flight {} + the method's verdict delay {} frames)",
      lag, config_.run.max_in_flight, *delay);
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
               enum_name(dataset_.layout()), config_.run.rate, threads, config_.run.max_in_flight);
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
      if (closer_.active() && r.usable_pose())
        closer_.record_pose(r.frame, r.odometry.pose.T_w_b, r.odometry.pose.position_sigma_m(),
                            r.odometry.step_cov);
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

  RunResult result;
  const double cpu_start_s = cpu_seconds();
  clock_.restart();
  produce([&queue](FrameMsg message) { queue->try_put(message); });
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
  const std::int64_t method_cpu_ns = thread_cpu_ns() - cpu_start_ns;
  if (config_.output.trace) trace_end_of_stream("end of stream: method (matcher flush, search)", start_ns);
  close_run(result, EndOfStreamWork{start_ns, method_cpu_ns, finish_parallel_ns.load(), cpu_start_ns,
                                    std::move(aborted), cpu_start_s});
}

}  // namespace pipeline_internal

RunResult run_pipeline(const PipelineConfig& config, const Dataset& dataset,
                       const std::filesystem::path& out_dir, const std::atomic<bool>* stop,
                       bool keep_step_cov) {
  if (dataset.frame_count() == 0) throw DataError(dataset.root(), "dataset has no frames");
  require_poses_if_needed(config, dataset);
  refuse_outputs_over_inputs(config, out_dir);
  pipeline_internal::PipelineRun run(config, dataset, out_dir, stop, keep_step_cov);
  return run.run();
}

}  // namespace loopgate
