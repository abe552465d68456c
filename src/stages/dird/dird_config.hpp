// Configuration of the DIRD descriptor and of its similarity (docs/detection.md § DIRD, the descriptor, and §
// The paper's matcher).
#pragma once

#include <span>

#include "core/enum_names.hpp"

namespace loopgate {

// dird.normalization: "libdird": per-pixel division by floor(sqrt(q)), bit-exact with the reference (pixels
// with floor(sqrt(q)) == 0 are invalid and zero their cell); "l2": division by sqrt(q), no invalid pixels.
enum class DirdNormalization { kLibdird, kL2 };
inline constexpr EnumName<DirdNormalization> kDirdNormalizationNames[] = {
    {DirdNormalization::kLibdird, "libdird"}, {DirdNormalization::kL2, "l2"}};
constexpr std::span<const EnumName<DirdNormalization>> enum_names(DirdNormalization) {
  return kDirdNormalizationNames;
}

// dird.resize: how the image becomes the 192 x 192 working image (see DirdConfig::resize).
enum class DirdResize { kNearest, kArea };
inline constexpr EnumName<DirdResize> kDirdResizeNames[] = {{DirdResize::kNearest, "nearest"},
                                                            {DirdResize::kArea, "area"}};
constexpr std::span<const EnumName<DirdResize>> enum_names(DirdResize) {
  return kDirdResizeNames;
}

// dird.metric: "l1" (sum of absolute byte differences, the reference) or "l2" (Euclidean).
enum class DirdMetric { kL1, kL2 };
inline constexpr EnumName<DirdMetric> kDirdMetricNames[] = {{DirdMetric::kL1, "l1"}, {DirdMetric::kL2, "l2"}};
constexpr std::span<const EnumName<DirdMetric>> enum_names(DirdMetric) {
  return kDirdMetricNames;
}

// Reference logistic constants of the original library for the L1 metric on full-resolution photographs
// in `libdird` mode: sim(d) = 1 / (1 + exp((d - mu) / sigma)).
constexpr double kDirdReferenceMuL1 = 70000.0 / 1.85;  // 37837.84
constexpr double kDirdReferenceSigmaL1 = 4000.0;
// Scale of the same logistic for the L2 metric under the assumption that the per-byte differences are of
// equal size (L2 = L1 / sqrt(3456)). This is only an order of magnitude: with metric l2, mu and sigma must
// be calibrated on the data (calibrate_logistic(), `loopgate calibrate`), validate() insists on it.
constexpr double kDirdScaleMuL2 = kDirdReferenceMuL1 / 58.787753826796276;        // ~643.6
constexpr double kDirdScaleSigmaL2 = kDirdReferenceSigmaL1 / 58.787753826796276;  // ~68.0

struct DirdConfig {
  // "libdird": per-pixel division by floor(sqrt(q)), bit-exact with the reference (pixels with
  // floor(sqrt(q)) == 0 are invalid and zero their cell). "l2": division by sqrt(q), no invalid pixels.
  DirdNormalization normalization = DirdNormalization::kLibdird;
  // Read the image bottom-up, as the reference command-line tool does.
  bool flip_vertical = false;
  // How the image becomes the 192 x 192 working image: "nearest" (docs/detection.md § DIRD, bit-exact with
  // the reference: one source pixel per working pixel, the others ignored) or "area" (each working pixel the
  // rounded mean of the source pixels its footprint covers: a box filter before sampling, which averages
  // sensor noise and aliasing away on images larger than 192 x 192; on smaller ones it is nearest
  // neighbour with integer index arithmetic). docs/illumination.md measures it.
  DirdResize resize = DirdResize::kNearest;
  // "l1" (sum of absolute byte differences, the reference) or "l2" (Euclidean).
  DirdMetric metric = DirdMetric::kL1;
  // Logistic similarity centre and scale, in distance units of `metric`.
  double mu = kDirdReferenceMuL1;
  double sigma = kDirdReferenceSigmaL1;
  // Sparse similarity: only entries with sim > tau1 are kept.
  double tau1 = 0.05;

  // The keys, in order, for loading, printing and the JSON echo (Self is DirdConfig or const DirdConfig).
  template <class Self, class V>
  static void fields(Self& self, V&& v) {
    v("normalization", self.normalization);
    v("flip_vertical", self.flip_vertical);
    v("resize", self.resize);
    v("metric", self.metric);
    v("mu", self.mu);
    v("sigma", self.sigma);
    v("tau1", self.tau1);
  }
  // Throws ConfigError naming the key: sigma > 0, finite mu, 0 < tau1 < 1, and with metric l2 mu/sigma must
  // not be the L1 reference values (the words of normalization, resize and metric are checked on loading).
  void validate() const;

  bool l2_normalization() const { return normalization == DirdNormalization::kL2; }
  bool area_resize() const { return resize == DirdResize::kArea; }
  bool l2_metric() const { return metric == DirdMetric::kL2; }
};

}  // namespace loopgate
