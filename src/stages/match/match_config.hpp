// Configuration of the sequence matching and non-maximum suppression (docs/detection.md § The paper's
// matcher).
#pragma once

namespace loopgate {

struct MatchConfig {
  // Safety margin in frames: only pairs (j, i) with i - j >= margin are compared (single-sequence mode).
  // Reference 200 for KITTI-like driving at 10 Hz; about 10-20 for EuRoC at 20 Hz.
  int margin = 200;
  // L: number of consecutive current frames a matched sequence spans (20 for KITTI, ~10 for EuRoC).
  int sequence_length = 20;
  // A DP value is kept when DP > tau3 * L (1.0 for the KITTI reference values).
  double tau3 = 0.05;
  // Per step back in i, the earlier index j moves back by 0..max_step frames.
  int max_step = 3;
  // NMS window: values M(j - k, i + k), k = -nms_half_window..nms_half_window, along the anti-diagonal.
  int nms_half_window = 59;

  // The keys, in order, for loading, printing and the JSON echo (Self is MatchConfig or const MatchConfig).
  template <class Self, class V>
  static void fields(Self& self, V&& v) {
    v("margin", self.margin);
    v("sequence_length", self.sequence_length);
    v("tau3", self.tau3);
    v("max_step", self.max_step);
    v("nms_half_window", self.nms_half_window);
  }
  // Throws ConfigError naming the key and its bounds: margin in [0, 1e6], sequence_length in [1, 1000],
  // tau3 in [0, 1], max_step in [0, 100], nms_half_window in [0, 1000].
  void validate() const;

  double dp_threshold() const { return tau3 * static_cast<double>(sequence_length); }
};

}  // namespace loopgate
