// The run's time accounting (docs/architecture.md § Time accounting): where the run's work went, by kind of
// work rather than by graph node, so that `compare` puts the same work in the same row for every method.
// Unit: thread CPU time in ms (CLOCK_THREAD_CPUTIME_ID), so that a loaded machine does not inflate one column
// more than another: each node body's CPU time on its thread, plus the CPU time other threads spent in the
// tasks of its parallel loops, summed over the frames, plus the end of the stream on the calling thread.
//
//   decode    the decode node, and every image decoded inside describe (a gated method reading a past
//             frame again, or its own frame when decode did not read it)
//   describe  the describe node without those reads and similarities: descriptors, SeqSLAM's preprocessing
//   match     the match node, the similarities computed inside describe (full DIRD's rows) and the method's
//             end-of-stream work (the matcher's flush, SeqSLAM's search)
//   rest      sync, odometry, gate, sink, and the end of the stream outside the method (loops.csv; the loop
//             closer's own thread, which verifies loops during the run, is not in the accounting)
//   total     decode + describe + match + rest
#pragma once

#include <array>
#include <cstdint>
#include <nlohmann/json.hpp>

#include "core/thread_cpu_time.hpp"
#include "pipeline/frame/frame_record.hpp"

namespace loopgate {

// What a frame's node bodies measured (FrameRecord), or its sum over frames.
struct StageTimes {
  std::array<double, kStageCount> cpu_ms{};       // the node body on its thread
  std::array<double, kStageCount> parallel_ms{};  // other threads in the body's parallel loops
  double decode_in_describe_ms = 0;               // images decoded inside describe (part of its CPU time)
  double match_in_describe_ms = 0;                // similarities computed inside describe (part of it too)
  double odometry_in_decode_ms = 0;               // the odometry's image preparation inside decode (too)
  StageTimes& operator+=(const StageTimes& other);
};
StageTimes stage_times(const FrameRecord& r);

// The end of the stream, on the calling thread: the method's finish() (and its parallel loops' helpers),
// then the rest (loops.csv, waiting for the loop closer).
struct EndOfStreamTime {
  double method_cpu_ms = 0;
  double method_parallel_ms = 0;
  double other_cpu_ms = 0;
};

struct TimeParts {
  double decode_ms = 0, describe_ms = 0, match_ms = 0, rest_ms = 0, total_ms = 0;
  double decode_in_describe_ms = 0;  // of decode_ms
  double match_in_describe_ms = 0;   // of match_ms
  double odometry_in_decode_ms = 0;  // of rest_ms: OdometrySource::prepare, run in the decode node
  double parallel_ms = 0;            // of total_ms: other threads in parallel loops
};

// A frame's parts (end = {}), or the run's (the frames' sum and the end of the stream).
TimeParts account_time(const StageTimes& frames, const EndOfStreamTime& end = {});

// summary.json "time_accounting": {"unit", "decode_ms", "describe_ms", "match_ms", "rest_ms", "total_ms",
// "decode_in_describe_ms", "match_in_describe_ms", "odometry_in_decode_ms", "parallel_ms", "stages_cpu_ms":
// {stage: ms}, "end_of_stream_cpu_ms"}.
nlohmann::json time_accounting_json(const StageTimes& frames, const EndOfStreamTime& end);

}  // namespace loopgate
