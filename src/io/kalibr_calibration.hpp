// Kalibr calibration files (the yaml formats of github.com/ethz-asl/kalibr/wiki/yaml-formats), as TUM-VI
// ships them (dso/camchain.yaml, dso/imu_config.yaml) and as Kalibr writes them (camchain-imucam.yaml,
// imu.yaml).
//
// camchain: one section per camera, cam0, cam1, ...:
//   camera_model: pinhole (omni, ds, eucm are not supported)
//   intrinsics: [fu, fv, pu, pv]
//   distortion_model: radtan | equidistant | none,  distortion_coeffs: 4 numbers (radtan k1 k2 p1 p2,
//                                                    equidistant k1..k4)
//   resolution: [width, height]
//   T_cam_imu: 4 rows of 4 numbers, maps IMU coordinates to camera coordinates (T_c_i)
// The body frame is the IMU, as in EuRoC: T_b_c = T_cam_imu^-1 (the inverse of what EuRoC's cam0 T_BS holds).
// timeshift_cam_imu (t_imu = t_cam + shift) is not applied: a non-zero one is reported in the log.
//
// imu: accelerometer_noise_density, accelerometer_random_walk, gyroscope_noise_density, gyroscope_random_walk
// (continuous-time, EuRoC units) and update_rate [Hz], at the top level (Kalibr's input file, TUM-VI's
// imu_config.yaml) or in a section imu0 (Kalibr's result file). T_b_i is the identity (the IMU is the body).
//
// Every error is a DataError naming the file and the line.
#pragma once

#include <filesystem>

#include "core/types.hpp"

namespace loopgate {

// Camera `camera_index` (section cam<camera_index>) of a Kalibr camchain.
CameraCalibration read_kalibr_camchain(const std::filesystem::path& yaml_file, int camera_index);
ImuCalibration read_kalibr_imu(const std::filesystem::path& yaml_file);

}  // namespace loopgate
