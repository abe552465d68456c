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
#include <filesystem>

#include "pipeline/outputs/run_folder.hpp"
#include "pipeline/outputs/run_result.hpp"
#include "pipeline/pipeline_config.hpp"

namespace loopgate {

class Dataset;

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
