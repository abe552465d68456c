// Timing helpers of the loop closer's files (loop_closer.hpp): milliseconds since a start, and the
// count / p50 / p90 / max / total of a list of times as summary.json gives them.
#pragma once

#include <algorithm>
#include <chrono>
#include <cstddef>
#include <nlohmann/json.hpp>
#include <numeric>
#include <vector>

namespace loopgate::loop_internal {

inline double ms_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

inline nlohmann::json stats_json(std::vector<double> values) {
  if (values.empty()) return {{"count", 0}, {"total_ms", 0.0}};
  std::sort(values.begin(), values.end());
  const auto at = [&](double q) {
    return values[std::min(values.size() - 1,
                           static_cast<std::size_t>(q * static_cast<double>(values.size())))];
  };
  return {{"count", values.size()},
          {"p50_ms", at(0.5)},
          {"p90_ms", at(0.9)},
          {"max_ms", values.back()},
          {"total_ms", std::accumulate(values.begin(), values.end(), 0.0)}};
}

}  // namespace loopgate::loop_internal
