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
  EXPECT_EQ(config.init_mode, EkfInitMode::kAuto);  // from the sensors, not from ground truth
  EXPECT_EQ(config.klt_check_pyramid_levels, 0);
}

TEST(EkfConfig, InitModeWordsIncludeTheOldStandstill) {
  EXPECT_EQ(enum_choices(EkfInitMode::kAuto), "auto|static|dynamic|ground_truth|standstill");
  EXPECT_EQ(enum_name(EkfInitMode::kStatic), "static");  // standstill reads as static, prints as static
  int standstill = 0;
  for (const auto& n : enum_names(EkfInitMode::kAuto))
    if (n.name == "standstill") standstill += n.value == EkfInitMode::kStatic ? 1 : 100;
  EXPECT_EQ(standstill, 1);
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
  EXPECT_TRUE(keys.contains("max_init_s"));
  EXPECT_TRUE(keys.contains("min_tracked_share"));
  EXPECT_TRUE(keys.contains("static_window_s"));
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
  config.static_lowpass_s = 0.6;  // two moving averages of it do not fit the 1 s window
  EXPECT_NE(message_of(config).find("ekf.static_lowpass_s"), std::string::npos);
  config = EkfConfig{};
  config.min_tracked_share = 1.5;
  EXPECT_NE(message_of(config).find("ekf.min_tracked_share"), std::string::npos);
  config = EkfConfig{};
  config.max_init_s = 0.0;
  EXPECT_NE(message_of(config).find("ekf.max_init_s"), std::string::npos);

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
