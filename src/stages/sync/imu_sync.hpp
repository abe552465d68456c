// IMU/image synchronisation: for each image, the IMU samples since the previous image, with both ends
// interpolated (linearly) to the two image timestamps, and a per-frame report of the anomalies of the
// IMU stream (gaps, out-of-order and duplicate samples) that touch the frame's interval.
//
// The input is the IMU stream in file order (as a lenient dataset keeps it). It is cleaned once: a sample
// whose time is not after the last accepted one is rejected (equal time: duplicate; earlier: out of
// order); consecutive accepted samples further apart than `max_gap_ms` form a gap. Each rejected sample
// is reported by the frame whose interval (t_prev, t_image] holds the last accepted time before it (the
// first frame also reports everything before it); a gap is reported by every frame whose interval
// overlaps it.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "core/types.hpp"

namespace loopgate {

struct SyncConfig {
  double max_gap_ms = 20.0;  // consecutive IMU samples further apart than this form a gap

  // The keys, in order, for loading, printing and the JSON echo (Self is SyncConfig or const SyncConfig).
  template <class Self, class V>
  static void fields(Self& self, V&& v) {
    v("max_gap_ms", self.max_gap_ms);
  }
  void validate() const;
};

// One anomaly of the IMU stream.
struct ImuAnomaly {
  enum class Kind { kGap, kOutOfOrder, kDuplicate };
  Kind kind = Kind::kGap;
  Timestamp t_ns = 0;      // time of the offending sample (gap: its end)
  Timestamp ref_t_ns = 0;  // last accepted sample time before it (gap: its start)
  std::size_t index = 0;   // position of the offending sample in the input stream (0-based)
  std::string to_string() const;
};
const char* to_string(ImuAnomaly::Kind kind);

struct SyncReport {
  int gaps = 0;
  int out_of_order = 0;
  int duplicates = 0;
  bool imu_missing = false;  // the dataset has IMU but the interval is not covered by it
  double max_gap_s = 0;      // largest gap overlapping the interval
  std::vector<std::string> messages;

  bool ok() const { return gaps == 0 && out_of_order == 0 && duplicates == 0 && !imu_missing; }
};

struct SyncedImu {
  Timestamp t_prev_ns = 0;  // previous image time (== t_image_ns for the first frame)
  Timestamp t_image_ns = 0;
  // Samples in [t_prev, t_image], strictly increasing; the first is at t_prev and the last at t_image
  // (interpolated when no sample falls exactly there). Empty when the IMU does not cover the interval.
  std::vector<ImuSample> samples;
  SyncReport report;
};

class ImuSynchronizer {
 public:
  ImuSynchronizer(std::vector<ImuSample> samples_in_file_order, const SyncConfig& config);

  // Next image, in increasing time order (frames dropped upstream are simply not passed). Throws
  // std::invalid_argument when t_image_ns does not increase.
  SyncedImu next(Timestamp t_image_ns);

  bool has_imu() const { return !clean_.empty(); }
  const std::vector<ImuSample>& clean_samples() const { return clean_; }
  const std::vector<ImuAnomaly>& anomalies() const { return anomalies_; }

 private:
  ImuSample interpolate_at(Timestamp t_ns) const;  // requires coverage

  SyncConfig config_;
  std::vector<ImuSample> clean_;
  std::vector<ImuAnomaly> anomalies_;  // all, in stream order (sorted by ref_t_ns)
  std::vector<ImuAnomaly> rejected_;   // out-of-order and duplicates, sorted by ref_t_ns
  std::vector<ImuAnomaly> gaps_;       // gaps only, sorted by start
  std::size_t rejected_cursor_ = 0;
  std::size_t gap_cursor_ = 0;
  bool started_ = false;
  Timestamp t_prev_ns_ = 0;
};

}  // namespace loopgate
