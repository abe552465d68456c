#include "stages/gate/gate_config.hpp"

#include <cmath>
#include <string>

#include "core/error.hpp"

namespace loopgate {

void GateConfig::validate() const {
  if (gap_frames < 1) throw ConfigError("gate.gap_frames: must be >= 1 frame");
  if (!(std::isfinite(beta_m) && beta_m >= 0.0))
    throw ConfigError("gate.beta_m: must be a finite number >= 0");
  if (sigma_norm != "max_eigen" && sigma_norm != "trace") {
    throw ConfigError("gate.sigma_norm: '" + sigma_norm + "' is not one of: max_eigen, trace");
  }
  if (!(std::isfinite(confidence_scale) && confidence_scale >= 0.0)) {
    throw ConfigError("gate.confidence_scale: must be a finite number >= 0");
  }
  // The combined distance needs I + P_i + P_j positive definite: tolerating eigenvalues down to -0.25
  // keeps its smallest eigenvalue >= 0.5.
  if (!(std::isfinite(covariance_tolerance_m2) && covariance_tolerance_m2 >= 0.0 &&
        covariance_tolerance_m2 <= 0.25)) {
    throw ConfigError("gate.covariance_tolerance_m2: must be in [0, 0.25]");
  }
  if (kdtree_leaf_size < 1) throw ConfigError("gate.kdtree_leaf_size: must be >= 1");
  if (kdtree_seed_neighbours < 1) throw ConfigError("gate.kdtree_seed_neighbours: must be >= 1");
  if (area_max_hole_frames < 0) throw ConfigError("gate.area_max_hole_frames: must be >= 0");
  if (area_j_tolerance_frames < 0) throw ConfigError("gate.area_j_tolerance_frames: must be >= 0");
  if (area_margin_query_frames < 0) throw ConfigError("gate.area_margin_query_frames: must be >= 0");
  if (area_margin_reference_frames < 0) throw ConfigError("gate.area_margin_reference_frames: must be >= 0");
}

void GateConfig::validate_for_sequence_length(int sequence_length) const {
  if (area_margin_query_frames < sequence_length) {
    throw ConfigError("gate.area_margin_query_frames: " + std::to_string(area_margin_query_frames) +
                      " must be >= the sequence length L = " + std::to_string(sequence_length) +
                      " (match.sequence_length) so the DP has its history when an area opens");
  }
  if (row_horizon_frames < area_margin_query_frames || row_horizon_frames < area_max_hole_frames + 1) {
    throw ConfigError("gate.row_horizon_frames: " + std::to_string(row_horizon_frames) +
                      " must be >= gate.area_margin_query_frames (" +
                      std::to_string(area_margin_query_frames) + ") and > gate.area_max_hole_frames (" +
                      std::to_string(area_max_hole_frames) + "): rows older than the horizon are final");
  }
}

}  // namespace loopgate
