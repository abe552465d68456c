// Trajectory and calibration files: TUM, KITTI poses/times/calib, EuRoC ground truth and sensor.yaml.
// Every reader throws DataError naming the file and line on malformed input.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "core/types.hpp"

namespace loopgate {

// TUM: "t_s tx ty tz qx qy qz qw" per line, '#' comments. Timestamps must strictly increase.
std::vector<StampedPose> read_tum(const std::filesystem::path& file);
void write_tum(const std::filesystem::path& file, const std::vector<StampedPose>& poses);

// KITTI odometry: poses (12 numbers per line, row-major 3x4 T_w_cam0; or 13, a time in seconds first) and
// times.txt (seconds).
// The two files must have the same number of rows (poses may have fewer rows only if `allow_fewer`).
std::vector<StampedPose> read_kitti_poses(const std::filesystem::path& poses_file,
                                          const std::filesystem::path& times_file);
std::vector<Timestamp> read_kitti_times(const std::filesystem::path& times_file);

// EuRoC state_groundtruth_estimate0/data.csv (or a 8+-column csv with t_ns, p, q_wxyz).
std::vector<GroundTruthState> read_euroc_groundtruth(const std::filesystem::path& csv_file);
// EuRoC imu0/data.csv: t_ns, w_xyz (rad/s), a_xyz (m/s^2).
std::vector<ImuSample> read_euroc_imu(const std::filesystem::path& csv_file);
// EuRoC sensor.yaml files (the "%YAML:1.0" header line is accepted).
CameraCalibration read_euroc_camera_yaml(const std::filesystem::path& yaml_file);
ImuCalibration read_euroc_imu_yaml(const std::filesystem::path& yaml_file);

// Writers for the simulator's EuRoC-layout output (same formats the readers accept).
void write_euroc_imu(const std::filesystem::path& csv_file, const std::vector<ImuSample>& samples);
void write_euroc_groundtruth(const std::filesystem::path& csv_file,
                             const std::vector<GroundTruthState>& states);
void write_euroc_camera_yaml(const std::filesystem::path& yaml_file, const CameraCalibration& camera);
void write_euroc_imu_yaml(const std::filesystem::path& yaml_file, const ImuCalibration& imu);

// KITTI poses with times; with allow_fewer the poses file may have fewer rows than times.txt
// (ground truth that stops early); more rows is always an error. A pose file with 13 columns (a time in
// seconds first, then the 12) is timed by itself: times_file is then not read.
std::vector<StampedPose> read_kitti_poses(const std::filesystem::path& poses_file,
                                          const std::filesystem::path& times_file, bool allow_fewer);
// KITTI odometry calib.txt: camera `camera_index` (0..3) from its projection matrix P<i>: fx fy cx cy,
// no distortion (rectified), T_b_c with body = camera 0 (translation -K^-1 P[:,3]). Size left 0.
CameraCalibration read_kitti_calib(const std::filesystem::path& calib_file, int camera_index);
void write_kitti_poses(const std::filesystem::path& poses_file,
                       const std::vector<Eigen::Isometry3d>& T_w_cam0);
void write_kitti_times(const std::filesystem::path& times_file, const std::vector<Timestamp>& t_ns);

// EuRoC cam<i>/data.csv: "t_ns,filename" per image (filename relative to cam<i>/data/).
struct EurocImageEntry {
  Timestamp t_ns = 0;
  std::string filename;
  std::size_t index = 0;  // the frame's number: its data row in the file, counting rows rejected before it
};
std::vector<EurocImageEntry> read_euroc_camera_csv(const std::filesystem::path& csv_file);
// Frame times (the simulator's simulation.frame_times_file): an EuRoC cam<i>/data.csv (a comma on the first
// data line), or a plain list of one time per line, '#' comments and blank lines skipped: integer nanoseconds
// (as EuRoC / TUM-VI stamp images) or seconds with a decimal point or exponent (as KITTI times.txt), one unit
// for the whole file, strictly increasing, at most 1000 Hz (integer seconds would otherwise be read as
// nanoseconds). DataError names the file and line.
std::vector<Timestamp> read_frame_times(const std::filesystem::path& file);
void write_euroc_camera_csv(const std::filesystem::path& csv_file,
                            const std::vector<EurocImageEntry>& images);

}  // namespace loopgate
