#include "sim/sensor.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include "core/error.hpp"

namespace loopgate::sim {
namespace {

constexpr int kMeterLutSize = 4096;  // linear [0, 1] -> display grey, for the metering
constexpr int kBisectionSteps = 18;  // on log k: the range of k is below e^10, so 10 / 2^18 ~ 4e-5
constexpr double kTargetToleranceGrey = 0.05;

void require(bool ok, const std::string& key, const std::string& what, double value) {
  if (!ok) throw ConfigError("sensor." + key + ": must be " + what + " (got " + std::to_string(value) + ")");
}

class MeterLut {
 public:
  explicit MeterLut(double gamma) : lut_(kMeterLutSize + 1) {
    for (int k = 0; k <= kMeterLutSize; ++k) {
      lut_[static_cast<std::size_t>(k)] =
          255.0 * std::pow(static_cast<double>(k) / kMeterLutSize, 1.0 / gamma);
    }
  }
  double mean(const std::vector<float>& samples, double k) const {
    if (samples.empty()) return 0.0;
    double sum = 0.0;
    for (const float s : samples) {
      const double x = std::clamp(k * static_cast<double>(s), 0.0, 1.0);
      sum += lut_[static_cast<std::size_t>(x * kMeterLutSize)];
    }
    return sum / static_cast<double>(samples.size());
  }

 private:
  std::vector<double> lut_;
};

}  // namespace

void SensorConfig::validate() const {
  require(full_well_e > 0.0, "full_well_e", "> 0", full_well_e);
  require(read_noise_e >= 0.0, "read_noise_e", ">= 0", read_noise_e);
  require(ae_target_grey > 0.0 && ae_target_grey < 255.0, "ae_target_grey", "in (0, 255)", ae_target_grey);
  require(ae_min_exposure > 0.0, "ae_min_exposure", "> 0", ae_min_exposure);
  require(ae_max_exposure >= ae_min_exposure, "ae_max_exposure", ">= ae_min_exposure", ae_max_exposure);
  require(ae_max_gain >= 1.0, "ae_max_gain", ">= 1", ae_max_gain);
  require(std::log(ae_max_exposure * ae_max_gain / ae_min_exposure) < 10.0, "ae_max_exposure",
          "such that ae_max_exposure * ae_max_gain / ae_min_exposure < e^10", ae_max_exposure);
  require(ae_metering_stride_px >= 1, "ae_metering_stride_px", ">= 1", ae_metering_stride_px);
}

double metered_grey(const std::vector<float>& radiance_samples, double k, double gamma) {
  if (radiance_samples.empty()) return 0.0;
  double sum = 0.0;
  for (const float s : radiance_samples) {
    sum += 255.0 * std::pow(std::clamp(k * static_cast<double>(s), 0.0, 1.0), 1.0 / gamma);
  }
  return sum / static_cast<double>(radiance_samples.size());
}

SensorExposure auto_exposure(const std::vector<float>& radiance_samples, const SensorConfig& sensor,
                             double gamma) {
  const MeterLut meter(gamma);
  const double target = sensor.ae_target_grey;
  SensorExposure exposure;
  if (meter.mean(radiance_samples, sensor.ae_max_exposure * sensor.ae_max_gain) <= target) {
    // Too dark even at the longest exposure and the highest gain: the limits.
    exposure.exposure_time = sensor.ae_max_exposure;
    exposure.gain = sensor.ae_max_gain;
    return exposure;
  }
  if (meter.mean(radiance_samples, sensor.ae_min_exposure) >= target) {
    exposure.exposure_time = sensor.ae_min_exposure;  // too bright even at the shortest exposure
    return exposure;
  }
  double lo = std::log(sensor.ae_min_exposure);
  double hi = std::log(sensor.ae_max_exposure * sensor.ae_max_gain);
  for (int step = 0; step < kBisectionSteps; ++step) {
    const double mid = 0.5 * (lo + hi);
    const double grey = meter.mean(radiance_samples, std::exp(mid));
    if (std::abs(grey - target) < kTargetToleranceGrey) {
      lo = hi = mid;
      break;
    }
    (grey < target ? lo : hi) = mid;
  }
  // Exposure time first, then gain.
  const double k = std::exp(0.5 * (lo + hi));
  exposure.exposure_time = std::clamp(k, sensor.ae_min_exposure, sensor.ae_max_exposure);
  exposure.gain = std::clamp(k / exposure.exposure_time, 1.0, sensor.ae_max_gain);
  return exposure;
}

double sensor_noise_sigma_dn(double signal_dn, const SensorExposure& exposure, const SensorConfig& sensor) {
  const double g = exposure.dn_per_electron(sensor);
  const double read_dn = g * sensor.read_noise_e;
  return std::sqrt(g * std::max(0.0, signal_dn) + read_dn * read_dn);
}

}  // namespace loopgate::sim
