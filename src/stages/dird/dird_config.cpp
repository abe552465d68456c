#include "stages/dird/dird_config.hpp"

#include <cmath>

#include "core/error.hpp"

namespace loopgate {

void DirdConfig::validate() const {
  if (!std::isfinite(mu)) throw ConfigError("dird.mu: must be a finite number");
  if (!(std::isfinite(sigma) && sigma > 0.0)) throw ConfigError("dird.sigma: must be > 0");
  if (!(tau1 > 0.0 && tau1 < 1.0)) throw ConfigError("dird.tau1: must be in (0, 1)");
  if (l2_metric() && mu == kDirdReferenceMuL1 && sigma == kDirdReferenceSigmaL1) {
    throw ConfigError(
        "dird.mu/dird.sigma: metric l2 needs its own logistic constants (the defaults are the L1 reference "
        "values); calibrate them with `loopgate calibrate` (order of magnitude: mu ~ 644, sigma ~ 68)");
  }
}

}  // namespace loopgate
