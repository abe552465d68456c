// SeqSLAM parameters (OpenSeqSLAM defaults, docs/detection.md § SeqSLAM) and the exclusion rule
// that keeps a run from matching itself.
#pragma once

#include <cstddef>
#include <span>
#include <vector>

#include "core/enum_names.hpp"

namespace loopgate {

// seqslam.resize_method: "lanczos3" (MATLAB imresize, antialiased) or "area" (OpenCV INTER_AREA).
enum class SeqSlamResize { kLanczos3, kArea };
inline constexpr EnumName<SeqSlamResize> kSeqSlamResizeNames[] = {{SeqSlamResize::kLanczos3, "lanczos3"},
                                                                  {SeqSlamResize::kArea, "area"}};
constexpr std::span<const EnumName<SeqSlamResize>> enum_names(SeqSlamResize) {
  return kSeqSlamResizeNames;
}

// seqslam.exclusion: which (reference, query) entries the search may use (see SeqSlamConfig::exclusion).
enum class SeqSlamExclusionKind { kNone, kBand, kPast };
inline constexpr EnumName<SeqSlamExclusionKind> kSeqSlamExclusionKindNames[] = {
    {SeqSlamExclusionKind::kNone, "none"},
    {SeqSlamExclusionKind::kBand, "band"},
    {SeqSlamExclusionKind::kPast, "past"}};
constexpr std::span<const EnumName<SeqSlamExclusionKind>> enum_names(SeqSlamExclusionKind) {
  return kSeqSlamExclusionKindNames;
}

struct SeqSlamConfig {
  // Step 1: preprocessing (grey -> resize -> patch normalisation).
  // Inputs already preprocessed (e.g. kitti/00/thumbs): only converted to grey and size-checked.
  bool input_preprocessed = false;
  int image_width_px = 64;
  int image_height_px = 32;
  SeqSlamResize resize_method = SeqSlamResize::kLanczos3;  // lanczos3 | area (SeqSlamResize)
  int patch_size_px = 8;           // non-overlapping blocks; 0 disables patch normalisation
  double patch_mean_grey = 127.0;  // normalised block = mean_grey + round((p - mean) / std)
  // Step 3: local contrast enhancement over rows r - R/2 .. r + R/2 of the same column.
  int contrast_window_rows = 10;
  // Step 4: sequence search.
  int sequence_length_frames = 10;  // ds: a sequence covers ds + 1 query frames centred on the query
  double velocity_min = 0.8;        // moves are the integers in [vmin * ds, vmax * ds]
  double velocity_max = 1.2;
  int second_best_window_rows = 10;  // Rwindow: second best is taken outside best +- Rwindow/2
  double ratio_threshold = 0.9;      // accepted when best / second <= threshold
  // Step 5: which (reference r, query q) entries the search may use.
  //   "none": every entry (two different runs);
  //   "band": entries with |r - q| < margin are excluded (same run seen twice, e.g. stereo pair);
  //   "past": single-sequence loop closure, only r <= q - margin is allowed (note that the sequence
  //           of query q spans query frames q - ds/2 .. q + ds/2, so its match is known ds/2 frames later).
  // Excluded entries are never computed, take no part in the contrast statistics, and score
  // +infinity in the search, so a sequence touching one cannot win.
  SeqSlamExclusionKind exclusion = SeqSlamExclusionKind::kNone;
  int exclusion_margin_frames = 100;

  // The keys, in order, for loading, printing and the JSON echo (Self is SeqSlamConfig or const
  // SeqSlamConfig).
  template <class Self, class V>
  static void fields(Self& self, V&& v) {
    v("input_preprocessed", self.input_preprocessed);
    v("image_width_px", self.image_width_px);
    v("image_height_px", self.image_height_px);
    v("resize_method", self.resize_method);
    v("patch_size_px", self.patch_size_px);
    v("patch_mean_grey", self.patch_mean_grey);
    v("contrast_window_rows", self.contrast_window_rows);
    v("sequence_length_frames", self.sequence_length_frames);
    v("velocity_min", self.velocity_min);
    v("velocity_max", self.velocity_max);
    v("second_best_window_rows", self.second_best_window_rows);
    v("ratio_threshold", self.ratio_threshold);
    v("exclusion", self.exclusion);
    v("exclusion_margin_frames", self.exclusion_margin_frames);
  }

  // Throws ConfigError naming the key and its bounds (the words of the choices are checked on loading).
  void validate() const;

  // The integer moves (frames of reference per ds query frames) of the velocity search.
  std::vector<int> moves() const;
};

// The exclusion rule of a config, applied per entry (reference row r, query column q).
class SeqSlamExclusion {
 public:
  using Kind = SeqSlamExclusionKind;

  SeqSlamExclusion() = default;
  SeqSlamExclusion(Kind kind, std::size_t margin_frames) : kind_(kind), margin_(margin_frames) {}
  static SeqSlamExclusion from_config(const SeqSlamConfig& config);

  bool excluded(std::size_t r, std::size_t q) const {
    switch (kind_) {
      case Kind::kNone: return false;
      case Kind::kBand: return (r > q ? r - q : q - r) < margin_;
      case Kind::kPast: return r + margin_ > q;
    }
    return false;
  }
  Kind kind() const { return kind_; }
  std::size_t margin_frames() const { return margin_; }

 private:
  Kind kind_ = Kind::kNone;
  std::size_t margin_ = 0;
};

}  // namespace loopgate
