// The photon sensor's auto-exposure (exposure time first, then gain, within limits) and its noise model
// (sim/sensor.hpp); the noise measured through the renderer is in sim_lights_test.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "core/error.hpp"
#include "sim/sensor.hpp"

namespace loopgate::sim {
namespace {

TEST(Sensor, AutoExposureMeetsTheTargetWithinItsLimits) {
  SensorConfig sensor;
  sensor.validate();
  const double gamma = 2.2;
  // Day: a mid-grey scene reaches the target at a short exposure and gain 1.
  const std::vector<float> day(1000, 0.2f);
  const SensorExposure e_day = auto_exposure(day, sensor, gamma);
  EXPECT_NEAR(metered_grey(day, e_day.scale(), gamma), sensor.ae_target_grey, 0.5);
  EXPECT_DOUBLE_EQ(e_day.gain, 1.0);
  EXPECT_LT(e_day.exposure_time, sensor.ae_max_exposure);
  // Dusk: the longest exposure is not enough, the gain rises.
  const std::vector<float> dusk(1000, 0.02f);
  const SensorExposure e_dusk = auto_exposure(dusk, sensor, gamma);
  EXPECT_DOUBLE_EQ(e_dusk.exposure_time, sensor.ae_max_exposure);
  EXPECT_GT(e_dusk.gain, 1.0);
  EXPECT_LT(e_dusk.gain, sensor.ae_max_gain);
  EXPECT_NEAR(metered_grey(dusk, e_dusk.scale(), gamma), sensor.ae_target_grey, 0.5);
  // Night: the limits: the longest exposure at the highest gain, darker than the target.
  const std::vector<float> night(1000, 0.001f);
  const SensorExposure e_night = auto_exposure(night, sensor, gamma);
  EXPECT_DOUBLE_EQ(e_night.exposure_time, sensor.ae_max_exposure);
  EXPECT_DOUBLE_EQ(e_night.gain, sensor.ae_max_gain);
  EXPECT_LT(metered_grey(night, e_night.scale(), gamma), sensor.ae_target_grey);
  // Too bright: the shortest exposure.
  const std::vector<float> glare(1000, 100.0f);
  EXPECT_DOUBLE_EQ(auto_exposure(glare, sensor, gamma).exposure_time, sensor.ae_min_exposure);
  // Noise model.
  EXPECT_NEAR(sensor_noise_sigma_dn(100.0, e_night, sensor),
              std::sqrt(e_night.dn_per_electron(sensor) * 100.0 +
                        std::pow(e_night.dn_per_electron(sensor) * sensor.read_noise_e, 2)),
              1e-12);
  sensor.ae_max_gain = 0.5;
  EXPECT_THROW(sensor.validate(), ConfigError);
}

}  // namespace
}  // namespace loopgate::sim
