// Per-stage timing statistics gathered by the pipeline (not by the stages): service time (enter to
// exit of a node body), queue wait (exit of the previous node to enter of this one) and end-to-end
// latency (release by the source to exit of the sink), as percentiles, totals and a text table.
#pragma once

#include <cstddef>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace loopgate {

struct LatencyStats {
  std::size_t calls = 0;
  double p50_ms = 0, p90_ms = 0, p99_ms = 0, max_ms = 0, total_ms = 0;
};

// Nearest-rank percentiles of `samples_ms` (copied and sorted).
LatencyStats compute_stats(std::vector<double> samples_ms);

class StageProfiler {
 public:
  explicit StageProfiler(std::vector<std::string> stage_names);

  void add(std::size_t stage, double service_ms, double wait_ms);
  void add_latency(double latency_ms) { latency_ms_.push_back(latency_ms); }

  const std::vector<std::string>& stage_names() const { return names_; }
  LatencyStats service(std::size_t stage) const { return compute_stats(service_ms_[stage]); }
  LatencyStats wait(std::size_t stage) const { return compute_stats(wait_ms_[stage]); }
  LatencyStats latency() const { return compute_stats(latency_ms_); }

  // {"<stage>": {p50_ms, p90_ms, p99_ms, max_ms, total_ms, calls, wait_p50_ms, wait_p99_ms, wait_max_ms},
  //  "latency": {...}}
  nlohmann::json to_json() const;
  // A fixed-width table, one row per stage plus end-to-end latency; `wall_s` gives the busy share.
  std::string table(double wall_s) const;

 private:
  std::vector<std::string> names_;
  std::vector<std::vector<double>> service_ms_;
  std::vector<std::vector<double>> wait_ms_;
  std::vector<double> latency_ms_;
};

}  // namespace loopgate
