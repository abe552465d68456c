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

// The samples of one series, kept compact: each as a float (4 bytes a frame instead of 8), with the count,
// total and maximum kept exactly in double. A float holds a duration to 6e-8 of itself, so the nearest whole
// nanosecond of a sample below 8 ms is the measured one (the stamps are whole nanoseconds): the percentiles
// are given as that.
class SampleSeries {
 public:
  void reserve(std::size_t n) { samples_.reserve(n); }
  void add(double ms);
  // Nearest-rank percentiles of the samples (each to the nanosecond as above), the exact maximum and total.
  LatencyStats stats() const;
  std::size_t size() const { return samples_.size(); }

 private:
  std::vector<float> samples_;
  double total_ms_ = 0, max_ms_ = 0;
};

class StageProfiler {
 public:
  // `expected_frames`: the samples each series may get (reserved: a vector's doubling would keep up to twice
  // its samples and copy them as it grows; untouched reserved pages take no memory).
  explicit StageProfiler(std::vector<std::string> stage_names, std::size_t expected_frames = 0);

  void add(std::size_t stage, double service_ms, double wait_ms);
  void add_latency(double latency_ms) { latency_ms_.add(latency_ms); }

  const std::vector<std::string>& stage_names() const { return names_; }
  LatencyStats service(std::size_t stage) const { return service_ms_[stage].stats(); }
  LatencyStats wait(std::size_t stage) const { return wait_ms_[stage].stats(); }
  LatencyStats latency() const { return latency_ms_.stats(); }

  // {"<stage>": {p50_ms, p90_ms, p99_ms, max_ms, total_ms, calls, wait_p50_ms, wait_p99_ms, wait_max_ms},
  //  "latency": {...}}
  nlohmann::json to_json() const;
  // A fixed-width table, one row per stage plus end-to-end latency; `wall_s` gives the busy share.
  std::string table(double wall_s) const;

 private:
  std::vector<std::string> names_;
  std::vector<SampleSeries> service_ms_;
  std::vector<SampleSeries> wait_ms_;
  SampleSeries latency_ms_;
};

}  // namespace loopgate
