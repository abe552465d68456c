#include "stages/match/match_config.hpp"

#include <cmath>

#include "core/error.hpp"
#include "core/validate.hpp"

namespace loopgate {

void MatchConfig::validate() const {
  // Upper bounds: what makes sense for a sequence match (the NMS visits 2W+1 cells per DP entry and the DP
  // keeps L columns), far beyond any configuration in use, so that no value makes a run hang.
  require_in("match.margin", margin, 0, 1'000'000, "frames");
  require_in("match.sequence_length", sequence_length, 1, 1000, "frames");
  require_in("match.tau3", tau3, 0.0, 1.0, "(DP > tau3 * L; similarities are at most 1)");
  require_in("match.max_step", max_step, 0, 100, "frames");
  require_in("match.nms_half_window", nms_half_window, 0, 1000, "frames");
}

}  // namespace loopgate
