// `loopgate run`: the oneTBB flow graph (architecture.md § The graph) over one dataset.
//
//   producer ──► queue ──► limiter ──► seq ──► sync ──► decode* ──► seq ──► odometry ──► seq ──► gate ──►
//   describe* ──► seq (replay clock,          (K in flight)       (serial) (parallel)          (serial)
//   (serial)  (parallel)     │
//    main thread)              ▲ │
//                              │                         sink ◄── seq ◄── match (serial)
//                              ◄─────────────────────────────────┘ └──── integer decrement (1 per frame) ◄──
//                              (serial)
//
// Every serial node sits behind a sequencer: a serial node's outputs can overtake each other.
// - run.mode = gated: the gate node (PoseGate + CandidateAreaTracker) decides per frame which cells became
//   covered and which descriptors are needed; describe computes those (past frames read again); match
//   computes the new cells' similarities and feeds rows older than gate.row_horizon_frames to the matcher.
// - The producer runs on the calling thread, outside the worker arena. `rate: max` waits for a free slot
//   (back-pressure, no drops); `rate: R` releases frame i at start + (t_i - t_first) / R on a steady
//   clock and drops it (counted, before it gets a sequence number) when K frames are in flight.
// - Every released frame gets the next contiguous sequence number and passes every node, whatever
//   happens to it; sequencers restore the order after the parallel node (and guard the serial ones).
// - decode is lazy: it decodes only when a later stage needs the pixels of this frame now (run.decode
//   = all forces it; a visual odometry source needs every frame, and so does describe in full mode).
// - run.mode = odometry: describe and match pass frames through. run.mode = full (the pure-DIRD
//   baseline): describe extracts the frame's DIRD descriptor into a store owned by the run (3456 bytes
//   per frame, DescriptorStore) and computes its similarities against the frames j <= i - max(margin, K)
//   (certainly through the sink: the producer releases seq i only when at most K - 1 frames are in
//   flight); match, in order, adds the pairs i - K < j <= i - margin (only when margin < K), feeds the
//   streaming SequenceMatcher and writes loops.csv (i,j,t_i,t_j,score; dataset frame indices, times in
//   s). The sink holds each frames.csv row until the matcher has finalised the frame (NMS delay 2 W
//   frames); the matcher is flushed at the end of the stream. frames.csv then gains the columns
//   descriptor (y/n), detection (no candidate | below threshold | suppressed | loop), match_frame and
//   match_score (the frame's largest DP value, accepted or not) and detection_reason. The matcher indexes
//   frames by sequence number (contiguous also when rate mode drops frames; match.margin counts them).
// - Bad data in one frame (image that fails to decode, IMU gap/out-of-order/duplicates, odometry lost)
//   is recorded in that frame's status and in the summary; the run goes on. Any other exception escaping
//   a node cancels the graph; it is reported once with its stage and frame, the outputs of the frames
//   already through the sink are written, and the result is `failed`.
// - A stop request (SIGINT) stops the producer; the graph drains and every output is written.
#pragma once

#include <atomic>
#include <cstddef>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <utility>

#include "pipeline/pipeline_config.hpp"
#include "stages/dird/dird_extractor.hpp"

namespace loopgate {

class Dataset;

struct RunResult {
  std::size_t frames_in = 0;         // presented by the source: processed + dropped (+ lost on failure)
  std::size_t frames_processed = 0;  // through the sink
  std::size_t frames_dropped = 0;    // real-time overload drops (rate mode)
  std::size_t deadline_misses = 0;   // rate mode: sink exit later than release + deadline
  std::size_t frames_ok = 0, frames_warning = 0, frames_error = 0;
  double wall_s = 0, data_s = 0, realtime_factor = 0, cpu_s = 0, peak_rss_mb = 0;
  bool interrupted = false;
  bool failed = false;
  std::string error;          // the failure, naming stage, seq and frame
  std::string profile_table;  // the profiler table (also in summary.json as numbers)
  nlohmann::json summary;     // what summary.json holds
  // A descriptor for the plots' picture (DIRD methods: the first loop's query frame, else the middle
  // frame), with its dataset frame index.
  std::optional<std::pair<std::size_t, Descriptor>> example_descriptor;
};

// Runs the graph over `dataset` and writes frames.csv, trajectory.tum, timing.csv, summary.json (and
// trace.json when output.trace; loops.csv when detecting loops; candidate_areas.csv, candidate_cells.csv and
// descriptors.csv in gated mode; ground_truth.tum and truth_loops.csv with ground truth) into `out_dir`.
// summary.json has mode, method, images_decoded, descriptors_computed, similarities_computed, loops,
// detection (frames per outcome), gate counts, and with ground truth an "evaluation" block (loops true /
// false, PR curve, AP, recall at 100/99/95% precision, gate coverage). `config` must be validated. `stop`
// (may be null) is polled by the producer. Throws ConfigError/DataError for problems found before the graph
// starts.
RunResult run_pipeline(const PipelineConfig& config, const Dataset& dataset,
                       const std::filesystem::path& out_dir, const std::atomic<bool>* stop = nullptr);

}  // namespace loopgate
