#include "stages/seqslam/seqslam_config.hpp"

#include <cmath>

#include "core/error.hpp"

namespace loopgate {

namespace {
// Tolerance when turning vmin * ds and vmax * ds into integer moves (0.8 * 10 is not exactly 8).
constexpr double kMoveTolerance = 1e-9;

void require(bool ok, const std::string& key, const std::string& what) {
  if (!ok) throw ConfigError("seqslam." + key + ": " + what);
}
}  // namespace

void SeqSlamConfig::validate() const {
  // Upper bounds: what makes sense for SeqSLAM's downsampled images and windows (no value may
  // make a run hang or exhaust memory).
  require(image_width_px > 0 && image_width_px <= 4096, "image_width_px", "must be in [1, 4096] px");
  require(image_height_px > 0 && image_height_px <= 4096, "image_height_px", "must be in [1, 4096] px");
  require(patch_size_px >= 0 && patch_size_px <= 4096, "patch_size_px",
          "must be in [0, 4096] px (0 disables patch normalisation)");
  require(patch_mean_grey >= 0.0 && patch_mean_grey <= 255.0, "patch_mean_grey", "must be in 0..255");
  require(contrast_window_rows >= 0 && contrast_window_rows <= 100'000 && contrast_window_rows % 2 == 0,
          "contrast_window_rows", "must be even and in [0, 100000]");
  require(sequence_length_frames >= 2 && sequence_length_frames <= 1000 && sequence_length_frames % 2 == 0,
          "sequence_length_frames", "must be even and in [2, 1000]");
  require(velocity_min > 0.0 && velocity_min <= 10.0, "velocity_min", "must be in (0, 10] frames per frame");
  require(velocity_max >= velocity_min && velocity_max <= 10.0, "velocity_max",
          "must be in [velocity_min, 10] frames per frame");
  require(!moves().empty(), "velocity_min",
          "no integer move in [velocity_min, velocity_max] * sequence_length_frames");
  require(second_best_window_rows >= 0 && second_best_window_rows <= 1'000'000 &&
              second_best_window_rows % 2 == 0,
          "second_best_window_rows", "must be even and in [0, 1000000]");
  require(ratio_threshold > 0.0 && ratio_threshold <= 1.0, "ratio_threshold",
          "must be in (0, 1] (best / second best)");
  require(exclusion_margin_frames >= 0 && exclusion_margin_frames <= 1'000'000, "exclusion_margin_frames",
          "must be in [0, 1000000] frames");
}

std::vector<int> SeqSlamConfig::moves() const {
  std::vector<int> result;
  const double ds = sequence_length_frames;
  const int first = static_cast<int>(std::ceil(velocity_min * ds - kMoveTolerance));
  const int last = static_cast<int>(std::floor(velocity_max * ds + kMoveTolerance));
  for (int move = first; move <= last; ++move) result.push_back(move);
  return result;
}

SeqSlamExclusion SeqSlamExclusion::from_config(const SeqSlamConfig& config) {
  const auto margin = static_cast<std::size_t>(config.exclusion_margin_frames);
  if (config.exclusion == Kind::kNone) return {Kind::kNone, 0};
  return {config.exclusion, margin};
}

}  // namespace loopgate
