// Dataset layouts written from a simulated EuRoC tree, for the e2e tests that run loopgate on them: TUM-VI's
// (mocap0 ground truth, Kalibr calibration files; the same rewrite as e2e_tumvi_test's), KITTI's, an image
// folder. Header only: a test that does not call a writer does not link what it needs.
#pragma once

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <sstream>
#include <string>
#include <vector>

#include "core/geometry.hpp"
#include "io/trajectory_io.hpp"

namespace loopgate::testing {

// Shortest exact text of a double (17 significant digits read back to the same value).
inline std::string exact(double value) {
  std::ostringstream out;
  out << std::setprecision(17) << value;
  return out.str();
}

inline void write_text(const std::filesystem::path& file, const std::string& text) {
  std::filesystem::create_directories(file.parent_path());
  std::ofstream(file, std::ios::binary) << text;
}

// Ground truth as 8 columns (t_ns, p_xyz, q_wxyz), the columns both layouts have; `header` is the file's
// first line.
inline std::string pose_rows(const std::vector<GroundTruthState>& states, const std::string& header) {
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

inline std::string matrix_rows(const Eigen::Matrix4d& M, const std::string& indent) {
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
// the TUM-VI way: mav0/mocap0/data.csv, Kalibr's dso/camchain.yaml and dso/imu_config.yaml, no
// state_groundtruth_estimate0 and no sensor.yaml.
inline void make_tumvi_layouts(const std::filesystem::path& sim, const std::filesystem::path& euroc,
                               const std::filesystem::path& tumvi) {
  namespace fs = std::filesystem;
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

// The simulated tree `sim` as a KITTI odometry sequence in `kitti`: image_0/NNNNNN.png (cam0's images in
// order), times.txt, poses.txt (the camera-0 poses, the ground truth interpolated to the frame times) and
// calib.txt (P0..P3 from cam0's pinhole intrinsics, no baseline).
inline void make_kitti_layout(const std::filesystem::path& sim, const std::filesystem::path& kitti) {
  namespace fs = std::filesystem;
  const fs::path mav = sim / "mav0";
  const std::vector<EurocImageEntry> frames = read_euroc_camera_csv(mav / "cam0/data.csv");
  const std::vector<GroundTruthState> states =
      read_euroc_groundtruth(mav / "state_groundtruth_estimate0/data.csv");
  const CameraCalibration camera = read_euroc_camera_yaml(mav / "cam0/sensor.yaml");
  ASSERT_EQ(camera.distortion_model, DistortionModel::kNone);
  ASSERT_GE(states.size(), 2u);
  fs::create_directories(kitti / "image_0");
  std::vector<Eigen::Isometry3d> T_w_cam0;
  std::vector<Timestamp> times;
  std::size_t k = 0;
  for (std::size_t f = 0; f < frames.size(); ++f) {
    const Timestamp t_ns = frames[f].t_ns;
    while (k + 2 < states.size() && states[k + 1].t_ns <= t_ns) ++k;
    const StampedPose a{states[k].t_ns, states[k].T_w_b};
    const StampedPose b{states[k + 1].t_ns, states[k + 1].T_w_b};
    T_w_cam0.push_back(interpolate_pose(a, b, t_ns) * camera.T_b_c);
    times.push_back(t_ns);
    char name[32];
    std::snprintf(name, sizeof(name), "%06zu.png", f);
    fs::copy_file(mav / "cam0/data" / frames[f].filename, kitti / "image_0" / name);
  }
  write_kitti_times(kitti / "times.txt", times);
  write_kitti_poses(kitti / "poses.txt", T_w_cam0);
  const std::string P = exact(camera.fx) + " 0 " + exact(camera.cx) + " 0 0 " + exact(camera.fy) + " " +
                        exact(camera.cy) + " 0 0 0 1 0\n";
  write_text(kitti / "calib.txt", "P0: " + P + "P1: " + P + "P2: " + P + "P3: " + P);
}

// cam0's images of the simulated tree `sim` in the folder `folder`, named by their nanosecond times as
// EuRoC and TUM-VI name them, without times.txt.
inline void make_image_folder(const std::filesystem::path& sim, const std::filesystem::path& folder) {
  namespace fs = std::filesystem;
  fs::create_directories(folder);
  for (const EurocImageEntry& frame : read_euroc_camera_csv(sim / "mav0/cam0/data.csv")) {
    fs::copy_file(sim / "mav0/cam0/data" / frame.filename, folder / frame.filename);
  }
}

}  // namespace loopgate::testing
