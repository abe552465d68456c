#include "stages/match/match_config.hpp"

#include <cmath>

#include "core/error.hpp"

namespace loopgate {

void MatchConfig::validate() const {
  if (margin < 0) throw ConfigError("match.margin: must be >= 0 frames");
  if (sequence_length < 1) throw ConfigError("match.sequence_length: must be >= 1");
  if (!(std::isfinite(tau3) && tau3 >= 0.0)) throw ConfigError("match.tau3: must be a finite number >= 0");
  if (max_step < 0) throw ConfigError("match.max_step: must be >= 0");
  if (nms_half_window < 0) throw ConfigError("match.nms_half_window: must be >= 0");
}

}  // namespace loopgate
