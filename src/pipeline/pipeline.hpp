// `loopgate run`: the oneTBB flow graph (architecture.md § The graph) over one dataset.
//
//   producer ──► queue ──► limiter ──► seq ──► sync ──► decode* ──► seq ──► odometry ──► seq ──► sink
//   (replay clock,          (K in flight)       (serial) (parallel)          (serial)            (serial)
//    main thread)              ▲                                                                    │
//                              └──────────────── integer decrement (1 per frame) ◄─────────────────┘
//
// - The producer runs on the calling thread, outside the worker arena. `rate: max` waits for a free slot
//   (back-pressure, no drops); `rate: R` releases frame i at start + (t_i - t_first) / R on a steady
//   clock and drops it (counted, before it gets a sequence number) when K frames are in flight.
// - Every released frame gets the next contiguous sequence number and passes every node, whatever
//   happens to it; sequencers restore the order after the parallel node (and guard the serial ones).
// - decode is lazy: it decodes only when a later stage needs the pixels of this frame now (run.decode
//   = all forces it; a visual odometry source needs every frame). The gate / describe / match nodes of
//   the DIRD issues go between odometry and sink; describe reads the images it needs itself through the
//   dataset's random access.
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
#include <string>

#include "pipeline/pipeline_config.hpp"

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
};

// Runs the graph over `dataset` and writes frames.csv, trajectory.tum, timing.csv, summary.json (and
// trace.json when output.trace) into `out_dir`. `config` must be validated. `stop` (may be null) is
// polled by the producer. Throws ConfigError/DataError for problems found before the graph starts.
RunResult run_pipeline(const PipelineConfig& config, const Dataset& dataset,
                       const std::filesystem::path& out_dir, const std::atomic<bool>* stop = nullptr);

}  // namespace loopgate
