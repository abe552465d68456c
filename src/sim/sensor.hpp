// The camera sensor of the lamps night model (illumination.night_model = lamps): per-frame auto-exposure
// (exposure time first, then analogue gain, within limits) and noise that follows the signal (photon shot
// noise + read noise), then gamma, quantisation and clipping to 8 bits. Section "sensor".
//
// Units. Scene radiance is that of the illumination model (albedo x irradiance, a day surface ~0.1-0.8).
// The exposure scale k = exposure_time x gain multiplies it into the linear signal S = 255 k radiance in
// linear grey levels (DN, 255 = full scale); exposure_time is in the units of illumination.day_exposure
// (a radiance multiplier at gain 1). At gain g the full scale holds full_well_e / g electrons, so the
// conversion is G = 255 g / full_well_e DN per electron and the noise of a pixel, in linear DN, has variance
//   var(S) = G S + (G read_noise_e)^2
// (Poisson shot noise in its Gaussian approximation, plus read noise before the gain: the photon transfer
// curve). The noisy S is clipped to [0, 255], gamma-encoded (illumination.gamma), rounded to 8 bits.
#pragma once

#include <cstddef>
#include <vector>

namespace loopgate::sim {

struct SensorConfig {
  double full_well_e = 5000.0;  // electrons at full scale at gain 1
  double read_noise_e = 4.0;    // read noise std-dev in electrons (before the gain)
  // Auto-exposure: the mean display grey level (0..255, after clipping and gamma, before noise) it aims at,
  // with exposure_time in [ae_min_exposure, ae_max_exposure] raised first, then the gain in [1, ae_max_gain].
  double ae_target_grey = 130.0;
  double ae_min_exposure = 0.05;
  double ae_max_exposure = 2.0;
  double ae_max_gain = 8.0;
  int ae_metering_stride_px = 4;  // the metering reads every N-th pixel of every N-th row

  // The keys, in order, for loading, printing and the JSON echo (Self is SensorConfig or const SensorConfig).
  template <class Self, class V>
  static void fields(Self& self, V&& v) {
    v("full_well_e", self.full_well_e);
    v("read_noise_e", self.read_noise_e);
    v("ae_target_grey", self.ae_target_grey);
    v("ae_min_exposure", self.ae_min_exposure);
    v("ae_max_exposure", self.ae_max_exposure);
    v("ae_max_gain", self.ae_max_gain);
    v("ae_metering_stride_px", self.ae_metering_stride_px);
  }
  void validate() const;  // throws loopgate::ConfigError naming the key
};

// What the auto-exposure chose for a frame.
struct SensorExposure {
  double exposure_time = 1.0;  // in [ae_min_exposure, ae_max_exposure]
  double gain = 1.0;           // analogue gain in [1, ae_max_gain]
  double scale() const { return exposure_time * gain; }
  // Linear DN (0..255 full scale) per electron at this gain.
  double dn_per_electron(const SensorConfig& sensor) const { return 255.0 * gain / sensor.full_well_e; }
};

// Mean display grey (0..255) of the radiance samples under exposure scale k: 255 clamp(k L, 0, 1)^(1/gamma).
double metered_grey(const std::vector<float>& radiance_samples, double k, double gamma);

// The exposure whose metered grey is closest to ae_target_grey within the limits (the brightest allowed
// when even that stays below the target, the darkest when even that is above). Deterministic.
SensorExposure auto_exposure(const std::vector<float>& radiance_samples, const SensorConfig& sensor,
                             double gamma);

// Std-dev (linear DN) of the sensor noise at linear signal signal_dn (clamped at 0) under `exposure`.
double sensor_noise_sigma_dn(double signal_dn, const SensorExposure& exposure, const SensorConfig& sensor);

}  // namespace loopgate::sim
