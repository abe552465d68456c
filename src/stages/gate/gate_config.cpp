#include "stages/gate/gate_config.hpp"

#include <cmath>
#include <string>

#include "core/error.hpp"
#include "core/validate.hpp"

namespace loopgate {

void GateConfig::validate() const {
  // Upper bounds: far beyond any use, so that no value makes a run hang or exhaust memory.
  require_in("gate.gap_frames", gap_frames, 1, 1'000'000, "frames");
  revisit.validate("gate.min_travel_m");
  require_in("gate.beta_m", beta_m, 0.0, 1e5, "m");
  require_in("gate.confidence_scale", confidence_scale, 0.0, 1000.0);
  // The combined distance needs I + P_i + P_j positive definite: tolerating eigenvalues down to -0.25
  // keeps its smallest eigenvalue >= 0.5.
  if (!(std::isfinite(covariance_tolerance_m2) && covariance_tolerance_m2 >= 0.0 &&
        covariance_tolerance_m2 <= 0.25)) {
    throw ConfigError("gate.covariance_tolerance_m2: must be in [0, 0.25]");
  }
  require_in("gate.kdtree_leaf_size", kdtree_leaf_size, 1, 10'000);
  require_in("gate.kdtree_seed_neighbours", kdtree_seed_neighbours, 1, 1000);
  require_in("gate.area_max_hole_frames", area_max_hole_frames, 0, 10'000, "frames");
  require_in("gate.area_j_tolerance_frames", area_j_tolerance_frames, 0, 100'000, "frames");
  require_in("gate.area_margin_query_frames", area_margin_query_frames, 0, 10'000, "frames");
  require_in("gate.area_margin_reference_frames", area_margin_reference_frames, 0, 100'000, "frames");
  // A horizon beyond the run's length means "never final before the end" (what a batch comparison wants); the
  // rows it keeps open are bounded by the frames of the run, not by the value.
  require_in("gate.row_horizon_frames", row_horizon_frames, 0, 10'000'000, "frames");
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
