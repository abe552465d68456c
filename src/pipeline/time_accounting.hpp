// The run's time accounting (docs/architecture.md § Time accounting): where the run's thread time went, by
// kind of work rather than by graph node, so that `compare` puts the same work in the same row for every
// method. Unit: thread time in ms, i.e. each node body's wall time plus the time other threads spent in its
// parallel loops, summed over the frames, plus the end of the stream.
//
//   decode    the decode node, and every image decoded inside describe (a gated method reading a past
//             frame again, or its own frame when decode did not read it)
//   describe  the describe node without those reads: descriptors, SeqSLAM's preprocessing
//   match     the match node and the method's end-of-stream work (the matcher's flush, SeqSLAM's search)
//   rest      sync, odometry, gate, sink, and the end of the stream outside the method (loops.csv, loop
//             closure)
//   total     decode + describe + match + rest: every node's thread time plus the end of the stream
#pragma once

#include <array>
#include <nlohmann/json.hpp>

#include "pipeline/frame_record.hpp"

namespace loopgate {

// The end of the stream: the method's finish() (wall, and its parallel loops' helpers).
struct EndOfStreamTime {
  double method_ms = 0;
  double method_parallel_ms = 0;
};

// What the run measured, summed over the frames through the sink.
struct MeasuredTime {
  std::array<double, kStageCount> service_ms{};   // node bodies' wall time, per stage
  std::array<double, kStageCount> parallel_ms{};  // other threads' time in their parallel loops, per stage
  double decode_in_describe_ms = 0;               // images decoded inside describe (part of its thread time)
  double end_of_stream_ms = 0;                    // the whole end of the stream (wall)
  EndOfStreamTime end_of_stream;
};

struct TimeParts {
  double decode_ms = 0, describe_ms = 0, match_ms = 0, rest_ms = 0, total_ms = 0;
  double decode_in_describe_ms = 0;  // of decode_ms
  double parallel_ms = 0;            // of total_ms: helpers' time in parallel loops
};

TimeParts account_time(const MeasuredTime& measured);

// summary.json "time_accounting": {"unit", "decode_ms", "describe_ms", "match_ms", "rest_ms", "total_ms",
// "decode_in_describe_ms", "parallel_ms"}.
nlohmann::json time_accounting_json(const TimeParts& parts);

}  // namespace loopgate
