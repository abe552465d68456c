#include "pipeline/pipeline.hpp"

#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>
#include <sys/resource.h>
#include <tbb/flow_graph.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>
#include <tbb/task_scheduler_observer.h>
#include <unistd.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <deque>
#include <limits>
#include <map>
#include <mutex>
#include <opencv2/core/mat.hpp>
#include <thread>
#include <unordered_map>

#include "core/error.hpp"
#include "eval/ground_truth.hpp"
#include "eval/precision_recall.hpp"
#include "io/config.hpp"
#include "io/dataset.hpp"
#include "io/writers.hpp"
#include "pipeline/descriptor_store.hpp"
#include "pipeline/odometry_factory.hpp"
#include "pipeline/parallel_handoff.hpp"
#include "pipeline/run_metrics.hpp"
#include "pipeline/seqslam_batch.hpp"
#include "pipeline/stage_profiler.hpp"
#include "stages/dird/dird_extractor.hpp"
#include "stages/dird/dird_similarity.hpp"
#include "stages/gate/candidate_areas.hpp"
#include "stages/gate/pose_gate.hpp"
#include "stages/match/sequence_matcher.hpp"

namespace loopgate {

namespace {

using Clock = std::chrono::steady_clock;

enum Stage : std::size_t { kSync, kDecode, kOdometry, kGate, kDescribe, kMatch, kSink, kStageCount };
constexpr std::array<const char*, kStageCount> kStageNames = {"sync",     "decode", "odometry", "gate",
                                                              "describe", "match",  "sink"};
constexpr std::size_t kMaxMessagesPerFrame = 4;  // per-frame reasons kept in frames.csv
constexpr std::size_t kMaxListedProblems = 200;  // frames / dataset issues listed in summary.json
constexpr double kProgressPeriodS = 0.25;
constexpr auto kWorkerLeaveTimeout = std::chrono::milliseconds(2000);
constexpr auto kPollPeriod = std::chrono::milliseconds(20);  // producer: stop-flag polling while waiting

// Small stable index per thread, for the trace tracks.
int thread_index() {
  static std::atomic<int> next{0};
  thread_local const int index = next.fetch_add(1);
  return index;
}

double cpu_seconds() {
  rusage usage{};
  ::getrusage(RUSAGE_SELF, &usage);
  const auto seconds = [](const timeval& tv) {
    return static_cast<double>(tv.tv_sec) + 1e-6 * static_cast<double>(tv.tv_usec);
  };
  return seconds(usage.ru_utime) + seconds(usage.ru_stime);
}

double peak_rss_mb() {
  rusage usage{};
  ::getrusage(RUSAGE_SELF, &usage);
  return static_cast<double>(usage.ru_maxrss) / 1024.0;  // ru_maxrss is in KiB on Linux
}

struct StageStamp {
  std::int64_t enter_ns = 0;
  std::int64_t exit_ns = 0;
  int thread = -1;
};

struct FrameRecord {
  std::uint64_t seq = 0;
  std::size_t frame = 0;
  Timestamp t_ns = 0;
  std::int64_t release_ns = 0;
  std::int64_t deadline_ns = 0;  // 0: no deadline (rate max)
  SyncedImu imu;
  bool imu_synced = false;
  bool needs_pixels = false;
  bool decoded = false;
  cv::Mat image;
  OdometryOutput odometry;
  bool has_pose = false;
  bool described = false;                   // DIRD descriptor computed for this frame
  std::vector<SimilarityEntry> similarity;  // S(., seq): describe fills j <= seq - K, match the rest
  std::size_t similarities_computed = 0;    // descriptor comparisons made for this frame
  // gated mode: the gate's decision, the area the frame joined (-1: none), the frames (seqs) whose
  // descriptors this frame's describe computes, and the cells its match computes.
  bool gate_ran = false;
  GateDecision gate;
  int area_id = -1;
  std::vector<std::int64_t> describe_seqs;
  std::vector<CellSpan> new_cells;
  std::vector<std::string> warnings;
  std::vector<std::string> errors;
  std::array<StageStamp, kStageCount> stamps{};

  // The hand-over between nodes goes through TBB's scheduler, whose synchronisation ThreadSanitizer
  // cannot see (uninstrumented library); each node body starts with acquire() and ends with release()
  // so that the happens-before edge is explicit.
  mutable std::atomic<int> handoff{0};
  void acquire() const { static_cast<void>(handoff.load(std::memory_order_acquire)); }
  void release() const { handoff.fetch_add(1, std::memory_order_release); }
};
// Messages carry the sequence number by value (the sequencers read it without touching the record)
// and a pointer to the record, owned by PipelineRun::live_: created by the producer, destroyed by the
// sink once the frame is written; whatever a failed run leaves is freed at the end.
struct FrameMsg {
  std::uint64_t seq = 0;
  FrameRecord* record = nullptr;
};
using FramePtr = FrameMsg;

void add_message(std::vector<std::string>& list, std::string message) {
  list.push_back(std::move(message));
}

std::string join_messages(const std::vector<std::string>& messages) {
  std::string out;
  const std::size_t shown = std::min(messages.size(), kMaxMessagesPerFrame);
  for (std::size_t i = 0; i < shown; ++i) out += (i ? "; " : "") + messages[i];
  if (messages.size() > shown) out += fmt::format("; ... {} more", messages.size() - shown);
  return out;
}

// Counts the worker threads inside the arena. When the graph is drained, the run waits until every
// worker has left before tearing the graph down: the acquire of the last exit orders everything the
// workers did before the teardown, visibly for ThreadSanitizer too (TBB's own synchronisation lives in an
// uninstrumented library).
// Constant-initialised (no run-time write that a worker could race with); shared by concurrent runs,
// which then only wait for each other's workers too.
std::atomic<int> g_workers_inside{0};

class WorkerExitObserver : public tbb::task_scheduler_observer {
 public:
  explicit WorkerExitObserver(tbb::task_arena& arena) : tbb::task_scheduler_observer(arena) { observe(true); }
  ~WorkerExitObserver() override { observe(false); }
  void on_scheduler_entry(bool is_worker) override {
    if (is_worker) g_workers_inside.fetch_add(1, std::memory_order_acq_rel);
  }
  void on_scheduler_exit(bool is_worker) override {
    if (is_worker) g_workers_inside.fetch_sub(1, std::memory_order_acq_rel);
  }
  bool wait_until_all_left(std::chrono::milliseconds timeout) const {
    const auto deadline = Clock::now() + timeout;
    while (g_workers_inside.load(std::memory_order_acquire) > 0) {
      if (Clock::now() > deadline) return false;
      std::this_thread::sleep_for(std::chrono::microseconds(200));
    }
    return true;
  }
};

class PipelineRun {
 public:
  PipelineRun(const PipelineConfig& config, const Dataset& dataset, const std::filesystem::path& out_dir,
              const std::atomic<bool>* stop)
      : config_(config),
        dataset_(dataset),
        out_dir_(out_dir),
        stop_(stop),
        rate_(config.run.rate_factor()),
        profiler_({kStageNames.begin(), kStageNames.end()}) {
    std::tie(first_frame_, last_frame_) = config_.run.frame_range(dataset_.frame_count());
    decode_all_ = config_.run.decode == "all";
    if (decode_all_ && !dataset_.has_images()) {
      spdlog::warn("run.decode is 'all' but dataset {} has no images: nothing to decode",
                   dataset_.root().string());
      decode_all_ = false;
    }
    if (dataset_.has_imu())
      synchronizer_ = std::make_unique<ImuSynchronizer>(dataset_.imu_samples(), config_.sync);
    odometry_ = make_odometry_source(config_.odometry, config_.ekf, dataset_);
    seqslam_ = config_.run.seqslam();
    full_ = config_.run.mode == "full" && !seqslam_;
    gated_ = config_.run.mode == "gated" && !seqslam_;
    const std::size_t capacity = last_frame_ - first_frame_;
    seq_frame_.resize(capacity);
    seq_t_ns_.resize(capacity);
    if (seqslam_) {
      if (!dataset_.has_images()) {
        throw DataError(dataset_.root(), "run.method seqslam needs images, and this dataset has none");
      }
      seqslam_batch_ = std::make_unique<SeqSlamBatch>(config_.seqslam, capacity);
      seqslam_described_.assign(capacity, 0);
      spdlog::info(
          "run: SeqSLAM on every frame (run.mode {} does not apply to it); matches at the end of the stream",
          config_.run.mode);
    }
    if (full_ || gated_) {
      if (!dataset_.has_images()) {
        throw DataError(dataset_.root(),
                        "run.mode " + config_.run.mode +
                            " needs images, and this dataset has none (use --mode odometry)");
      }
      extractor_ = std::make_unique<DirdExtractor>(config_.dird);
      similarity_ = std::make_unique<DirdSimilarity>(config_.dird);
      store_ = std::make_unique<DescriptorStore>(capacity);
      matcher_ = std::make_unique<SequenceMatcher>(config_.match, SequenceMatcher::Mode::kSingleSequence, 0);
    }
    if (gated_) {
      pose_gate_ = std::make_unique<PoseGate>(config_.gate, "odometry (gate)");
      tracker_ = std::make_unique<CandidateAreaTracker>(config_.gate, config_.match.sequence_length,
                                                        config_.match.margin);
      row_cells_.assign(capacity, 0);
    }
    if (full_) {
      if (config_.run.max_in_flight > config_.match.margin) {
        spdlog::info(
            "run: match.margin {} < run.max_in_flight {}: the similarities against the last {} frames "
            "before the margin are computed in the (serial) match node",
            config_.match.margin, config_.run.max_in_flight,
            config_.run.max_in_flight - config_.match.margin);
      }
    }
    const std::string progress = config_.output.progress;
    show_progress_ = progress == "on" || (progress == "auto" && ::isatty(STDERR_FILENO));
  }

  RunResult run();

 private:
  std::int64_t now_ns() const {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - start_).count();
  }

  template <class Body>
  auto node_body(Stage stage, Body body) {
    return [this, stage, body](FramePtr message) -> FramePtr {
      FrameRecord& r = *message.record;
      r.acquire();
      r.stamps[stage].enter_ns = now_ns();
      r.stamps[stage].thread = thread_index();
      try {
        body(r);
      } catch (const std::exception& e) {
        record_failure(stage, r, e.what());
        r.release();
        throw;
      }
      r.stamps[stage].exit_ns = now_ns();
      r.release();
      return message;
    };
  }

  void stage_sync(FrameRecord& r);
  void stage_decode(FrameRecord& r);
  void stage_odometry(FrameRecord& r);
  void stage_gate(FrameRecord& r);
  void stage_describe(FrameRecord& r);
  void describe_requested(FrameRecord& r);
  void push_final_rows(std::size_t end_seq, MatchOutput& output);  // gated: rows [next_push_seq_, end_seq)
  void stage_match(FrameRecord& r);
  void stage_sink(FrameRecord& r);
  // Appends to `out` the similarities of frame `seq` against the earlier frames [j_begin, j_end) of the
  // store (each must be published), skipping frames without a descriptor; returns the comparisons made.
  std::size_t similarity_range(std::size_t seq, std::size_t j_begin, std::size_t j_end,
                               std::vector<SimilarityEntry>& out) const;
  void handle_match_output(MatchOutput& output);  // match node or, after the drain, run()
  void write_finished_rows(bool end_of_stream);   // sink or, after the drain, run()
  std::vector<std::string> detection_cells(const FrameMatchStatus& status, std::size_t seq) const;
  void write_area_files();          // gated: candidate_areas.csv and candidate_cells.csv
  nlohmann::json evaluate_loops();  // with ground truth: loop_truth, precision_recall, gate coverage
  void record_failure(std::size_t stage, const FrameRecord& r, const std::string& what);
  void produce(tbb::flow::queue_node<FramePtr>& queue, RunResult& result);
  void open_outputs();
  void show_progress(bool final);
  nlohmann::json make_summary(const RunResult& result);

  const PipelineConfig& config_;
  const Dataset& dataset_;
  std::filesystem::path out_dir_;
  const std::atomic<bool>* stop_;
  std::optional<double> rate_;
  std::size_t first_frame_ = 0;
  std::size_t last_frame_ = 0;
  bool decode_all_ = false;
  bool show_progress_ = false;
  Clock::time_point start_ = Clock::now();

  // sync node state
  std::mutex sync_mutex_;
  std::unique_ptr<ImuSynchronizer> synchronizer_;
  bool have_last_sync_t_ = false;
  Timestamp last_sync_t_ns_ = 0;

  // odometry node state
  std::mutex odometry_mutex_;
  std::unique_ptr<OdometrySource> odometry_;

  // seq -> dataset frame and time, written by the producer before the frame is released (preallocated)
  std::vector<std::size_t> seq_frame_;
  std::vector<Timestamp> seq_t_ns_;
  std::size_t frame_of(std::int64_t seq) const { return seq_frame_.at(static_cast<std::size_t>(seq)); }

  // gated mode: gate node state (serial)
  bool gated_ = false;
  std::mutex gate_mutex_;
  std::unique_ptr<PoseGate> pose_gate_;
  std::unique_ptr<CandidateAreaTracker> tracker_;
  std::size_t frames_gate_ran_ = 0, frames_gated_ = 0, gate_errors_ = 0;
  std::vector<std::pair<std::int64_t, std::int64_t>> describe_requests_;  // (seq described, requesting seq)
  // match node state: similarity rows still open to new cells, cells per row, next row for the matcher
  std::map<std::int64_t, std::vector<SimilarityEntry>> open_rows_;
  std::vector<std::uint32_t> row_cells_;
  std::size_t next_push_seq_ = 0, match_end_seq_ = 0;
  std::atomic<std::size_t> images_read_for_description_{0};
  // Recently decoded images (gated mode, run.image_cache_frames): (seq, image), oldest first.
  std::mutex image_cache_mutex_;
  std::deque<std::pair<std::size_t, cv::Mat>> image_cache_;
  std::atomic<std::size_t> image_cache_hits_{0};
  void cache_image(std::size_t seq, const cv::Mat& image);
  cv::Mat cached_image(std::size_t seq);

  // seqslam method: describe preprocesses every frame; the search runs at the end of the stream
  bool seqslam_ = false;
  std::unique_ptr<SeqSlamBatch> seqslam_batch_;
  std::vector<std::uint8_t> seqslam_described_;  // per seq, written once by describe, read after the drain
  double end_of_stream_ms_ = 0;                  // matcher flush / SeqSLAM batch after the last frame
  void finish_seqslam(tbb::task_arena& arena);
  bool detects() const { return full_ || gated_ || seqslam_; }

  // full and gated mode: describe (parallel; stateless extractor, store entries written once per seq)
  // and match
  bool full_ = false;
  std::unique_ptr<DirdExtractor> extractor_;
  std::unique_ptr<DirdSimilarity> similarity_;
  std::unique_ptr<DescriptorStore> store_;
  std::atomic<std::size_t> descriptors_computed_{0};
  std::atomic<std::size_t> similarities_computed_{0};
  std::mutex match_mutex_;  // match node state
  std::unique_ptr<SequenceMatcher> matcher_;
  CsvWriter loops_csv_;
  std::size_t loops_ = 0;
  std::vector<Detection> detections_;          // every loop closure, dataset frame indices (evaluation)
  std::vector<Detection> seqslam_candidates_;  // SeqSLAM: every query's match, accepted or not
  std::array<std::size_t, 4> outcome_counts_{};
  // frame statuses finalised by the matcher (NMS delay), waiting for their frames.csv row
  std::mutex finished_mutex_;
  std::deque<FrameMatchStatus> finished_statuses_;

  // sink node state (everything below is touched by the sink only, and by run() after the drain)
  std::mutex sink_mutex_;
  CsvWriter frames_csv_;
  CsvWriter timing_csv_;
  TumWriter trajectory_;
  std::vector<StampedPose> tracked_poses_;  // odometry poses with status tracking (ATE in summary.json)
  TraceWriter trace_;
  StageProfiler profiler_;
  std::uint64_t next_sink_seq_ = 0;
  std::size_t processed_ = 0, frames_ok_ = 0, frames_warning_ = 0, frames_error_ = 0;
  std::size_t deadline_misses_ = 0, decoded_ = 0, odometry_lost_ = 0, image_errors_ = 0;
  std::size_t imu_gaps_ = 0, imu_out_of_order_ = 0, imu_duplicates_ = 0, imu_missing_frames_ = 0;
  bool have_first_t_ = false;
  Timestamp first_t_ns_ = 0, last_t_ns_ = 0;
  nlohmann::json problem_frames_ = nlohmann::json::array();
  std::size_t problem_frame_count_ = 0;
  std::int64_t last_progress_ns_ = 0;
  struct PendingRow {  // full/gated mode: a frames.csv row waiting for its detection status
    std::size_t seq = 0;
    std::vector<std::string> cells;
  };
  std::deque<PendingRow> pending_rows_;

  // frames inside the graph, by seq
  std::mutex live_mutex_;
  std::unordered_map<std::uint64_t, std::unique_ptr<FrameRecord>> live_;

  // shared between the producer and the sink
  std::mutex flight_mutex_;
  std::condition_variable flight_cv_;
  int in_flight_ = 0;

  // failure (first one wins)
  std::mutex failure_mutex_;
  std::atomic<bool> failed_{false};
  std::string failure_;
};

void PipelineRun::record_failure(std::size_t stage, const FrameRecord& r, const std::string& what) {
  {
    std::lock_guard lock(failure_mutex_);
    if (!failed_.load()) {
      failure_ = fmt::format("stage '{}' failed on seq {} (frame {}, t = {:.6f} s): {}", kStageNames[stage],
                             r.seq, r.frame, ns_to_s(r.t_ns), what);
      failed_.store(true);
    }
  }
  flight_cv_.notify_all();
}

void PipelineRun::stage_sync(FrameRecord& r) {
  std::lock_guard lock(sync_mutex_);
  // Lazy decode: pixels are needed now by a visual odometry source, and in full mode by describe (gated
  // mode: describe reads the images the candidate areas need itself, current frame included).
  r.needs_pixels = decode_all_ || odometry_->needs_images() || full_ || seqslam_;
  if (!synchronizer_) return;
  if (have_last_sync_t_ && r.t_ns <= last_sync_t_ns_) {
    add_message(r.errors,
                fmt::format("frame time {:.6f} s does not increase: IMU not synced", ns_to_s(r.t_ns)));
    return;
  }
  have_last_sync_t_ = true;
  last_sync_t_ns_ = r.t_ns;
  r.imu = synchronizer_->next(r.t_ns);
  r.imu_synced = true;
  for (const auto& message : r.imu.report.messages) add_message(r.warnings, message);
}

void PipelineRun::cache_image(std::size_t seq, const cv::Mat& image) {
  const auto capacity = static_cast<std::size_t>(config_.run.image_cache_frames);
  if (!gated_ || capacity == 0) return;
  std::lock_guard lock(image_cache_mutex_);
  image_cache_.emplace_back(seq, image);  // shares the pixels (reference counted)
  while (image_cache_.size() > capacity) image_cache_.pop_front();
}

cv::Mat PipelineRun::cached_image(std::size_t seq) {
  std::lock_guard lock(image_cache_mutex_);
  for (const auto& [cached_seq, image] : image_cache_) {
    if (cached_seq == seq) return image;
  }
  return {};
}

void PipelineRun::stage_decode(FrameRecord& r) {
  if (!r.needs_pixels) return;
  try {
    r.image = dataset_.load_image(r.frame);
    r.decoded = true;
    cache_image(static_cast<std::size_t>(r.seq), r.image);
  } catch (const DataError& e) {
    add_message(r.errors, std::string("image: ") + e.what());
  }
}

void PipelineRun::stage_odometry(FrameRecord& r) {
  std::lock_guard lock(odometry_mutex_);
  OdometryInput input;
  input.frame = r.frame;
  input.t_ns = r.t_ns;
  if (odometry_->needs_ground_truth()) input.T_w_b_true = dataset_.ground_truth_T_w_b(r.frame);
  input.imu = r.imu_synced ? &r.imu.samples : nullptr;
  input.image = r.decoded ? &r.image : nullptr;
  try {
    r.odometry = odometry_->process(input);
    r.has_pose = true;
  } catch (const DataError& e) {
    add_message(r.errors, std::string("odometry: ") + e.what());
    return;
  }
  if (r.odometry.pose.status != OdometryStatus::kTracking) {
    add_message(r.warnings, fmt::format("odometry {}{}{}", to_string(r.odometry.pose.status),
                                        r.odometry.reason.empty() ? "" : ": ", r.odometry.reason));
  }
}

std::size_t PipelineRun::similarity_range(std::size_t seq, std::size_t j_begin, std::size_t j_end,
                                          std::vector<SimilarityEntry>& out) const {
  if (j_begin >= j_end) return 0;
  bool any_missing = false;
  for (std::size_t j = j_begin; j < j_end; ++j) {
    const auto state = store_->state(j);
    if (state == DescriptorStore::State::kEmpty) {
      throw std::logic_error(fmt::format("similarity of seq {}: earlier seq {} not described yet", seq, j));
    }
    any_missing = any_missing || state == DescriptorStore::State::kNoDescriptor;
  }
  const std::size_t first_new = out.size();
  similarity_->sparse_row(store_->descriptor(seq), store_->data() + j_begin, j_end - j_begin,
                          static_cast<std::int64_t>(j_begin), out);
  if (any_missing) {
    const auto is_missing = [this](const SimilarityEntry& e) {
      return store_->state(static_cast<std::size_t>(e.j)) != DescriptorStore::State::kValid;
    };
    out.erase(std::remove_if(out.begin() + static_cast<std::ptrdiff_t>(first_new), out.end(), is_missing),
              out.end());
    std::size_t compared = 0;
    for (std::size_t j = j_begin; j < j_end; ++j)
      compared += store_->state(j) == DescriptorStore::State::kValid ? 1 : 0;
    return compared;
  }
  return j_end - j_begin;
}

// gate (serial, in order; gated mode): the pose gate's decision for this frame (frames without a usable
// pose are not gated and not stored) and the candidate-area update: the cells that became covered and the
// frames that newly need a descriptor. All indices are sequence numbers.
void PipelineRun::stage_gate(FrameRecord& r) {
  if (!gated_) return;
  std::lock_guard lock(gate_mutex_);
  const auto seq = static_cast<std::int64_t>(r.seq);
  GateDecision decision;
  decision.frame = seq;
  if (r.has_pose && r.odometry.pose.status != OdometryStatus::kLost) {
    try {
      decision = pose_gate_->process(seq, r.odometry.pose);
      r.gate_ran = true;
      ++frames_gate_ran_;
      if (decision.gated) ++frames_gated_;
    } catch (const DataError& e) {
      add_message(r.warnings, std::string("gate: pose not usable: ") + e.what());
      ++gate_errors_;
      decision = GateDecision{};
      decision.frame = seq;
    }
  }
  r.gate = decision;
  AreaUpdate update = tracker_->update(decision);
  r.area_id = update.joined_area;
  r.new_cells = std::move(update.new_cells);
  r.describe_seqs = std::move(update.new_descriptor_frames);
  for (const std::int64_t k : r.describe_seqs) describe_requests_.emplace_back(k, seq);
}

// describe, gated mode: the descriptors the gate asked for, each computed once: the current frame's from
// its decoded image when decode already has it, every other (past, or this frame's when not decoded) read
// again through the dataset's random access. Several requests are described in parallel.
void PipelineRun::describe_requested(FrameRecord& r) {
  const std::vector<std::int64_t>& seqs = r.describe_seqs;
  std::vector<std::string> problems(seqs.size());
  const auto describe_one = [&](std::size_t index) {
    const auto k = static_cast<std::size_t>(seqs[index]);
    const std::size_t frame = seq_frame_[k];
    cv::Mat image;
    bool ok = false;
    if (k == r.seq && r.decoded) {
      image = r.image;
      ok = true;
    } else if (image = cached_image(k); !image.empty()) {
      image_cache_hits_.fetch_add(1, std::memory_order_relaxed);
      ok = true;
    } else {
      try {
        image = dataset_.load_image(frame);
        images_read_for_description_.fetch_add(1, std::memory_order_relaxed);
        ok = true;
      } catch (const DataError& e) {
        problems[index] = fmt::format("describe: frame {} could not be read: {}", frame, e.what());
      }
    }
    if (ok) {
      extractor_->extract(image, store_->slot(k));
      descriptors_computed_.fetch_add(1, std::memory_order_relaxed);
    }
    store_->publish(k, ok);
  };
  if (seqs.size() > 1) {
    parallel_for_with_handoff(seqs.size(), describe_one);
  } else if (seqs.size() == 1) {
    describe_one(0);
  }
  for (auto& problem : problems) {
    if (!problem.empty()) add_message(r.warnings, std::move(problem));
  }
}

// describe (parallel): the frame's DIRD descriptor, and its similarities against the earlier frames
// that are certainly through the graph: the producer releases seq i only when at most K - 1 frames are
// in flight, and the sink retires frames in order, so every seq <= i - K has left the sink (and
// describe). The rest of the row (i - K < j <= i - margin, only when margin < K) is done by match,
// after the sequencer. Either way the row is the same set of pairs whatever the thread timing.
void PipelineRun::stage_describe(FrameRecord& r) {
  if (seqslam_) {
    const auto seq = static_cast<std::size_t>(r.seq);
    if (r.decoded) {
      try {
        seqslam_batch_->add(seq, r.image);
        r.described = true;
        seqslam_described_[seq] = 1;
        descriptors_computed_.fetch_add(1, std::memory_order_relaxed);
      } catch (const std::invalid_argument& e) {
        add_message(r.errors, std::string("seqslam preprocessing: ") + e.what());
      }
    }
    if (!r.described) seqslam_batch_->add_missing(seq);
    return;
  }
  if (gated_) {
    describe_requested(r);
    return;
  }
  if (!full_) return;
  const std::size_t seq = static_cast<std::size_t>(r.seq);
  if (r.decoded) {
    extractor_->extract(r.image, store_->slot(seq));
    r.described = true;
    descriptors_computed_.fetch_add(1, std::memory_order_relaxed);
  }
  store_->publish(seq, r.described);
  if (!r.described) return;
  const std::size_t margin = static_cast<std::size_t>(config_.match.margin);
  const std::size_t limit = std::max(margin, static_cast<std::size_t>(config_.run.max_in_flight));
  if (seq >= limit) {
    r.similarities_computed += similarity_range(seq, 0, seq - limit + 1, r.similarity);
  }
}

// match (serial, in order): completes the similarity row, feeds the streaming sequence matcher and
// writes the loop closures that became final (NMS delay 2 W frames).
void PipelineRun::stage_match(FrameRecord& r) {
  if (gated_) {
    // The similarities of the cells this frame's gate update covered (every descriptor they need was
    // requested at this frame or earlier, so it has passed describe), into rows still open; rows older
    // than the gate's horizon are final and go to the matcher.
    std::lock_guard lock(match_mutex_);
    for (const CellSpan& span : r.new_cells) {
      if (static_cast<std::size_t>(span.i) < next_push_seq_) {
        throw std::logic_error(fmt::format("cells for row {} after it went to the matcher", span.i));
      }
      row_cells_[static_cast<std::size_t>(span.i)] += static_cast<std::uint32_t>(span.j1 - span.j0 + 1);
      if (store_->state(static_cast<std::size_t>(span.i)) != DescriptorStore::State::kValid) continue;
      r.similarities_computed +=
          similarity_range(static_cast<std::size_t>(span.i), static_cast<std::size_t>(span.j0),
                           static_cast<std::size_t>(span.j1) + 1, open_rows_[span.i]);
    }
    similarities_computed_.fetch_add(r.similarities_computed, std::memory_order_relaxed);
    match_end_seq_ = r.seq + 1;
    const auto horizon = static_cast<std::size_t>(config_.gate.row_horizon_frames);
    MatchOutput output;
    if (r.seq >= horizon) push_final_rows(r.seq - horizon + 1, output);
    handle_match_output(output);
    return;
  }
  if (!full_) return;
  std::lock_guard lock(match_mutex_);
  const std::size_t seq = static_cast<std::size_t>(r.seq);
  const std::size_t margin = static_cast<std::size_t>(config_.match.margin);
  const std::size_t in_flight = static_cast<std::size_t>(config_.run.max_in_flight);
  if (r.described && margin < in_flight && seq >= margin) {
    const std::size_t j_begin = seq + 1 >= in_flight ? seq + 1 - in_flight : 0;
    r.similarities_computed += similarity_range(seq, j_begin, seq - margin + 1, r.similarity);
  }
  similarities_computed_.fetch_add(r.similarities_computed, std::memory_order_relaxed);
  MatchOutput output;
  matcher_->push(static_cast<std::int64_t>(seq), r.similarity, output);
  r.similarity.clear();
  r.similarity.shrink_to_fit();
  handle_match_output(output);
}

// Pushes rows [next_push_seq_, end_seq) to the matcher, in order (rows without cells pushed empty).
void PipelineRun::push_final_rows(std::size_t end_seq, MatchOutput& output) {
  for (; next_push_seq_ < end_seq; ++next_push_seq_) {
    const auto i = static_cast<std::int64_t>(next_push_seq_);
    const auto it = open_rows_.find(i);
    if (it == open_rows_.end()) {
      matcher_->push(i, {}, output);
    } else {
      matcher_->push(i, it->second, output);
      open_rows_.erase(it);
    }
  }
}

void PipelineRun::handle_match_output(MatchOutput& output) {
  for (const LoopClosure& loop : output.loops) {
    const std::size_t frame_i = frame_of(loop.i), frame_j = frame_of(loop.j);
    loops_csv_.write_row({std::to_string(frame_i), std::to_string(frame_j),
                          format_fixed(ns_to_s(seq_t_ns_[static_cast<std::size_t>(loop.i)]), 9),
                          format_fixed(ns_to_s(seq_t_ns_[static_cast<std::size_t>(loop.j)]), 9),
                          format_fixed(loop.score, 6)});
    ++loops_;
    detections_.push_back(Detection{frame_i, frame_j, loop.score});
  }
  if (!output.loops.empty()) loops_csv_.flush();
  if (output.frames.empty()) return;
  std::lock_guard lock(finished_mutex_);
  for (const FrameMatchStatus& status : output.frames) finished_statuses_.push_back(status);
}

std::vector<std::string> PipelineRun::detection_cells(const FrameMatchStatus& status, std::size_t seq) const {
  std::string reason;
  const double threshold = config_.match.dp_threshold();
  const bool described = store_->state(seq) == DescriptorStore::State::kValid;
  switch (status.outcome) {
    case FrameOutcome::kNoCandidate:
      if (gated_ && row_cells_[seq] == 0) {
        reason = "outside every candidate area";
      } else if (!described) {
        reason = "no descriptor (image not decoded)";
      } else if (seq < static_cast<std::size_t>(config_.match.margin)) {
        reason = fmt::format("no earlier frame beyond the margin of {}", config_.match.margin);
      } else {
        reason = fmt::format("no similarity above tau1 = {}", config_.dird.tau1);
      }
      break;
    case FrameOutcome::kBelowThreshold:
      reason = fmt::format("{} candidates, best similarity {:.4f}; best DP {:.4f} <= {:.4f}",
                           status.candidates, status.best_similarity, status.best_score, threshold);
      break;
    case FrameOutcome::kSuppressed:
      reason =
          fmt::format("{} DP values above {:.4f}, all suppressed by NMS", status.above_threshold, threshold);
      break;
    case FrameOutcome::kLoop:
      reason = fmt::format("{} loop closure(s) of {} DP values above {:.4f}", status.loops,
                           status.above_threshold, threshold);
      break;
  }
  const bool has_best = status.best_j >= 0;
  return {described ? "y" : "n", to_string(status.outcome),
          has_best ? std::to_string(frame_of(status.best_j)) : "",
          has_best ? format_fixed(status.best_score, 6) : "", reason};
}

// Writes the pending frames.csv rows whose detection status is final, in order. At the end of the stream
// (after the matcher's flush), a row without a status (a failed run) is written with empty cells.
void PipelineRun::write_finished_rows(bool end_of_stream) {
  std::lock_guard lock(finished_mutex_);
  while (!pending_rows_.empty()) {
    PendingRow& row = pending_rows_.front();
    while (!finished_statuses_.empty() && static_cast<std::size_t>(finished_statuses_.front().i) < row.seq)
      finished_statuses_.pop_front();
    if (finished_statuses_.empty()) {
      if (!end_of_stream) return;
      for (int k = 0; k < 5; ++k) row.cells.emplace_back("");
    } else {
      const FrameMatchStatus& status = finished_statuses_.front();
      if (static_cast<std::size_t>(status.i) != row.seq) {
        throw std::logic_error(fmt::format("match status of seq {} while seq {} waits", status.i, row.seq));
      }
      for (auto& cell : detection_cells(status, row.seq)) row.cells.push_back(std::move(cell));
      ++outcome_counts_[static_cast<std::size_t>(status.outcome)];
      finished_statuses_.pop_front();
    }
    frames_csv_.write_row(row.cells);
    pending_rows_.pop_front();
  }
}

void PipelineRun::stage_sink(FrameRecord& r) {
  std::lock_guard lock(sink_mutex_);
  if (r.seq != next_sink_seq_) {
    throw std::logic_error(fmt::format("sink received seq {} while expecting {}", r.seq, next_sink_seq_));
  }
  ++next_sink_seq_;

  const std::string status = !r.errors.empty() ? "error" : !r.warnings.empty() ? "warning" : "ok";
  std::vector<std::string> messages = r.errors;
  messages.insert(messages.end(), r.warnings.begin(), r.warnings.end());
  const std::string reason = join_messages(messages);

  std::vector<std::string> row = {std::to_string(r.seq), std::to_string(r.frame), std::to_string(r.t_ns),
                                  format_fixed(ns_to_s(r.t_ns), 9)};
  const PoseEstimate& pose = r.odometry.pose;
  if (r.has_pose) {
    const Eigen::Vector3d p = pose.T_w_b.translation();
    const Eigen::Quaterniond q(pose.T_w_b.rotation());
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(pose.position_cov_m2(),
                                                                Eigen::EigenvaluesOnly);
    const double sigma_m = std::sqrt(std::max(0.0, solver.eigenvalues().maxCoeff()));
    for (const double value : {p.x(), p.y(), p.z(), q.x(), q.y(), q.z(), q.w()})
      row.push_back(format_fixed(value, 9));
    row.push_back(format_fixed(sigma_m, 9));
    row.emplace_back(to_string(pose.status));
    if (pose.status != OdometryStatus::kLost) trajectory_.write(r.t_ns, pose.T_w_b);
    if (pose.status == OdometryStatus::kTracking) tracked_poses_.push_back({r.t_ns, pose.T_w_b});
  } else {
    for (int i = 0; i < 8; ++i) row.emplace_back("");
    row.emplace_back("none");
  }
  row.push_back(std::to_string(r.imu.samples.size()));
  row.emplace_back(r.decoded ? "y" : "n");
  row.push_back(status);
  row.push_back(reason);
  if (odometry_->needs_images())  // visual sources (ekf): features tracked in this image
    row.push_back(r.has_pose ? std::to_string(std::max(0, r.odometry.tracked_features)) : "");
  if (gated_) {
    const GateDecision& g = r.gate;
    const bool has_nearest = r.gate_ran && g.has_nearest;
    row.push_back(has_nearest ? std::to_string(frame_of(g.nearest_frame)) : "");
    row.push_back(has_nearest ? format_fixed(g.distance_m, 6) : "");
    row.push_back(r.gate_ran ? format_fixed(g.threshold_m, 6) : "");
    row.emplace_back(g.gated ? "y" : "n");
    row.push_back(std::to_string(r.area_id));
  }
  if (seqslam_) {
    pending_rows_.push_back(PendingRow{static_cast<std::size_t>(r.seq), std::move(row)});  // until the end
  } else if (full_ || gated_) {
    pending_rows_.push_back(PendingRow{static_cast<std::size_t>(r.seq), std::move(row)});
    write_finished_rows(false);
  } else {
    frames_csv_.write_row(row);
  }

  ++processed_;
  (status == "ok" ? frames_ok_ : status == "warning" ? frames_warning_ : frames_error_)++;
  if (r.decoded) ++decoded_;
  if (r.needs_pixels && !r.decoded) ++image_errors_;
  if (r.has_pose && pose.status == OdometryStatus::kLost) ++odometry_lost_;
  imu_gaps_ += static_cast<std::size_t>(r.imu.report.gaps);
  imu_out_of_order_ += static_cast<std::size_t>(r.imu.report.out_of_order);
  imu_duplicates_ += static_cast<std::size_t>(r.imu.report.duplicates);
  if (r.imu.report.imu_missing) ++imu_missing_frames_;
  if (!have_first_t_) {
    have_first_t_ = true;
    first_t_ns_ = r.t_ns;
  }
  last_t_ns_ = r.t_ns;
  if (status != "ok") {
    if (problem_frames_.size() < kMaxListedProblems) {
      problem_frames_.push_back({{"seq", r.seq}, {"frame", r.frame}, {"status", status}, {"reason", reason}});
    }
    ++problem_frame_count_;
  }
  r.image.release();

  const std::int64_t exit_ns = now_ns();
  r.stamps[kSink].exit_ns = exit_ns;
  if (r.deadline_ns > 0 && exit_ns > r.deadline_ns) ++deadline_misses_;

  std::vector<std::string> timing = {std::to_string(r.seq), std::to_string(r.frame)};
  double total_ms = 0;
  std::int64_t previous_exit_ns = r.release_ns;
  for (std::size_t s = 0; s < kStageCount; ++s) {
    const double service_ms = 1e-6 * static_cast<double>(r.stamps[s].exit_ns - r.stamps[s].enter_ns);
    const double wait_ms = 1e-6 * static_cast<double>(r.stamps[s].enter_ns - previous_exit_ns);
    previous_exit_ns = r.stamps[s].exit_ns;
    profiler_.add(s, service_ms, wait_ms);
    total_ms += service_ms;
    timing.push_back(format_fixed(service_ms, 4));
    if (config_.output.trace) {
      trace_.add(TraceEvent{kStageNames[s], "stage", 1e-3 * static_cast<double>(r.stamps[s].enter_ns),
                            1e-3 * static_cast<double>(r.stamps[s].exit_ns - r.stamps[s].enter_ns),
                            r.stamps[s].thread, static_cast<std::int64_t>(r.seq),
                            static_cast<std::int64_t>(r.frame)});
    }
  }
  const double latency_ms = 1e-6 * static_cast<double>(exit_ns - r.release_ns);
  profiler_.add_latency(latency_ms);
  timing.push_back(format_fixed(latency_ms, 4));
  timing.push_back(format_fixed(total_ms, 4));
  timing_csv_.write_row(timing);

  if (processed_ % static_cast<std::size_t>(config_.output.flush_every) == 0) {
    frames_csv_.flush();
    timing_csv_.flush();
    trajectory_.flush();
  }
  if (show_progress_ && exit_ns - last_progress_ns_ > static_cast<std::int64_t>(kProgressPeriodS * 1e9)) {
    last_progress_ns_ = exit_ns;
    show_progress(false);
  }
  {
    std::lock_guard flight_lock(flight_mutex_);
    --in_flight_;
  }
  flight_cv_.notify_all();
}

void PipelineRun::show_progress(bool final) {
  const double elapsed_s = 1e-9 * static_cast<double>(now_ns());
  const std::size_t total = last_frame_ - first_frame_;
  const double fps = elapsed_s > 0 ? static_cast<double>(processed_) / elapsed_s : 0.0;
  const double data_s = have_first_t_ ? ns_to_s(last_t_ns_ - first_t_ns_) : 0.0;
  const double rtf = elapsed_s > 0 ? data_s / elapsed_s : 0.0;
  const double eta_s = fps > 0 ? static_cast<double>(total - std::min(total, processed_)) / fps : 0.0;
  const std::string line = fmt::format("\r[run] {}/{} frames  {:.1f} frames/s  rtf {:.2f}x  ETA {:.0f} s   ",
                                       processed_, total, fps, rtf, eta_s);
  std::fputs(line.c_str(), stderr);
  if (final) std::fputs("\n", stderr);
  std::fflush(stderr);
}

void PipelineRun::open_outputs() {
  std::filesystem::create_directories(out_dir_);
  std::vector<std::string> frame_columns = {
      "seq", "frame", "t_ns",    "t_s",         "x_m",         "y_m",     "z_m",    "qx",    "qy",
      "qz",  "qw",    "sigma_m", "odom_status", "imu_samples", "decoded", "status", "reason"};
  if (odometry_->needs_images()) frame_columns.emplace_back("tracked_features");
  if (gated_) {
    // the gate: nearest past frame under the combined distance, d, threshold, decision, area joined
    for (const char* column : {"nearest_frame", "gate_d_m", "gate_threshold_m", "gated", "area_id"})
      frame_columns.emplace_back(column);
  }
  if (detects()) {
    // descriptor computed (y/n); detection: no candidate | below threshold | suppressed | loop; the best
    // DP value of the frame and its earlier frame (accepted or not); why. SeqSLAM: descriptor = the
    // preprocessed image; detection no match | rejected | loop; its best match and ratio (lower is better).
    for (const char* column : {"descriptor", "detection", "match_frame", "match_score", "detection_reason"})
      frame_columns.emplace_back(column);
    loops_csv_.open(out_dir_ / "loops.csv", {"i", "j", "t_i", "t_j", "score"});
  }
  frames_csv_.open(out_dir_ / "frames.csv", frame_columns);
  std::vector<std::string> timing_columns = {"seq", "frame"};
  for (const char* name : kStageNames) timing_columns.push_back(std::string(name) + "_ms");
  timing_columns.emplace_back("latency_ms");
  timing_columns.emplace_back("total_ms");
  timing_csv_.open(out_dir_ / "timing.csv", timing_columns);
  trajectory_.open(out_dir_ / "trajectory.tum");
}

void PipelineRun::produce(tbb::flow::queue_node<FramePtr>& queue, RunResult& result) {
  const int max_in_flight = config_.run.max_in_flight;
  const Timestamp t_first_ns = dataset_.frame_t_ns(first_frame_);
  const std::int64_t producer_start_ns = now_ns();
  const auto stop_requested = [&] { return (stop_ && stop_->load()) || failed_.load(); };
  std::uint64_t next_seq = 0;
  for (std::size_t frame = first_frame_; frame < last_frame_; ++frame) {
    if (stop_requested()) break;
    const Timestamp t_ns = dataset_.frame_t_ns(frame);
    std::int64_t deadline_ns = 0;
    bool released = false;
    if (rate_) {
      // Release on the replay clock; sleep in short slices so that a stop request is seen quickly.
      const auto release_ns =
          producer_start_ns + static_cast<std::int64_t>(static_cast<double>(t_ns - t_first_ns) / *rate_);
      while (!stop_requested() && now_ns() < release_ns) {
        std::this_thread::sleep_for(
            std::min<std::chrono::nanoseconds>(std::chrono::nanoseconds(release_ns - now_ns()), kPollPeriod));
      }
      if (stop_requested()) break;
      ++result.frames_in;
      released = true;
      {
        std::lock_guard lock(flight_mutex_);
        if (in_flight_ >= max_in_flight) {
          ++result.frames_dropped;
          continue;  // dropped before it gets a sequence number
        }
      }
      double budget_ns = config_.run.deadline_ms * 1e6;
      if (budget_ns <= 0) {
        const Timestamp next_t_ns =
            frame + 1 < dataset_.frame_count() ? dataset_.frame_t_ns(frame + 1) : t_ns;
        const Timestamp prev_t_ns = frame > 0 ? dataset_.frame_t_ns(frame - 1) : t_ns;
        const Timestamp period_ns = next_t_ns > t_ns ? next_t_ns - t_ns : t_ns - prev_t_ns;
        budget_ns = static_cast<double>(period_ns) / *rate_;
      }
      deadline_ns = now_ns() + static_cast<std::int64_t>(budget_ns);
    } else {
      std::unique_lock lock(flight_mutex_);
      while (in_flight_ >= max_in_flight && !stop_requested()) flight_cv_.wait_for(lock, kPollPeriod);
      if (stop_requested()) break;
    }
    FrameRecord* record = nullptr;
    {
      auto owned = std::make_unique<FrameRecord>();
      record = owned.get();
      std::lock_guard lock(live_mutex_);
      live_.emplace(next_seq, std::move(owned));
    }
    seq_frame_[next_seq] = frame;
    seq_t_ns_[next_seq] = t_ns;
    record->seq = next_seq++;
    record->frame = frame;
    record->t_ns = t_ns;
    record->release_ns = now_ns();
    record->deadline_ns = deadline_ns;
    record->release();
    {
      std::lock_guard lock(flight_mutex_);
      ++in_flight_;
    }
    if (!released) ++result.frames_in;
    queue.try_put(FrameMsg{record->seq, record});
  }
  result.interrupted = stop_ && stop_->load();
}

RunResult PipelineRun::run() {
  RunResult result;
  open_outputs();
  const int threads = config_.run.threads;
  spdlog::info("run: {} frames [{}, {}) of {} ({}), rate {}, {} worker threads, at most {} in flight",
               last_frame_ - first_frame_, first_frame_, last_frame_, dataset_.root().string(),
               dataset_.layout(), config_.run.rate, threads, config_.run.max_in_flight);

  // `threads` workers run the nodes; the calling thread produces outside the arena and joins it to drain.
  tbb::global_control parallelism(tbb::global_control::max_allowed_parallelism,
                                  static_cast<std::size_t>(threads) + 1);
  tbb::task_arena arena(threads + 1, 1);
  arena.initialize();
  WorkerExitObserver workers(arena);
  using namespace tbb::flow;
  std::unique_ptr<graph> g;
  std::unique_ptr<queue_node<FramePtr>> queue;
  std::unique_ptr<limiter_node<FramePtr, int>> limiter;
  const auto seq_of = [](const FramePtr& message) { return static_cast<std::size_t>(message.seq); };
  std::unique_ptr<sequencer_node<FramePtr>> seq_in, seq_decoded, seq_odometry, seq_described, seq_out;
  std::unique_ptr<function_node<FramePtr, FramePtr>> sync, decode, odometry, gate, describe, match;
  std::unique_ptr<function_node<FramePtr, int>> sink;
  arena.execute([&] {
    g = std::make_unique<graph>();
    queue = std::make_unique<queue_node<FramePtr>>(*g);
    limiter = std::make_unique<limiter_node<FramePtr, int>>(
        *g, static_cast<std::size_t>(config_.run.max_in_flight));
    seq_in = std::make_unique<sequencer_node<FramePtr>>(*g, seq_of);
    seq_decoded = std::make_unique<sequencer_node<FramePtr>>(*g, seq_of);
    seq_odometry = std::make_unique<sequencer_node<FramePtr>>(*g, seq_of);
    seq_described = std::make_unique<sequencer_node<FramePtr>>(*g, seq_of);
    seq_out = std::make_unique<sequencer_node<FramePtr>>(*g, seq_of);
    sync = std::make_unique<function_node<FramePtr, FramePtr>>(
        *g, serial, node_body(kSync, [this](FrameRecord& r) { stage_sync(r); }));
    decode = std::make_unique<function_node<FramePtr, FramePtr>>(
        *g, unlimited, node_body(kDecode, [this](FrameRecord& r) { stage_decode(r); }));
    odometry = std::make_unique<function_node<FramePtr, FramePtr>>(
        *g, serial, node_body(kOdometry, [this](FrameRecord& r) { stage_odometry(r); }));
    gate = std::make_unique<function_node<FramePtr, FramePtr>>(
        *g, serial, node_body(kGate, [this](FrameRecord& r) { stage_gate(r); }));
    describe = std::make_unique<function_node<FramePtr, FramePtr>>(
        *g, unlimited, node_body(kDescribe, [this](FrameRecord& r) { stage_describe(r); }));
    match = std::make_unique<function_node<FramePtr, FramePtr>>(
        *g, serial, node_body(kMatch, [this](FrameRecord& r) { stage_match(r); }));
    sink = std::make_unique<function_node<FramePtr, int>>(*g, serial, [this](FramePtr message) -> int {
      FrameRecord& r = *message.record;
      r.acquire();
      r.stamps[kSink].enter_ns = now_ns();
      r.stamps[kSink].thread = thread_index();
      try {
        stage_sink(r);
      } catch (const std::exception& e) {
        record_failure(kSink, r, e.what());
        throw;
      }
      std::lock_guard lock(live_mutex_);
      live_.erase(r.seq);
      return 1;
    });
    make_edge(*queue, *limiter);
    make_edge(*limiter, *seq_in);
    make_edge(*seq_in, *sync);
    make_edge(*sync, *decode);
    make_edge(*decode, *seq_decoded);
    make_edge(*seq_decoded, *odometry);
    // A serial node's outputs can overtake each other (the next body may start before the previous
    // output is put), so the gate, which needs frames in order, sits behind its own sequencer.
    make_edge(*odometry, *seq_odometry);
    make_edge(*seq_odometry, *gate);
    make_edge(*gate, *describe);
    make_edge(*describe, *seq_described);
    make_edge(*seq_described, *match);
    make_edge(*match, *seq_out);
    make_edge(*seq_out, *sink);
    make_edge(*sink, limiter->decrementer());
  });

  tsan_suppressions_anchor();  // TSan builds: links the oneTBB suppressions (parallel_handoff.hpp)
  const double cpu_start_s = cpu_seconds();
  start_ = Clock::now();
  produce(*queue, result);
  try {
    g->wait_for_all();
  } catch (const std::exception& e) {
    std::lock_guard lock(failure_mutex_);
    if (!failed_.load()) {
      failure_ = e.what();
      failed_.store(true);
    }
  }
  result.wall_s = 1e-9 * static_cast<double>(now_ns());
  result.cpu_s = cpu_seconds() - cpu_start_s;
  if (!workers.wait_until_all_left(kWorkerLeaveTimeout)) {
    spdlog::debug("run: TBB workers still in the arena at teardown");
  }
  result.peak_rss_mb = peak_rss_mb();
  {
    std::lock_guard lock(failure_mutex_);
    result.failed = failed_.load();
    result.error = failure_;
  }

  std::lock_guard lock(sink_mutex_);
  const std::int64_t end_of_stream_start_ns = now_ns();
  if (detects()) {
    // End of stream: (gated) the rows still open go to the matcher; the matcher finalises its last 2 W
    // frames; their rows follow. SeqSLAM: the whole search, then every row.
    std::lock_guard match_lock(match_mutex_);
    try {
      MatchOutput output;
      if (seqslam_) {
        finish_seqslam(arena);
      } else if (gated_) {
        tracker_->finish();
        push_final_rows(match_end_seq_, output);
        write_area_files();
      }
      if (!seqslam_) {
        matcher_->flush(output);
        handle_match_output(output);
        write_finished_rows(true);
      }
    } catch (const std::exception& e) {
      std::lock_guard failure_lock(failure_mutex_);
      if (!failed_.load()) {
        failure_ = std::string("match flush at the end of the stream: ") + e.what();
        failed_.store(true);
      }
      result.failed = true;
      result.error = failure_;
    }
    loops_csv_.close();
  }
  end_of_stream_ms_ = 1e-6 * static_cast<double>(now_ns() - end_of_stream_start_ns);
  // The end-of-stream work is part of the run (SeqSLAM's search happens there).
  result.wall_s = 1e-9 * static_cast<double>(now_ns());
  result.cpu_s = cpu_seconds() - cpu_start_s;
  result.peak_rss_mb = peak_rss_mb();
  if (show_progress_) show_progress(true);
  frames_csv_.close();
  timing_csv_.close();
  trajectory_.close();
  result.frames_processed = processed_;
  result.deadline_misses = deadline_misses_;
  result.frames_ok = frames_ok_;
  result.frames_warning = frames_warning_;
  result.frames_error = frames_error_;
  result.data_s = have_first_t_ ? ns_to_s(last_t_ns_ - first_t_ns_) : 0.0;
  result.realtime_factor = result.wall_s > 0 ? result.data_s / result.wall_s : 0.0;
  result.profile_table =
      profiler_.table(result.wall_s) +
      fmt::format(
          "cpu {:.2f} s / wall {:.2f} s = {:.2f} cores busy; {} frames in, {} processed, "
          "{} dropped, {} deadline misses; real-time factor {:.2f}\n",
          result.cpu_s, result.wall_s, result.wall_s > 0 ? result.cpu_s / result.wall_s : 0.0,
          result.frames_in, result.frames_processed, result.frames_dropped, result.deadline_misses,
          result.realtime_factor);
  result.summary = make_summary(result);
  write_json_file(out_dir_ / "summary.json", result.summary);
  if (config_.output.trace) {
    trace_.name_thread(0, "producer");
    for (int t = 1; t <= threads + 1; ++t) trace_.name_thread(t, fmt::format("thread {}", t));
    trace_.write(out_dir_ / "trace.json");
  }
  if (result.failed) spdlog::error("run failed: {}", result.error);
  return result;
}

// SeqSLAM at the end of the stream: the search over all frames (in the run's arena), loops.csv for the
// accepted matches, and every frames.csv row with its match.
void PipelineRun::finish_seqslam(tbb::task_arena& arena) {
  const std::size_t count = next_sink_seq_;
  std::vector<SeqSlamMatch> matches;
  arena.execute([&] { matches = seqslam_batch_->run(count); });
  const double threshold = config_.seqslam.ratio_threshold;
  for (const SeqSlamMatch& m : matches) {
    if (!m.has_match || !std::isfinite(m.ratio)) continue;
    const std::size_t frame_i = frame_of(static_cast<std::int64_t>(m.query));
    const std::size_t frame_j = frame_of(static_cast<std::int64_t>(m.reference));
    seqslam_candidates_.push_back(Detection{frame_i, frame_j, m.ratio});
    if (!m.accepted) continue;
    loops_csv_.write_row({std::to_string(frame_i), std::to_string(frame_j),
                          format_fixed(ns_to_s(seq_t_ns_[m.query]), 9),
                          format_fixed(ns_to_s(seq_t_ns_[m.reference]), 9), format_fixed(m.ratio, 6)});
    ++loops_;
    detections_.push_back(Detection{frame_i, frame_j, m.ratio});
  }
  const std::size_t half = static_cast<std::size_t>(config_.seqslam.sequence_length_frames / 2);
  for (PendingRow& row : pending_rows_) {
    const SeqSlamMatch& m = matches.at(row.seq);
    const bool described = seqslam_described_[row.seq] != 0;  // else it took part as a zero image
    std::string detection, reason;
    FrameOutcome outcome = FrameOutcome::kNoCandidate;
    if (!m.has_match) {
      detection = "no match";
      reason = row.seq < half || row.seq + half >= count
                   ? fmt::format("within ds/2 = {} frames of an end of the run", half)
                   : fmt::format("every sequence touches the exclusion ({} {} frames)",
                                 config_.seqslam.exclusion, config_.seqslam.exclusion_margin_frames);
    } else if (!m.accepted) {
      detection = "rejected";
      outcome = FrameOutcome::kBelowThreshold;
      reason = fmt::format("ratio {:.4f} > {:.4f}", m.ratio, threshold);
    } else {
      detection = "loop";
      outcome = FrameOutcome::kLoop;
      reason = fmt::format("ratio {:.4f} <= {:.4f}", m.ratio, threshold);
    }
    ++outcome_counts_[static_cast<std::size_t>(outcome)];
    row.cells.emplace_back(described ? "y" : "n");
    row.cells.push_back(detection);
    row.cells.push_back(m.has_match ? std::to_string(frame_of(static_cast<std::int64_t>(m.reference))) : "");
    row.cells.push_back(m.has_match ? format_fixed(m.ratio, 6) : "");
    row.cells.push_back(reason);
    frames_csv_.write_row(row.cells);
  }
  pending_rows_.clear();
}

// candidate_areas.csv: one rectangle per area (the bounding box of its cells; rows = query frames i,
// columns = reference frames j, inclusive), candidate_cells.csv: the cells actually compared, per row as
// disjoint column intervals, and descriptors.csv: every frame described, with the frame whose gate update
// asked for it (a frame's frames.csv row may be written before it is described as a later reference).
// Dataset frame indices.
void PipelineRun::write_area_files() {
  if (match_end_seq_ == 0) return;
  const auto last_seq = static_cast<std::int64_t>(match_end_seq_) - 1;
  const auto frame = [&](std::int64_t seq) { return std::to_string(frame_of(std::min(seq, last_seq))); };
  CsvWriter areas;
  areas.open(out_dir_ / "candidate_areas.csv", {"id", "row_begin", "row_end", "col_begin", "col_end",
                                                "i_first", "i_last", "j_min", "j_max", "gated_frames"});
  for (const CandidateArea& a : tracker_->areas()) {
    areas.write_row({std::to_string(a.id), frame(a.row_begin), frame(a.row_end), frame(a.col_begin),
                     frame(a.col_end), frame(a.i_first), frame(a.i_last), frame(a.j_min), frame(a.j_max),
                     std::to_string(a.gated_frames)});
  }
  areas.close();
  CsvWriter cells;
  cells.open(out_dir_ / "candidate_cells.csv", {"i", "j_first", "j_last"});
  for (std::int64_t i = 0; i <= last_seq; ++i) {
    for (const RowColumns& span : tracker_->covered_columns(i))
      cells.write_row({frame(i), frame(span.j0), frame(span.j1)});
  }
  cells.close();
  CsvWriter described;
  described.open(out_dir_ / "descriptors.csv", {"frame", "requested_by_frame", "computed"});
  for (const auto& [k, by] : describe_requests_) {
    const bool valid = store_->state(static_cast<std::size_t>(k)) == DescriptorStore::State::kValid;
    described.write_row({frame(k), frame(by), valid ? "y" : "n"});
  }
  described.close();
}

// The detections against the dataset's ground truth (evaluation.md): positives from positions (r_true,
// gap, plane), each query's best detection scored within r_accept, the PR curve; in gated mode the share
// of positive query frames whose true loop lies inside a candidate area. Also writes ground_truth.tum and
// truth_loops.csv for the plots.
nlohmann::json PipelineRun::evaluate_loops() {
  if (!dataset_.has_ground_truth()) return {{"available", false}};
  const std::size_t n = last_frame_ - first_frame_;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  std::vector<Eigen::Vector3d> p_w(n, Eigen::Vector3d::Constant(nan));
  TumWriter truth_tum;
  truth_tum.open(out_dir_ / "ground_truth.tum");
  for (std::size_t k = 0; k < n; ++k) {
    if (const auto T_w_b = dataset_.ground_truth_T_w_b(first_frame_ + k)) {
      p_w[k] = T_w_b->translation();
      truth_tum.write(dataset_.frame_t_ns(first_frame_ + k), *T_w_b);
    }
  }
  truth_tum.close();
  GroundTruthConfig truth_config;
  truth_config.radius_m = config_.eval.truth_radius_m;
  truth_config.gap_frames = config_.eval.truth_gap_frames;
  truth_config.plane = config_.eval.plane != "auto"   ? config_.eval.plane
                       : dataset_.layout() == "kitti" ? "xz"
                                                      : "xyz";
  truth_config.accept_radius_m = config_.eval.effective_accept_radius_m();
  const LoopGroundTruth truth = LoopGroundTruth::from_positions(p_w, truth_config);
  CsvWriter truth_loops;
  truth_loops.open(out_dir_ / "truth_loops.csv", {"i", "j"});
  for (const auto& [q, r] : truth.pairs())
    truth_loops.write_row({std::to_string(first_frame_ + q), std::to_string(first_frame_ + r)});
  truth_loops.close();

  std::vector<Detection> detections;
  detections.reserve(detections_.size());
  for (const Detection& d : detections_)
    detections.push_back({d.query - first_frame_, d.reference - first_frame_, d.score});
  // SeqSLAM: the PR sweep runs over every query's match (accepted or not: the ratio is the threshold);
  // loop_truth counts the accepted ones (loops.csv).
  std::vector<Detection> candidates;
  for (const Detection& d : seqslam_candidates_)
    candidates.push_back({d.query - first_frame_, d.reference - first_frame_, d.score});
  nlohmann::json out = {{"available", true},
                        {"truth",
                         {{"radius_m", truth_config.radius_m},
                          {"gap_frames", truth_config.gap_frames},
                          {"plane", truth_config.plane},
                          {"accept_radius_m", truth_config.effective_accept_radius_m()},
                          {"positives", truth.positive_count()}}}};
  out.update(loop_evaluation_json(detections, seqslam_ ? candidates : detections, truth,
                                  seqslam_ ? "lower_is_better" : "higher_is_better"));
  if (gated_ && tracker_) {
    // Positives the matcher could find (true reference at least match.margin frames back), and whether a
    // candidate area covers one of their true pairs.
    GroundTruthConfig reachable_config = truth_config;
    reachable_config.gap_frames = std::max(truth_config.gap_frames, config_.match.margin);
    const LoopGroundTruth reachable = LoopGroundTruth::from_positions(p_w, reachable_config);
    std::vector<std::int64_t> seq_of_index(n, -1);
    for (std::size_t seq = 0; seq < match_end_seq_; ++seq)
      seq_of_index[seq_frame_[seq] - first_frame_] = static_cast<std::int64_t>(seq);
    std::size_t positives = 0, covered = 0;
    for (std::size_t q = 0; q < n; ++q) {
      if (!reachable.is_positive(q) || seq_of_index[q] < 0) continue;
      ++positives;
      for (const std::size_t r : reachable.true_references(q)) {
        if (seq_of_index[r] >= 0 && tracker_->covers(seq_of_index[q], seq_of_index[r])) {
          ++covered;
          break;
        }
      }
    }
    out["gate_coverage"] = {{"gap_frames", reachable_config.gap_frames},
                            {"positive_query_frames", positives},
                            {"covered_query_frames", covered},
                            {"covered_fraction", positives ? static_cast<double>(covered) / positives : 0.0}};
  }
  return out;
}

nlohmann::json PipelineRun::make_summary(const RunResult& result) {
  PipelineConfig echo = config_;
  nlohmann::json issues = nlohmann::json::array();
  for (const auto& issue : dataset_.issues()) {
    if (issues.size() >= kMaxListedProblems) break;
    issues.push_back(issue.file.string() + (issue.line ? ":" + std::to_string(issue.line) : "") + ": " +
                     issue.message);
  }
  std::size_t imu_anomalies_total = 0;
  if (synchronizer_) imu_anomalies_total = synchronizer_->anomalies().size();
  nlohmann::json gate_json = {{"enabled", gated_}};
  if (gated_) {
    std::size_t cells = 0, rows = 0;
    for (std::size_t seq = 0; seq < match_end_seq_; ++seq) {
      cells += row_cells_[seq];
      rows += row_cells_[seq] > 0 ? 1 : 0;
    }
    gate_json.update(
        {{"frames_with_pose", frames_gate_ran_},
         {"frames_gated", frames_gated_},
         {"pass_rate", frames_gate_ran_ ? static_cast<double>(frames_gated_) / frames_gate_ran_ : 0.0},
         {"pose_errors", gate_errors_},
         {"candidate_areas", tracker_->areas().size()},
         {"cells", cells},
         {"rows_with_cells", rows},
         {"kdtree_frames", pose_gate_->frames_in_tree()}});
  }
  return {
      {"config", config_to_json(echo)},
      {"dataset",
       {{"root", dataset_.root().string()},
        {"layout", dataset_.layout()},
        {"frame_count", dataset_.frame_count()},
        {"first_frame", first_frame_},
        {"last_frame", last_frame_},
        {"has_images", dataset_.has_images()},
        {"has_imu", dataset_.has_imu()},
        {"has_ground_truth", dataset_.has_ground_truth()}}},
      {"frames_in", result.frames_in},
      {"frames_processed", result.frames_processed},
      {"frames_dropped", result.frames_dropped},
      {"deadline_misses", result.deadline_misses},
      {"wall_s", result.wall_s},
      {"data_s", result.data_s},
      {"realtime_factor", result.realtime_factor},
      {"throughput_fps",
       result.wall_s > 0 ? static_cast<double>(result.frames_processed) / result.wall_s : 0.0},
      {"cpu_s", result.cpu_s},
      {"cpu_wall_ratio", result.wall_s > 0 ? result.cpu_s / result.wall_s : 0.0},
      {"peak_rss_mb", result.peak_rss_mb},
      {"threads", config_.run.threads},
      {"interrupted", result.interrupted},
      {"failed", result.failed},
      {"error", result.error},
      {"counts",
       {{"frames_ok", result.frames_ok},
        {"frames_warning", result.frames_warning},
        {"frames_error", result.frames_error},
        {"decoded", decoded_},
        {"odometry_lost", odometry_lost_}}},
      {"mode", seqslam_ ? std::string("full") : config_.run.mode},  // SeqSLAM always sees every frame
      {"method", seqslam_ ? "seqslam" : "dird"},
      {"score_order", seqslam_ ? "lower_is_better" : "higher_is_better"},
      {"end_of_stream_ms", end_of_stream_ms_},
      {"images_decoded", decoded_ + images_read_for_description_.load()},
      {"images_read_for_description", images_read_for_description_.load()},
      {"image_cache_hits", image_cache_hits_.load()},
      {"candidate_areas", gated_ ? tracker_->areas().size() : 0},
      {"descriptors_computed", descriptors_computed_.load()},
      {"similarities_computed", similarities_computed_.load()},
      {"loops", loops_},
      {"detection",
       {{"no_candidate", outcome_counts_[static_cast<std::size_t>(FrameOutcome::kNoCandidate)]},
        {"below_threshold", outcome_counts_[static_cast<std::size_t>(FrameOutcome::kBelowThreshold)]},
        {"suppressed", outcome_counts_[static_cast<std::size_t>(FrameOutcome::kSuppressed)]},
        {"loop", outcome_counts_[static_cast<std::size_t>(FrameOutcome::kLoop)]},
        {"nms_delay_frames", full_ ? matcher_->emission_delay() : 0}}},
      {"evaluation", detects() ? evaluate_loops() : nlohmann::json{{"available", false}}},
      {"gate", gate_json},
      {"trajectory_accuracy", trajectory_accuracy_json(tracked_poses_, dataset_)},
      {"stages", profiler_.to_json()},
      {"data_issues",
       {{"dataset_issue_count", dataset_.issues().size()},
        {"dataset_issues", issues},
        {"image_errors", image_errors_},
        {"imu_gaps", imu_gaps_},
        {"imu_out_of_order", imu_out_of_order_},
        {"imu_duplicates", imu_duplicates_},
        {"imu_missing_frames", imu_missing_frames_},
        {"imu_anomalies_in_stream", imu_anomalies_total},
        {"frames_with_issues", problem_frame_count_},
        {"frames", problem_frames_}}},
  };
}

}  // namespace

RunResult run_pipeline(const PipelineConfig& config, const Dataset& dataset,
                       const std::filesystem::path& out_dir, const std::atomic<bool>* stop) {
  config.validate();
  if (dataset.frame_count() == 0) throw DataError(dataset.root(), "dataset has no frames");
  PipelineRun run(config, dataset, out_dir, stop);
  return run.run();
}

}  // namespace loopgate
