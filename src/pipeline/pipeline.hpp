// `loopgate run`: the oneTBB flow graph (architecture.md § The graph) over one dataset.
//
// clang-format off
//
//   producer ──► queue ──► limiter ──► seq ──► sync ──► decode* ──► seq ──► odometry ──► seq ──► gate ──► describe* ──► seq ──► match ──► seq ──► sink
//   (replay clock,          (K in flight)      (serial) (parallel)          (serial)            (serial)  (parallel)           (serial)          (serial)
//    calling thread)            ▲                                                                                                                  │
//                               └──────────────────────────────── integer decrement (one per frame) ◄─────────────────────────────────────────────┘
//
//   node        one call on                   what it does
//   sync        FrameSteps::sync              IMU samples between this frame and the previous one; decide whether to decode
//   decode      FrameSteps::decode            the frame's pixels, when a later stage needs them now (lazy)
//   odometry    FrameSteps::odometry          pose + covariance from the odometry source (drift, file, ekf)
//   gate        DetectionMethod::gate         gated DIRD / SeqSLAM: the pose gate and the candidate areas; others: nothing
//   describe    DetectionMethod::describe     DIRD descriptors / SeqSLAM preprocessing (parallel)
//   match       DetectionMethod::match        similarities, sequence DP + NMS, loops.csv (serial, in order)
//   sink        RunOutputs::sink              frames.csv, trajectory.tum, timing.csv, counters, trace
//
// clang-format on
//
// Every serial node sits behind a sequencer: a serial node's outputs can overtake each other.
// - The detection method is chosen once (pipeline/detection_method.hpp): none (run.mode odometry), DIRD full,
//   DIRD gated (default), SeqSLAM full or gated (run.method seqslam). After the drain its finish() runs
//   (matcher flush, SeqSLAM's search), then the rows held for their detection are written and summary.json.
// - The producer runs on the calling thread, outside the worker arena (ReplayClock: `rate: max` waits for
//   a free slot, `rate: R` releases frame i at start + (t_i - t_first) / R and drops it when K frames are in
//   flight).
// - Every released frame gets the next contiguous sequence number and passes every node, whatever happens
//   to it.
// - Bad data in one frame (image that fails to decode, IMU gap/out-of-order/duplicates, odometry lost) is
//   recorded in that frame's status and in the summary; the run goes on. Any other exception escaping a node
//   cancels the graph; it is reported once with its stage and frame, the outputs of the frames already
//   through the sink are written, and the result is `failed`.
// - A stop request (SIGINT, SIGTERM, SIGHUP) stops the producer; the graph drains and every output is
//   written; the evaluation covers only the frames presented.
// - Every output is whole or absent (written under a temporary name, renamed when complete); after the drain
//   each one is attempted even when another failed (a full disk), and the missing ones are listed in
//   RunResult::missing_outputs (and in summary.json when it could be written).
#pragma once

#include <atomic>
#include <cstddef>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "core/pose_covariance.hpp"
#include "core/types.hpp"
#include "eval/precision_recall.hpp"
#include "pipeline/pipeline_config.hpp"
#include "stages/dird/dird_extractor.hpp"

namespace loopgate {

class Dataset;

// A finished run's odometry and loops, for correcting its trajectory after the run (compare's loop
// correction, correct_after_run in loops/correct_after_run.hpp).
struct RunTrack {
  std::size_t first_frame = 0, last_frame = 0;  // the run's frame range [first, last)
  std::vector<std::size_t> tracked_frames;      // the frame of each tracked pose
  std::vector<StampedPose> tracked_poses;       // the odometry's estimates (status tracking; the ATE's poses)
  std::vector<double> tracked_sigma_m;          // their position sigma (PoseEstimate::position_sigma_m)
  // Their step covariances (OdometryOutput::step_cov) when the pose graph uses them (posegraph.odometry_cov
  // odometry) and loop closure is on (verify.enabled, or run_pipeline's keep_step_cov); else empty.
  std::vector<std::optional<PoseCov>> tracked_step_cov;
  std::vector<Detection> loops;  // as loops.csv, dataset frames
};

struct RunResult {
  std::size_t frames_in = 0;         // presented by the source: processed + dropped (+ lost on failure)
  std::size_t frames_processed = 0;  // through the sink
  std::size_t frames_dropped = 0;    // real-time overload drops (rate mode)
  std::size_t deadline_misses = 0;   // rate mode: sink exit later than release + deadline
  std::size_t frames_ok = 0, frames_warning = 0, frames_error = 0;
  double wall_s = 0, data_s = 0, realtime_factor = 0, cpu_s = 0, peak_rss_mb = 0;
  bool interrupted = false;
  bool failed = false;
  std::string error;  // the failure, naming stage, seq and frame
  // Outputs that could not be written (a full disk): each file is whole or absent; these are absent. A run
  // with a missing output is `failed`.
  std::vector<std::string> missing_outputs;
  std::vector<std::string> output_errors;  // why, naming the files
  std::string profile_table;               // the profiler table (also in summary.json as numbers)
  nlohmann::json summary;                  // what summary.json holds
  // A descriptor for the plots' picture (DIRD methods: the first loop's query frame, else the middle
  // frame), with its dataset frame index.
  std::optional<std::pair<std::size_t, Descriptor>> example_descriptor;
  RunTrack track;
};

// Every file a run may write into its output folder (frames.csv, ..., summary.json).
const std::vector<std::string>& run_output_file_names();

// Throws ConfigError when `out_dir` already holds another run's outputs (any of `names`, files or folders)
// and `force` is false: outputs of two runs must not mix in one folder. The message names what
// was found and says --force replaces it. `command` names the refusing command ("run", "compare").
void refuse_previous_outputs(const std::filesystem::path& out_dir, const std::vector<std::string>& names,
                             bool force, const std::string& command);

// Throws ConfigError when an input the run reads (odometry.file with source file; `extra` inputs of the
// command, e.g. its --config file) is one of the files it writes into `out_dir`: a previous run's
// trajectory.tum given as odometry.file would be read, then overwritten.
void refuse_outputs_over_inputs(const PipelineConfig& config, const std::filesystem::path& out_dir,
                                const std::vector<std::filesystem::path>& extra_inputs = {});

// Runs the graph over `dataset` and writes frames.csv, trajectory.tum, timing.csv, summary.json (and
// trace.json when output.trace; loops.csv when detecting loops; candidate_areas.csv, candidate_cells.csv and
// descriptors.csv in gated mode; ground_truth.tum and truth_loops.csv with ground truth) into `out_dir`.
// summary.json has mode, method, images_decoded, descriptors_computed, similarities_computed, loops,
// detection (frames per outcome), gate counts, and with ground truth an "evaluation" block (loops true /
// false, PR curve, AP, recall at 100/99/95% precision, gate coverage). `config` must be valid (load_config /
// apply_config validate it, once). `stop` (may be null) is polled by the producer. Throws
// ConfigError/DataError for problems found before the graph starts (refuse_outputs_over_inputs among them).
// `keep_step_cov`: RunTrack::tracked_step_cov is filled also without verify.enabled (compare verifies and
// corrects each method after its timed run).
RunResult run_pipeline(const PipelineConfig& config, const Dataset& dataset,
                       const std::filesystem::path& out_dir, const std::atomic<bool>* stop = nullptr,
                       bool keep_step_cov = false);

}  // namespace loopgate
