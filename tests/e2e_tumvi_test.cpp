// TUM-VI's layout end to end: a simulated EuRoC tree rewritten the TUM-VI way (ground truth in
// mav0/mocap0/data.csv, calibration in Kalibr files dso/camchain.yaml and dso/imu_config.yaml, no
// state_groundtruth_estimate0 and no sensor.yaml) runs with ground truth and the EKF, and gives the same
// frames.csv, loops.csv and trajectory.tum as the same data in EuRoC's own layout.
#include <gtest/gtest.h>

#include <fstream>
#include <iomanip>
#include <nlohmann/json.hpp>
#include <sstream>

#include "io/trajectory_io.hpp"
#include "test_support.hpp"

namespace loopgate {
namespace {

namespace fs = std::filesystem;

using testing::read_csv;
using testing::read_file;

std::string run(const std::string& args, int* status) {
  std::string output;
  *status = testing::run_command(testing::loopgate_binary().string() + " " + args, &output);
  return output;
}

// Shortest exact text of a double (17 significant digits read back to the same value).
std::string exact(double value) {
  std::ostringstream out;
  out << std::setprecision(17) << value;
  return out.str();
}

void write_text(const fs::path& file, const std::string& text) {
  fs::create_directories(file.parent_path());
  std::ofstream(file, std::ios::binary) << text;
}

// Ground truth as 8 columns (t_ns, p_xyz, q_wxyz), the columns both layouts have; `header` is the file's
// first line.
std::string pose_rows(const std::vector<GroundTruthState>& states, const std::string& header) {
  std::string text = header + "\n";
  for (const GroundTruthState& s : states) {
    const Eigen::Quaterniond q(s.T_w_b.linear());
    const Eigen::Vector3d& p = s.T_w_b.translation();
    text += std::to_string(s.t_ns);
    for (const double v : {p.x(), p.y(), p.z(), q.w(), q.x(), q.y(), q.z()}) text += "," + exact(v);
    text += "\n";
  }
  return text;
}

std::string matrix_rows(const Eigen::Matrix4d& M, const std::string& indent) {
  std::string text;
  for (int r = 0; r < 4; ++r) {
    text += indent + "- [";
    for (int c = 0; c < 4; ++c) text += (c ? ", " : "") + exact(M(r, c));
    text += "]\n";
  }
  return text;
}

// The simulated tree `sim` twice: `euroc` with its ground truth cut to 8 columns (TUM-VI's mocap has no
// velocity or biases, and the EKF initialises from them when they are there), and `tumvi`, the same numbers
// the TUM-VI way.
void make_layouts(const fs::path& sim, const fs::path& euroc, const fs::path& tumvi) {
  fs::copy(sim, euroc, fs::copy_options::recursive);
  const fs::path gt_csv = euroc / "mav0/state_groundtruth_estimate0/data.csv";
  const std::vector<GroundTruthState> states = read_euroc_groundtruth(gt_csv);
  write_text(gt_csv, pose_rows(states,
                               "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], "
                               "q_RS_x [], q_RS_y [], q_RS_z []"));

  fs::copy(euroc, tumvi, fs::copy_options::recursive);
  fs::remove_all(tumvi / "mav0/state_groundtruth_estimate0");
  write_text(tumvi / "mav0/mocap0/data.csv",
             pose_rows(states,
                       "#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],"
                       "q_RS_y [],q_RS_z []"));

  const CameraCalibration camera = read_euroc_camera_yaml(tumvi / "mav0/cam0/sensor.yaml");
  ASSERT_EQ(camera.distortion_model, DistortionModel::kNone);
  // Kalibr's T_cam_imu maps IMU coordinates to the camera: the inverse of EuRoC's T_BS (camera -> body).
  std::string chain = "cam0:\n  T_cam_imu:\n" + matrix_rows(camera.T_b_c.inverse().matrix(), "  ") +
                      "  cam_overlaps: []\n  camera_model: pinhole\n  distortion_coeffs: []\n"
                      "  distortion_model: none\n  intrinsics: [" +
                      exact(camera.fx) + ", " + exact(camera.fy) + ", " + exact(camera.cx) + ", " +
                      exact(camera.cy) + "]\n  resolution: [" + std::to_string(camera.width_px) + ", " +
                      std::to_string(camera.height_px) + "]\n  rostopic: /cam0/image_raw\n";
  write_text(tumvi / "dso/camchain.yaml", chain);
  const ImuCalibration imu = read_euroc_imu_yaml(tumvi / "mav0/imu0/sensor.yaml");
  ASSERT_TRUE(imu.T_b_i.matrix().isIdentity(0.0));
  write_text(tumvi / "dso/imu_config.yaml",
             "accelerometer_noise_density: " + exact(imu.accel_noise_density) +
                 "\naccelerometer_random_walk: " + exact(imu.accel_random_walk) +
                 "\ngyroscope_noise_density: " + exact(imu.gyro_noise_density) +
                 "\ngyroscope_random_walk: " + exact(imu.gyro_random_walk) +
                 "\nrostopic: /imu0\nupdate_rate: " + exact(imu.rate_hz) + "\n");
  fs::remove(tumvi / "mav0/cam0/sensor.yaml");
  fs::remove(tumvi / "mav0/imu0/sensor.yaml");
}

TEST(E2eTumVi, MocapAndKalibrRunWithGroundTruthAndTheEkf) {
  const fs::path root = testing::make_temp_dir("e2e-tumvi");
  int status = -1;
  std::string output =
      run("--log-level warn simulate --preset demo --frames 40 --out " + (root / "sim").string(), &status);
  ASSERT_EQ(status, 0) << output;
  make_layouts(root / "sim", root / "euroc", root / "tumvi");
  ASSERT_FALSE(fs::exists(root / "tumvi/mav0/state_groundtruth_estimate0"));
  ASSERT_FALSE(fs::exists(root / "tumvi/mav0/cam0/sensor.yaml"));

  const std::string args = " --config " + std::string(LOOPGATE_SOURCE_DIR) +
                           "/configs/demo.yaml --set match.margin=20 --set odometry.source=ekf"
                           " --set ekf.init_mode=ground_truth --set output.progress=off";
  output =
      run("run --dataset " + (root / "tumvi").string() + " --out " + (root / "out-tumvi").string() + args,
          &status);
  ASSERT_EQ(status, 0) << output;
  // The log says where the ground truth and the calibration came from.
  EXPECT_NE(output.find("mocap0/data.csv (TUM-VI motion capture"), std::string::npos) << output;
  EXPECT_NE(output.find("camera calibration from Kalibr"), std::string::npos) << output;
  EXPECT_NE(output.find("IMU calibration from Kalibr"), std::string::npos) << output;

  const auto summary = nlohmann::json::parse(read_file(root / "out-tumvi/summary.json"));
  EXPECT_TRUE(summary.at("dataset").at("has_ground_truth").get<bool>());
  EXPECT_TRUE(summary.at("dataset").at("has_imu").get<bool>());
  const auto& accuracy = summary.at("trajectory_accuracy");
  ASSERT_TRUE(accuracy.at("available").get<bool>()) << accuracy.dump();
  EXPECT_EQ(accuracy.at("pairs").get<int>(), 40) << accuracy.dump();
  EXPECT_LT(accuracy.at("rmse_m").get<double>(), 1.0) << accuracy.dump();  // 46 m driven
  EXPECT_EQ(summary.at("counts").at("odometry_lost").get<int>(), 0);
  std::vector<std::string> header;
  const auto rows = read_csv(root / "out-tumvi/frames.csv", &header);
  ASSERT_EQ(rows.size(), 40u);
  const std::size_t status_column = testing::column_index(header, "odom_status");
  const std::size_t features_column = testing::column_index(header, "tracked_features");
  for (const auto& row : rows) {
    EXPECT_EQ(row[status_column], "tracking");
    EXPECT_GT(std::stoi(row[features_column]), 20);
  }

  // The same data in EuRoC's layout: the same outputs, byte for byte.
  output = run("--log-level warn run --dataset " + (root / "euroc").string() + " --out " +
                   (root / "out-euroc").string() + args,
               &status);
  ASSERT_EQ(status, 0) << output;
  for (const char* file : {"frames.csv", "loops.csv", "trajectory.tum"}) {
    const std::string euroc = read_file(root / "out-euroc" / file);
    EXPECT_FALSE(euroc.empty()) << file;
    EXPECT_TRUE(euroc == read_file(root / "out-tumvi" / file)) << file << " differs between the layouts";
  }
}

}  // namespace
}  // namespace loopgate
