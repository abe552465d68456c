#include "pipeline/time_accounting.hpp"

namespace loopgate {

TimeParts account_time(const MeasuredTime& m) {
  const auto thread_ms = [&](Stage s) { return m.service_ms[s] + m.parallel_ms[s]; };
  TimeParts parts;
  parts.decode_in_describe_ms = m.decode_in_describe_ms;
  parts.decode_ms = thread_ms(kDecode) + m.decode_in_describe_ms;
  parts.describe_ms = thread_ms(kDescribe) - m.decode_in_describe_ms;
  parts.match_ms = thread_ms(kMatch) + m.end_of_stream.method_ms + m.end_of_stream.method_parallel_ms;
  parts.rest_ms = thread_ms(kSync) + thread_ms(kOdometry) + thread_ms(kGate) + thread_ms(kSink) +
                  (m.end_of_stream_ms - m.end_of_stream.method_ms);
  parts.total_ms = parts.decode_ms + parts.describe_ms + parts.match_ms + parts.rest_ms;
  parts.parallel_ms = m.end_of_stream.method_parallel_ms;
  for (const double ms : m.parallel_ms) parts.parallel_ms += ms;
  return parts;
}

nlohmann::json time_accounting_json(const TimeParts& parts) {
  return {
      {"unit",
       "thread time (ms): node bodies' wall time plus other threads' time in their parallel loops, summed "
       "over frames, plus the end of the stream; decode includes the images decoded inside describe, "
       "match the method's end-of-stream work"},
      {"decode_ms", parts.decode_ms},
      {"describe_ms", parts.describe_ms},
      {"match_ms", parts.match_ms},
      {"rest_ms", parts.rest_ms},
      {"total_ms", parts.total_ms},
      {"decode_in_describe_ms", parts.decode_in_describe_ms},
      {"parallel_ms", parts.parallel_ms}};
}

}  // namespace loopgate
