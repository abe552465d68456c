#include "stages/ekf/ekf_config.hpp"

#include <gtest/gtest.h>

#include <set>
#include <string>

#include "core/error.hpp"

namespace loopgate {
namespace {

TEST(EkfConfig, DefaultsAreValid) {
  EkfConfig config;
  EXPECT_NO_THROW(config.validate());
  EXPECT_EQ(config.window_size, 11);
  EXPECT_EQ(config.max_features, 150);
  EXPECT_DOUBLE_EQ(config.chi2_quantile, 0.95);
  EXPECT_EQ(config.init_mode, "ground_truth");
  EXPECT_EQ(config.klt_check_pyramid_levels, 0);
}

TEST(EkfConfig, VisitorSeesEveryKeyOnce) {
  EkfConfig config;
  std::set<std::string> keys;
  int count = 0;
  EkfConfig::fields(config, [&](const char* key, auto&) {
    keys.insert(key);
    ++count;
  });
  EXPECT_EQ(static_cast<int>(keys.size()), count);
  EXPECT_TRUE(keys.contains("window_size"));
  EXPECT_TRUE(keys.contains("init_mode"));
  EXPECT_TRUE(keys.contains("chi2_quantile"));
  EXPECT_TRUE(keys.contains("gyro_noise_density"));
}

TEST(EkfConfig, BadValuesNameTheKey) {
  auto message_of = [](const EkfConfig& c) {
    try {
      c.validate();
    } catch (const ConfigError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EkfConfig config;
  config.init_mode = "magic";
  const std::string m = message_of(config);
  EXPECT_NE(m.find("ekf.init_mode"), std::string::npos);
  EXPECT_NE(m.find("standstill"), std::string::npos);

  config = EkfConfig{};
  config.window_size = 1;
  EXPECT_NE(message_of(config).find("ekf.window_size"), std::string::npos);
  config = EkfConfig{};
  config.chi2_quantile = 0.05;  // the lower quantile would reject nearly everything
  EXPECT_NE(message_of(config).find("ekf.chi2_quantile"), std::string::npos);
  config = EkfConfig{};
  config.klt_window_px = 20;
  EXPECT_NE(message_of(config).find("ekf.klt_window_px"), std::string::npos);
  for (const int levels : {-2, 3}) {  // below -1, or more than the forward flow's klt_pyramid_levels (2)
    config = EkfConfig{};
    config.klt_check_pyramid_levels = levels;
    EXPECT_NE(message_of(config).find("ekf.klt_check_pyramid_levels"), std::string::npos) << levels;
  }
  config = EkfConfig{};
  config.klt_check_pyramid_levels = -1;  // the forward flow's levels
  EXPECT_EQ(message_of(config), "");
  config = EkfConfig{};
  config.accel_noise_density = -1.0;
  EXPECT_NE(message_of(config).find("ekf.accel_noise_density"), std::string::npos);
}

}  // namespace
}  // namespace loopgate
