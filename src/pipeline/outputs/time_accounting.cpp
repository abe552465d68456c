#include "pipeline/outputs/time_accounting.hpp"

namespace loopgate {

StageTimes& StageTimes::operator+=(const StageTimes& other) {
  for (std::size_t s = 0; s < kStageCount; ++s) {
    cpu_ms[s] += other.cpu_ms[s];
    parallel_ms[s] += other.parallel_ms[s];
  }
  decode_in_describe_ms += other.decode_in_describe_ms;
  match_in_describe_ms += other.match_in_describe_ms;
  odometry_in_decode_ms += other.odometry_in_decode_ms;
  return *this;
}

StageTimes stage_times(const FrameRecord& r) {
  StageTimes t;
  for (std::size_t s = 0; s < kStageCount; ++s) {
    t.cpu_ms[s] = 1e-6 * static_cast<double>(r.cpu_ns[s]);
    t.parallel_ms[s] = 1e-6 * static_cast<double>(r.parallel_cpu_ns[s].load(std::memory_order_relaxed));
  }
  t.decode_in_describe_ms = 1e-6 * static_cast<double>(r.reread_cpu_ns.load(std::memory_order_relaxed));
  t.match_in_describe_ms = 1e-6 * static_cast<double>(r.match_in_describe_cpu_ns);
  t.odometry_in_decode_ms = 1e-6 * static_cast<double>(r.odometry_in_decode_cpu_ns);
  return t;
}

TimeParts account_time(const StageTimes& m, const EndOfStreamTime& end) {
  const auto stage_ms = [&](Stage s) { return m.cpu_ms[s] + m.parallel_ms[s]; };
  TimeParts parts;
  parts.decode_in_describe_ms = m.decode_in_describe_ms;
  parts.match_in_describe_ms = m.match_in_describe_ms;
  parts.odometry_in_decode_ms = m.odometry_in_decode_ms;
  parts.decode_ms = stage_ms(kDecode) - m.odometry_in_decode_ms + m.decode_in_describe_ms;
  parts.describe_ms = stage_ms(kDescribe) - m.decode_in_describe_ms - m.match_in_describe_ms;
  parts.match_ms = stage_ms(kMatch) + m.match_in_describe_ms + end.method_cpu_ms + end.method_parallel_ms;
  parts.rest_ms = stage_ms(kSync) + stage_ms(kOdometry) + m.odometry_in_decode_ms + stage_ms(kGate) +
                  stage_ms(kSink) + end.other_cpu_ms;
  parts.total_ms = parts.decode_ms + parts.describe_ms + parts.match_ms + parts.rest_ms;
  parts.parallel_ms = end.method_parallel_ms;
  for (const double ms : m.parallel_ms) parts.parallel_ms += ms;
  return parts;
}

nlohmann::json time_accounting_json(const StageTimes& frames, const EndOfStreamTime& end) {
  const TimeParts parts = account_time(frames, end);
  nlohmann::json stages = nlohmann::json::object();
  for (std::size_t s = 0; s < kStageCount; ++s) stages[kStageNames[s]] = frames.cpu_ms[s];
  return {{"unit",
           "thread CPU time (ms): node bodies on their threads plus other threads in their parallel loops, "
           "summed over frames, plus the end of the stream; decode includes the images decoded inside "
           "describe, match the similarities computed inside describe and the method's end-of-stream work, "
           "rest the odometry's image preparation done in the decode node"},
          {"decode_ms", parts.decode_ms},
          {"describe_ms", parts.describe_ms},
          {"match_ms", parts.match_ms},
          {"rest_ms", parts.rest_ms},
          {"total_ms", parts.total_ms},
          {"decode_in_describe_ms", parts.decode_in_describe_ms},
          {"match_in_describe_ms", parts.match_in_describe_ms},
          {"odometry_in_decode_ms", parts.odometry_in_decode_ms},
          {"parallel_ms", parts.parallel_ms},
          {"stages_cpu_ms", stages},
          {"end_of_stream_cpu_ms", end.method_cpu_ms + end.other_cpu_ms}};
}

}  // namespace loopgate
