// Private helpers of src/io for the calibration YAML files (EuRoC sensor.yaml, Kalibr camchain / imu.yaml):
// loading with the file's line numbers kept, and typed fields whose errors name the file and line.
#pragma once

#include <yaml-cpp/yaml.h>

#include <Eigen/Geometry>
#include <cstddef>
#include <filesystem>
#include <string>
#include <vector>

#include "core/types.hpp"

namespace loopgate::io_detail {

// Parses `file` as a YAML mapping. OpenCV/EuRoC files start with "%YAML:1.0", a directive yaml-cpp rejects:
// such lines are read as comments (line numbers stay those of the file). Throws DataError (file, line).
YAML::Node load_yaml(const std::filesystem::path& file);

// 1-based line of `node` in its file.
std::size_t yaml_line(const YAML::Node& node);

// root[key]; DataError "missing key 'KEY'" (no line) when absent.
YAML::Node require_key(const std::filesystem::path& file, const YAML::Node& root, const char* key);

// A finite number (a leading '+' accepted); DataError naming `what` and the node's line.
double yaml_number(const std::filesystem::path& file, const YAML::Node& node, const std::string& what);
// A list of exactly `expected` finite numbers.
std::vector<double> yaml_numbers(const std::filesystem::path& file, const YAML::Node& node,
                                 const std::string& what, std::size_t expected);

// True when R^T R = I within 1e-2 (files carry a few decimals) and det R > 0.
bool is_rotation(const Eigen::Matrix3d& R);

// A homogeneous 4x4 rigid transform: bottom row [0 0 0 1] and a rotation block, else DataError naming
// `what` at `line`.
Eigen::Isometry3d rigid_transform(const std::filesystem::path& file, std::size_t line,
                                  const Eigen::Matrix4d& M, const std::string& what);

// "radial-tangential" / "radtan", "equidistant", "none" (absent node: none); DataError naming the line else.
DistortionModel yaml_distortion_model(const std::filesystem::path& file, const YAML::Node& node);

// resolution [width, height]: two positive integers, stored into camera.width_px / height_px.
void yaml_resolution(const std::filesystem::path& file, const YAML::Node& node, CameraCalibration& camera);

// intrinsics [fu, fv, cu, cv] with positive focal lengths, stored into camera.fx .. cy.
void yaml_pinhole_intrinsics(const std::filesystem::path& file, const YAML::Node& node,
                             CameraCalibration& camera);

// The 4 coefficients of camera.distortion_model (radtan k1 k2 p1 p2, equidistant k1..k4) from the list
// `node`, named `key` in messages.
void yaml_distortion_coefficients(const std::filesystem::path& file, const YAML::Node& node, const char* key,
                                  CameraCalibration& camera);

}  // namespace loopgate::io_detail
