#include "pipeline/outputs/stage_profiler.hpp"

#include <spdlog/fmt/fmt.h>

#include <algorithm>
#include <cmath>
#include <numeric>

namespace loopgate {

LatencyStats compute_stats(std::vector<double> samples_ms) {
  LatencyStats stats;
  stats.calls = samples_ms.size();
  if (samples_ms.empty()) return stats;
  std::sort(samples_ms.begin(), samples_ms.end());
  const auto rank = [&](double p) {
    const auto index =
        static_cast<std::size_t>(std::ceil(p / 100.0 * static_cast<double>(samples_ms.size())));
    return samples_ms[std::clamp<std::size_t>(index, 1, samples_ms.size()) - 1];
  };
  stats.p50_ms = rank(50);
  stats.p90_ms = rank(90);
  stats.p99_ms = rank(99);
  stats.max_ms = samples_ms.back();
  stats.total_ms = std::accumulate(samples_ms.begin(), samples_ms.end(), 0.0);
  return stats;
}

void SampleSeries::add(double ms) {
  samples_.push_back(static_cast<float>(ms));
  total_ms_ += ms;
  max_ms_ = samples_.size() == 1 ? ms : std::max(max_ms_, ms);
}

LatencyStats SampleSeries::stats() const {
  std::vector<double> samples_ms(samples_.size());
  // The nearest nanosecond of each float: the measured duration itself below 8 ms.
  std::transform(samples_.begin(), samples_.end(), samples_ms.begin(),
                 [](float ms) { return 1e-6 * std::round(1e6 * static_cast<double>(ms)); });
  LatencyStats stats = compute_stats(std::move(samples_ms));
  stats.total_ms = total_ms_;
  stats.max_ms = max_ms_;
  return stats;
}

StageProfiler::StageProfiler(std::vector<std::string> stage_names, std::size_t expected_frames)
    : names_(std::move(stage_names)), service_ms_(names_.size()), wait_ms_(names_.size()) {
  for (SampleSeries& s : service_ms_) s.reserve(expected_frames);
  for (SampleSeries& s : wait_ms_) s.reserve(expected_frames);
  latency_ms_.reserve(expected_frames);
}

void StageProfiler::add(std::size_t stage, double service_ms, double wait_ms) {
  service_ms_[stage].add(service_ms);
  wait_ms_[stage].add(wait_ms);
}

nlohmann::json StageProfiler::to_json() const {
  nlohmann::json json = nlohmann::json::object();
  const auto put = [](const LatencyStats& s) {
    return nlohmann::json{{"p50_ms", s.p50_ms}, {"p90_ms", s.p90_ms},     {"p99_ms", s.p99_ms},
                          {"max_ms", s.max_ms}, {"total_ms", s.total_ms}, {"calls", s.calls}};
  };
  for (std::size_t i = 0; i < names_.size(); ++i) {
    nlohmann::json entry = put(service(i));
    const LatencyStats w = wait(i);
    entry["wait_p50_ms"] = w.p50_ms;
    entry["wait_p99_ms"] = w.p99_ms;
    entry["wait_max_ms"] = w.max_ms;
    json[names_[i]] = entry;
  }
  json["latency"] = put(latency());
  return json;
}

std::string StageProfiler::table(double wall_s) const {
  std::string out = fmt::format("{:<10} {:>7} {:>9} {:>9} {:>9} {:>9} {:>11} {:>9} {:>6}\n", "stage", "calls",
                                "p50 ms", "p90 ms", "p99 ms", "max ms", "total ms", "wait p50", "busy");
  const auto row = [&](const std::string& name, const LatencyStats& s, double wait_p50, bool busy) {
    const double busy_pct = wall_s > 0 ? 100.0 * s.total_ms / (1000.0 * wall_s) : 0.0;
    out += fmt::format("{:<10} {:>7} {:>9.3f} {:>9.3f} {:>9.3f} {:>9.3f} {:>11.1f} {:>9.3f} {:>6}\n", name,
                       s.calls, s.p50_ms, s.p90_ms, s.p99_ms, s.max_ms, s.total_ms, wait_p50,
                       busy ? fmt::format("{:.0f}%", busy_pct) : std::string("-"));
  };
  for (std::size_t i = 0; i < names_.size(); ++i) row(names_[i], service(i), wait(i).p50_ms, true);
  row("latency", latency(), 0.0, false);
  return out;
}

}  // namespace loopgate
