// The definition of a revisit, shared by every setting that decides whether two frames may show the same
// place again: the pose gate (gate.min_travel_m), the evaluation (eval.min_travel_m), the ground truth of the
// evaluation library (ground_truth.min_travel_m) and the simulator's loop truth (loops.min_travel_m). A
// revisit needs at least min_travel_m of path between the two frames: standing still or hovering, a camera
// sees the place it has not left, and that is no loop. One struct, so that the four keys are bounded and
// reported alike.
#pragma once

#include <string>

#include "core/validate.hpp"

namespace loopgate {

struct RevisitRule {
  // Path length between the two frames of a revisit, in metres; 0 = no travel needed.
  double min_travel_m = 0.0;

  // Largest accepted value: far beyond any trajectory loopgate reads, so that no value can make a search
  // degenerate.
  static constexpr double kMaxTravelM = 1e6;

  // Throws ConfigError "KEY: must be in [0, 1e+06] m (0 = no travel needed) (got VALUE)" (NaN is out); `key`
  // is the full key, e.g. "gate.min_travel_m".
  void validate(const std::string& key) const {
    require_in(key, min_travel_m, 0.0, kMaxTravelM, "m (0 = no travel needed)");
  }
};

}  // namespace loopgate
