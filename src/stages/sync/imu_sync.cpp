#include "stages/sync/imu_sync.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "core/error.hpp"

namespace loopgate {

void SyncConfig::validate() const {
  if (!(max_gap_ms > 0 && max_gap_ms <= 60'000)) {
    throw ConfigError("sync.max_gap_ms: must be in (0, 60000] ms (got " + std::to_string(max_gap_ms) + ")");
  }
}

const char* to_string(ImuAnomaly::Kind kind) {
  switch (kind) {
    case ImuAnomaly::Kind::kGap: return "gap";
    case ImuAnomaly::Kind::kOutOfOrder: return "out-of-order";
    case ImuAnomaly::Kind::kDuplicate: return "duplicate";
  }
  return "unknown";
}

std::string ImuAnomaly::to_string() const {
  char buffer[160];
  switch (kind) {
    case Kind::kGap:
      std::snprintf(buffer, sizeof(buffer), "IMU gap of %.3f s (%.6f -> %.6f s, sample %zu)",
                    ns_to_s(t_ns - ref_t_ns), ns_to_s(ref_t_ns), ns_to_s(t_ns), index);
      break;
    case Kind::kOutOfOrder:
      std::snprintf(buffer, sizeof(buffer), "IMU sample %zu out of order (%.6f s after %.6f s), dropped",
                    index, ns_to_s(t_ns), ns_to_s(ref_t_ns));
      break;
    case Kind::kDuplicate:
      std::snprintf(buffer, sizeof(buffer), "IMU sample %zu duplicates time %.6f s, dropped", index,
                    ns_to_s(t_ns));
      break;
  }
  return buffer;
}

ImuSynchronizer::ImuSynchronizer(std::vector<ImuSample> samples_in_file_order, const SyncConfig& config)
    : config_(config) {
  config_.validate();
  const auto max_gap_ns = static_cast<Timestamp>(std::llround(config_.max_gap_ms * 1e6));
  clean_.reserve(samples_in_file_order.size());
  for (std::size_t i = 0; i < samples_in_file_order.size(); ++i) {
    const ImuSample& sample = samples_in_file_order[i];
    if (clean_.empty()) {
      clean_.push_back(sample);
      continue;
    }
    const Timestamp last_t_ns = clean_.back().t_ns;
    if (sample.t_ns <= last_t_ns) {
      ImuAnomaly anomaly;
      anomaly.kind = sample.t_ns == last_t_ns ? ImuAnomaly::Kind::kDuplicate : ImuAnomaly::Kind::kOutOfOrder;
      anomaly.t_ns = sample.t_ns;
      anomaly.ref_t_ns = last_t_ns;
      anomaly.index = i;
      anomalies_.push_back(anomaly);
      rejected_.push_back(anomaly);
      continue;
    }
    if (sample.t_ns - last_t_ns > max_gap_ns) {
      ImuAnomaly gap;
      gap.kind = ImuAnomaly::Kind::kGap;
      gap.t_ns = sample.t_ns;
      gap.ref_t_ns = last_t_ns;
      gap.index = i;
      anomalies_.push_back(gap);
      gaps_.push_back(gap);
    }
    clean_.push_back(sample);
  }
}

ImuSample ImuSynchronizer::interpolate_at(Timestamp t_ns) const {
  const auto it = std::lower_bound(clean_.begin(), clean_.end(), t_ns,
                                   [](const ImuSample& s, Timestamp t) { return s.t_ns < t; });
  if (it->t_ns == t_ns) return *it;
  const ImuSample& b = *it;
  const ImuSample& a = *(it - 1);
  const double alpha = static_cast<double>(t_ns - a.t_ns) / static_cast<double>(b.t_ns - a.t_ns);
  ImuSample out;
  out.t_ns = t_ns;
  out.gyro_radps = a.gyro_radps + alpha * (b.gyro_radps - a.gyro_radps);
  out.accel_mps2 = a.accel_mps2 + alpha * (b.accel_mps2 - a.accel_mps2);
  return out;
}

SyncedImu ImuSynchronizer::next(Timestamp t_image_ns) {
  if (started_ && t_image_ns <= t_prev_ns_) {
    throw std::invalid_argument("ImuSynchronizer::next: image time " + std::to_string(t_image_ns) +
                                " ns does not increase (previous " + std::to_string(t_prev_ns_) + " ns)");
  }
  SyncedImu out;
  out.t_prev_ns = started_ ? t_prev_ns_ : t_image_ns;
  out.t_image_ns = t_image_ns;
  const bool first = !started_;
  started_ = true;
  t_prev_ns_ = t_image_ns;
  if (clean_.empty()) return out;

  SyncReport& report = out.report;
  // Rejected samples found while the stream was inside this interval.
  while (rejected_cursor_ < rejected_.size() && rejected_[rejected_cursor_].ref_t_ns <= t_image_ns) {
    const ImuAnomaly& anomaly = rejected_[rejected_cursor_++];
    if (!first && anomaly.ref_t_ns <= out.t_prev_ns) continue;  // belonged to a frame dropped upstream
    (anomaly.kind == ImuAnomaly::Kind::kDuplicate ? report.duplicates : report.out_of_order)++;
    report.messages.push_back(anomaly.to_string());
  }
  // Gaps overlapping [t_prev, t_image] (a point interval for the first frame).
  while (gap_cursor_ < gaps_.size() && gaps_[gap_cursor_].t_ns <= out.t_prev_ns) ++gap_cursor_;
  for (std::size_t g = gap_cursor_; g < gaps_.size() && gaps_[g].ref_t_ns < t_image_ns; ++g) {
    const ImuAnomaly& gap = gaps_[g];
    if (gap.t_ns <= out.t_prev_ns) continue;
    ++report.gaps;
    report.max_gap_s = std::max(report.max_gap_s, ns_to_s(gap.t_ns - gap.ref_t_ns));
    report.messages.push_back(gap.to_string());
  }

  if (clean_.front().t_ns > out.t_prev_ns || clean_.back().t_ns < t_image_ns) {
    report.imu_missing = true;
    report.messages.push_back("IMU does not cover the frame interval");
    return out;
  }
  out.samples.push_back(interpolate_at(out.t_prev_ns));
  if (first) return out;
  auto it = std::upper_bound(clean_.begin(), clean_.end(), out.t_prev_ns,
                             [](Timestamp t, const ImuSample& s) { return t < s.t_ns; });
  for (; it != clean_.end() && it->t_ns < t_image_ns; ++it) out.samples.push_back(*it);
  out.samples.push_back(interpolate_at(t_image_ns));
  return out;
}

}  // namespace loopgate
