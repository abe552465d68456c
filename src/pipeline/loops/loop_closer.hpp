// Loop closures that correct the trajectory: every loop the method accepts (LoopsWriter's
// listener) is queued to one worker thread that verifies it geometrically (stages/verify) and, while the
// stream runs, solves the pose graph (stages/posegraph) whenever verified loops arrived, bounded by
// posegraph.max_solve_s. Nothing of the frame's path waits for it: the sink only holds a loop frame's
// frames.csv row until that frame's loops are verified. At the end of the stream finish() drains the queue
// and solves once more from the odometry poses (no time bound), so every output depends only on the loops
// and the poses, never on the timing of the solves in between: trajectory_corrected.tum, loop_edges.csv,
// the verification columns of loops.csv and frames.csv, summary fields.
#pragma once

#include <tbb/task_arena.h>

#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <thread>
#include <unordered_map>
#include <utility>
#include <vector>

#include "core/pose_covariance.hpp"
#include "core/types.hpp"
#include "eval/precision_recall.hpp"
#include "stages/posegraph/pose_graph.hpp"
#include "stages/verify/geometric_verifier.hpp"

namespace loopgate {

class Dataset;
struct PipelineConfig;
class LoopsWriter;

class LoopCloser {
 public:
  // Frames [first_frame, last_frame) of `dataset`. Inactive (does nothing) unless enabled and the run
  // detects.
  LoopCloser(const PipelineConfig& config, const Dataset& dataset, std::size_t first_frame,
             std::size_t last_frame, bool detects);
  ~LoopCloser();
  LoopCloser(const LoopCloser&) = delete;
  LoopCloser& operator=(const LoopCloser&) = delete;

  bool active() const { return active_; }
  // The odometry node (serial), once per frame with a usable pose: the pose the verifier and the graph use,
  // its position sigma (PoseEstimate::position_sigma_m; the odometry check) and its step covariance from
  // the previous recorded pose (OdometryOutput::step_cov; posegraph.odometry_cov). Frames never recorded
  // have no pose.
  void record_pose(std::size_t frame, const Eigen::Isometry3d& T_w_b, double sigma_m,
                   const std::optional<PoseCov>& step_cov);
  // A loop accepted by the method (match node or end of stream); queued in this order.
  void submit(const Detection& loop);
  // Called on the worker thread with every loop as its verification ends (verified, rejected or skipped), in
  // submission order, before the streaming solve it may start (gate.feedback, gate_feedback.hpp). Set before
  // the first submit().
  using ResultListener = std::function<void(const Detection& loop, const VerifyResult& result)>;
  void set_result_listener(ResultListener listener) { result_listener_ = std::move(listener); }
  // frames.csv's "geometry" cell of frame `frame` once every loop of that query frame is verified
  // (empty when it has none), nullopt while one is pending.
  std::optional<std::string> geometry_cell(std::size_t frame) const;
  // timing.csv's loop-closure cells of a query frame, once geometry_cell() has a value: the verification of
  // its loops and the streaming pose-graph solve its loop started (0 when none). Off the frame's path.
  struct FrameMs {
    double verify_ms = 0;
    double optimize_ms = 0;
  };
  FrameMs frame_ms(std::size_t frame) const;
  // After the last submit(): drains the queue, solves the final graph.
  void finish();
  // After finish(): why the final pose-graph solve failed (empty when it succeeded or did not run). A failed
  // solve corrects nothing: trajectory_corrected.tum and pose_graph.g2o are not written, the summary's
  // trajectory_accuracy_corrected is unavailable, and the run fails (pipeline_finish.cpp).
  const std::string& solve_failure() const { return final_solve_error_; }

  // After finish(): the files and the summary fields.
  void write_edges(const std::filesystem::path& out_dir) const;  // loop_edges.csv
  // pose_graph.g2o (io/g2o_file.hpp): the final solve's graph - its nodes at their odometry poses, its
  // odometry edges and the loop edges it kept (those it switched off are in loop_edges.csv only). Nothing
  // when there was no final solve.
  void write_graph(const std::filesystem::path& out_dir) const;
  // loops.csv again with the verification columns (when every loop written was submitted here).
  void annotate_loops(LoopsWriter& loops) const;
  // tracked poses of the run -> corrected poses (same times).
  std::vector<StampedPose> corrected(const std::vector<StampedPose>& tracked) const;
  // The loop oracle (pipeline/loops/loop_oracle.hpp) on the final solve's odometry graph with perfect edges
  // at `truth_pairs` (dataset frames: query i, reference j), read against this run: ATE of the odometry, of
  // the corrected trajectory and of the oracle's (the floor), and the share of the attainable gain this run
  // reached, (odometry - corrected) / (odometry - oracle), null when the oracle gains under 10% of the
  // odometry's ATE. After finish(), after the stream: it costs one more solve of the final graph ("ms").
  nlohmann::json oracle_report(const std::vector<StampedPose>& tracked,
                               const std::vector<std::pair<std::size_t, std::size_t>>& truth_pairs) const;
  // trajectory_corrected.tum; nothing when the final solve failed (solve_failure()).
  void write_corrected(const std::filesystem::path& out_dir, const std::vector<StampedPose>& tracked) const;
  nlohmann::json summary() const;
  // The run summary's fields: loops_verified, loops_rejected_geometry, loops_skipped_geometry,
  // trajectory_accuracy_corrected (of `tracked` corrected) and loop_closure (summary()).
  nlohmann::json summary_fields(const std::vector<StampedPose>& tracked) const;
  std::string profile_line() const;
  // The loops verification rejected and those it skipped, counted by their VerifyReason key (sorted).
  struct ReasonCounts {
    std::map<std::string, std::size_t> rejected, skipped;
  };
  ReasonCounts reason_counts() const;

 private:
  struct LoopResult {
    Detection loop;
    std::size_t neighbour = 0;
    VerifyResult result;
    double verify_ms = 0;
    bool outlier = false;  // switched off by the final solve
    double chi2 = 0;
    bool skipped = false;  // not verified by choice (min_information_gain, max_per_query, skip_after_*)
  };
  static std::vector<std::string> verification_cells(const LoopResult& r);
  void work();
  // `draining`: the stream has ended (finish()), the pipeline's threads are free. The result verify_ahead()
  // computed for this loop, when it did.
  LoopResult verify_one(const Detection& loop, bool draining);
  // What the verifier needs of a loop: its frames' features (read and detected here, worker only), or the
  // reason it cannot be verified.
  struct VerifyJob {
    std::optional<std::size_t> neighbour;  // j's neighbour (verify.neighbour_offset_frames)
    std::shared_ptr<const OrbFeatures> i, j, n;
    std::optional<VerifyNote> reason;  // set: nothing to run
  };
  std::optional<std::size_t> neighbour_of(const Detection& loop) const;
  // `prefetch`: the three frames' missing features detected at once first (prefetch_features).
  VerifyJob prepare(const Detection& loop, bool prefetch);
  // The verification of a prepared loop (the verifier and the odometry check): reads only what the worker
  // no longer changes, so several run at once.
  VerifyResult run(const Detection& loop, const VerifyJob& job) const;
  // At the end of the stream, with run.threads > 1: verifies at once, on run.threads threads, the loop at the
  // front of the queue and the next ones that will be verified if the outcomes not known yet are those of the
  // last loop verified or rejected, and keeps their results for verify_one(). Each result is taken in
  // submission order after its own skip check, so the files are those of one loop after the other.
  void verify_ahead();
  // Whether `earlier`, verified or rejected, makes skip_reason(later) say skip (skip_after_*_frames,
  // max_per_query).
  bool would_skip(const Detection& earlier, bool verified, const Detection& later) const;
  // The oracle's gain (odometry ATE - floor) below which no share is given: the share of a gain that small
  // is mostly the noise of the two ATEs.
  static constexpr double kOracleMinGain = 0.10;
  static constexpr std::size_t kVerifyAheadLoops = 256;  // how far down the queue verify_ahead() looks
  // At most this many loops per thread at once: the threads take them one by one, so that one slow
  // verification does not leave the other threads idle until it ends.
  static constexpr std::size_t kVerifyAheadPerThread = 4;
  // Whether `later` lies within verify.skip_after_verified_frames (or _rejected_) of `earlier`, in both i and
  // j, `earlier` having been verified (or rejected).
  bool in_skip_window(const Detection& earlier, bool verified, const Detection& later) const;
  // Why (i, j) is not verified given the loops verified before it (nullopt: verify it). Worker only.
  std::optional<VerifyNote> skip_reason(const Detection& loop);
  // The odometry's covariance of T_j_i as the pose graph would see it (worker only): the step covariances
  // from j to i composed (the prefix chain below), times the graph's scale (scale_now()), plus an edge's
  // floors per node between them; the model's (posegraph.odometry_cov model, or a frame without a step
  // covariance in between) otherwise.
  PoseCov relative_odometry_cov(std::size_t j, std::size_t i, double scale);
  // The graph's covariance of T_j_i from the odometry's composed step covariance `cov` over `frames` frames:
  // `cov` times `scale`, plus an edge's floors per node between j and i.
  PoseCov with_node_floors(const PoseCov& cov, std::size_t frames, double scale) const;
  // What the skip rule weighs the loop (i, j) with, taken from the verified loops over most of the same
  // odometry (their chains from j' to i' and from j to i share at least half of their union): the scale of
  // the odometry's covariance, the largest of scale_now() and the scales those loops' innovations show, and
  // the covariance of the most recent one's edge (what verification gives at this place and speed, not the
  // least certain edge it could accept). nullopt when no verified loop covers the loop yet: it is then
  // verified whatever its gain, so that every stretch of odometry is checked against the images before its
  // covariance is trusted to skip loops.
  struct SkipBasis {
    double scale = 1.0;
    PoseCov edge_cov = PoseCov::Zero();
  };
  std::optional<SkipBasis> skip_basis(const Detection& loop) const;
  // posegraph.odometry_cov_scale, or when it is 0 the scale the loops verified so far show (1 before 3).
  double scale_now() const;
  // Extends the chain below to the frames of index < span (worker only).
  void extend_chain(std::size_t span);
  // Each recorded frame's pose and covariance relative to the start of its chain of step covariances (a frame
  // without one starts a chain), filled as far as the loops need (worker only).
  std::vector<std::int64_t> chain_id_;
  std::vector<PoseCov> chain_cov_;
  std::vector<Eigen::Isometry3d> chain_T_;
  std::optional<std::size_t> chain_previous_;
  std::int64_t chains_ = -1;
  // The verified loops against the odometry so far (worker only): scale_now()'s input.
  std::vector<LoopInnovation> innovations_;
  // Per verified loop (query, reference) the scale its innovation alone shows (worker only).
  struct CheckedSpan {
    std::size_t query = 0, reference = 0;
    double scale = 1.0;
    PoseCov loop_cov = PoseCov::Zero();
  };
  std::vector<CheckedSpan> checked_spans_;
  void add_innovation(const LoopResult& r);
  // ORB features of a frame, detected once and kept for feature_cache_frames frames. Worker only.
  std::shared_ptr<const OrbFeatures> features_of(std::size_t frame);
  // At the end of the stream, with run.threads > 1: detects the features of those `frames` that are not
  // cached on run.threads threads at once and caches them in this order (what features_of() would do one
  // after the other, so every result is the same). Worker only.
  void prefetch_features(const std::vector<std::size_t>& frames);
  void remember_features(std::size_t frame, std::shared_ptr<const OrbFeatures> features);
  // Builds the graph from the poses of frames <= last and the verified loops so far; solves. Returns the
  // solve's time.
  double solve(std::size_t last, bool final);
  std::optional<Eigen::Isometry3d> pose_of(std::size_t frame) const;
  // `tracked` with the correction of the final graph's nodes at `node_poses` (corrected()).
  std::vector<StampedPose> corrected_by(const std::vector<StampedPose>& tracked,
                                        const std::vector<Eigen::Isometry3d>& node_poses) const;
  // Every frame of [from, to] has an odometry pose (none lost, initialising or without an image between).
  bool odometry_unbroken(std::size_t from, std::size_t to) const;

  const Dataset& dataset_;
  std::size_t first_ = 0, last_ = 0;
  bool active_ = false;
  VerifyConfig verify_config_;
  PoseGraphConfig graph_config_;
  GeometricVerifier verifier_;
  std::optional<VerifyNote> unusable_;  // the reason no loop can be verified (nullopt: they can)
  std::vector<std::optional<Eigen::Isometry3d>> poses_;  // by frame - first, written once each
  std::vector<double> sigma_m_;                          // by frame - first: the pose's position sigma
  // By frame - first (posegraph.odometry_cov odometry only): the step covariance from the previous recorded
  // pose, and whether the source gave one.
  std::vector<PoseCov> step_cov_;
  std::vector<char> has_step_cov_;
  // The covariance of the odometry edge between the recorded frames a < b: the step covariances composed
  // times `scale`, or the model's when a frame between them has none (or posegraph.odometry_cov is model).
  PoseCov odometry_edge_cov(std::size_t a, std::size_t b, double scale) const;
  // The factors for the odometry's covariances in a solve. `graph`, for the odometry edges:
  // posegraph.odometry_cov_scale, or when it is 0 the scale the verified loops show
  // (odometry_cov_scale_from_loops, never below 1). `loss_fraction` (at most 1), for the graph's covariance
  // of T_j_i (relative_odometry_cov(), the floors included) that widens each loop edge's robust loss
  // (loop_loss_scale()): from 3 loops on, the fraction of it at which the loops' median innovation is the
  // chi-square median, when they agree better than it predicts. A true loop's residual is spread as the
  // odometry's true covariance says, and an odometry (or its floors) more certain than it claims is not
  // a drift for the loss to make room for.
  struct OdometryScales {
    double graph = 1.0;
    double loss_fraction = 1.0;
  };
  // Frames up to index `span` of poses_.
  OdometryScales odometry_cov_scale(const std::vector<LoopResult>& loops, std::size_t span) const;

  mutable std::mutex mutex_;
  std::condition_variable wake_;
  std::deque<Detection> queue_;
  std::vector<LoopResult> results_;    // in submission order
  std::vector<int> pending_by_frame_;  // loops of query frame f queued, not yet verified
  bool stopping_ = false;
  ResultListener result_listener_;
  std::thread worker_;

  // Worker-only (and finish(), after the join).
  std::unordered_map<std::size_t, std::shared_ptr<const OrbFeatures>> feature_cache_;
  std::deque<std::size_t> feature_cache_order_;   // oldest first
  int drain_threads_ = 1;                         // run.threads: prefetch_features' threads
  std::unique_ptr<tbb::task_arena> drain_arena_;  // created by the first prefetch
  std::size_t drain_verified_ = 0;        // loops verified or rejected (not skipped) after the stream ended
  std::size_t drain_prefetched_ = 0;      // features detected by prefetch_features
  std::size_t drain_verified_ahead_ = 0;  // loops whose result verify_ahead() computed
  std::unordered_map<std::size_t, LoopResult> verified_ahead_;  // by submission index, until verify_one()
  std::size_t verified_at_last_solve_ = 0;
  std::vector<double> solve_ms_;  // solves while streaming
  // timing.csv's cells by query frame: its loops' verification and the streaming solves they started (mutex_)
  std::unordered_map<std::size_t, FrameMs> ms_by_frame_;
  double final_solve_ms_ = 0;
  SolveReport final_report_;
  std::string final_solve_error_;          // why the final solve failed (empty: it did not)
  double final_odometry_cov_scale_ = 1.0;  // the final solve's (posegraph.odometry_cov odometry)
  double final_loss_fraction_ = 1.0;       // the final solve's OdometryScales::loss_fraction
  std::vector<std::size_t> nodes_;         // frames of the final graph's nodes
  std::vector<Eigen::Isometry3d> node_poses_;
  std::vector<PoseGraphEdge> final_edges_;  // the final graph's edges (node indices into nodes_)
};

}  // namespace loopgate
