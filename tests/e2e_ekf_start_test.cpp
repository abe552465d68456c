// The ekf odometry must start from the sensors, or the run fails and says why: the real binary on a short
// simulated demo drive (a car that moves from its first frame, so that the static initialiser never finds
// the platform still). The run exits non-zero, the console names the reason with the initialiser's numbers,
// summary.json has failed: true, the reason in problems and the start in odometry_start, and every output
// is written.
#include <gtest/gtest.h>

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "test_support.hpp"

namespace loopgate {
namespace {

namespace fs = std::filesystem;

std::string run(const std::string& args, int* status) {
  std::string output;
  *status = testing::run_command("timeout 300 " + testing::loopgate_binary().string() + " " + args, &output);
  return output;
}

TEST(E2eEkfStart, OdometryThatNeverStartsFailsTheRunWithItsReason) {
  const fs::path sim = testing::make_temp_dir("e2e-ekf-start");
  int status = -1;
  std::string output =
      run("--log-level warn simulate --preset demo --frames 40 --force --out " + sim.string(), &status);
  ASSERT_EQ(status, 0) << output;
  const fs::path out = testing::make_temp_dir("e2e-ekf-start-out");
  output = run("--log-level warn run --dataset " + sim.string() + " --mode odometry --out " + out.string() +
                   " --set odometry.source=ekf --set ekf.init_mode=static --set ekf.max_init_s=1"
                   " --set output.progress=off",
               &status);
  EXPECT_NE(status, 0) << output;
  EXPECT_NE(output.find("run failed: no odometry: odometry.source ekf never started"), std::string::npos)
      << output;
  // The numbers behind it: the excitation and the image motion against their limits.
  EXPECT_NE(output.find("static: not still (image moving)"), std::string::npos) << output;
  EXPECT_NE(output.find("low-passed accelerometer spread"), std::string::npos) << output;
  EXPECT_NE(output.find("(limit 0.50 px)"), std::string::npos) << output;
  // Said while the run goes on, once max_init_s of data has passed.
  EXPECT_NE(output.find("ekf: not started after"), std::string::npos) << output;

  for (const char* name : {"frames.csv", "timing.csv", "trajectory.tum", "summary.json"})
    EXPECT_TRUE(fs::is_regular_file(out / name)) << name;
  EXPECT_EQ(testing::read_csv(out / "frames.csv").size(), 40u);
  const auto summary = nlohmann::json::parse(testing::read_file(out / "summary.json"));
  EXPECT_TRUE(summary["failed"].get<bool>());
  ASSERT_EQ(summary["problems"].size(), 1u) << summary["problems"];
  EXPECT_NE(summary["problems"][0].get<std::string>().find("never started"), std::string::npos);
  const auto& start = summary["odometry_start"];
  EXPECT_FALSE(start["started"].get<bool>());
  EXPECT_EQ(start["frames_seen"].get<int>(), 40);
  EXPECT_NE(start["status"].get<std::string>().find("image moving"), std::string::npos) << start;
}

// The same drive with the explicit ground-truth start: it starts at once and the run passes; summary.json
// says which initialiser ran, where, and what it estimated.
TEST(E2eEkfStart, AStartedRunReportsItsStart) {
  const fs::path sim = testing::make_temp_dir("e2e-ekf-start-gt");
  int status = -1;
  std::string output =
      run("--log-level warn simulate --preset demo --frames 40 --force --out " + sim.string(), &status);
  ASSERT_EQ(status, 0) << output;
  const fs::path out = testing::make_temp_dir("e2e-ekf-start-gt-out");
  output = run("--log-level warn run --dataset " + sim.string() + " --mode odometry --out " + out.string() +
                   " --set odometry.source=ekf --set ekf.init_mode=ground_truth --set output.progress=off",
               &status);
  ASSERT_EQ(status, 0) << output;
  const auto summary = nlohmann::json::parse(testing::read_file(out / "summary.json"));
  EXPECT_FALSE(summary["failed"].get<bool>());
  const auto& start = summary["odometry_start"];
  EXPECT_TRUE(start["started"].get<bool>()) << start;
  EXPECT_EQ(start["method"].get<std::string>(), "ground_truth");
  EXPECT_EQ(start["frame"].get<int>(), 0);
  EXPECT_GE(start["tracked_share"].get<double>(), 0.95) << start;
  EXPECT_EQ(start["state"]["up_in_imu_frame"].size(), 3u);
}

// Started from the sensors, the filter's world is its own; with its up along -y (odometry.ekf_up_axis) the
// trajectory differs from the z-up one by that rotation only, and the position + yaw ATE, which first turns
// the estimate's up onto the ground truth's, is the same. On the real V1_01 excerpt (skipped without it).
TEST(E2eEkfStart, AteDoesNotDependOnTheEstimatesUpAxis) {
  LOOPGATE_REQUIRE_SHARED_DATA("euroc/V1_01_easy_micro");
  const fs::path data = testing::shared_data_dir() / "euroc/V1_01_easy_micro";
  double rmse[2] = {-1.0, -1.0};
  const char* axes[2] = {"z", "-y"};
  for (int k = 0; k < 2; ++k) {
    const fs::path out = testing::make_temp_dir(std::string("e2e-ekf-start-up-") + (k == 0 ? "z" : "y"));
    int status = -1;
    const std::string output =
        run("--log-level warn run --dataset " + data.string() + " --mode odometry --out " + out.string() +
                " --set odometry.source=ekf --set output.progress=off --set odometry.ekf_up_axis=" + axes[k],
            &status);
    ASSERT_EQ(status, 0) << output;
    const auto summary = nlohmann::json::parse(testing::read_file(out / "summary.json"));
    EXPECT_EQ(summary["odometry_start"]["method"].get<std::string>(), "static");
    ASSERT_TRUE(summary["trajectory_accuracy"]["available"].get<bool>()) << summary["trajectory_accuracy"];
    rmse[k] = summary["trajectory_accuracy"]["rmse_m"].get<double>();
  }
  EXPECT_LT(rmse[0], 0.01);
  EXPECT_NEAR(rmse[0], rmse[1], 1e-6);
}

}  // namespace
}  // namespace loopgate
