// EuRoC sensor.yaml files (camera and IMU calibration): read with every key checked, written as EuRoC writes
// them. Declared in io/trajectory_io.hpp (read_yaml_T_BS in io/csv_formats.hpp).
#include <yaml-cpp/yaml.h>

#include <string>

#include "core/error.hpp"
#include "io/csv_formats.hpp"
#include "io/trajectory_io.hpp"
#include "io/yaml_fields.hpp"

namespace loopgate {

namespace {

using io_detail::is_rotation;
using io_detail::load_yaml;
using io_detail::require_key;
using io_detail::rigid_transform;
using io_detail::yaml_line;
using io_detail::yaml_number;
using io_detail::yaml_numbers;

Eigen::Isometry3d yaml_T_BS(const std::filesystem::path& file, const YAML::Node& root) {
  const YAML::Node node = require_key(file, root, "T_BS");
  if (!node.IsMap()) throw DataError(file, yaml_line(node), "T_BS: expected a mapping with rows, cols, data");
  const YAML::Node rows = require_key(file, node, "rows");
  const YAML::Node cols = require_key(file, node, "cols");
  if (yaml_number(file, rows, "T_BS.rows") != 4 || yaml_number(file, cols, "T_BS.cols") != 4) {
    throw DataError(file, yaml_line(node), "T_BS: expected a 4x4 matrix");
  }
  const YAML::Node data = require_key(file, node, "data");
  const std::vector<double> values = yaml_numbers(file, data, "T_BS.data", 16);
  Eigen::Matrix4d M;
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) M(r, c) = values[static_cast<std::size_t>(4 * r + c)];
  }
  return rigid_transform(file, yaml_line(data), M, "T_BS");
}

void append_list(std::string& out, const double* values, std::size_t n) {
  out += '[';
  for (std::size_t i = 0; i < n; ++i) {
    if (i) out += ", ";
    io_detail::append_double(out, values[i]);
  }
  out += ']';
}

void append_T_BS(std::string& out, const Eigen::Isometry3d& T) {
  out += "T_BS:\n  cols: 4\n  rows: 4\n  data: [";
  const Eigen::Matrix4d M = T.matrix();
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) {
      if (r || c) out += (c == 0) ? ",\n         " : ", ";
      io_detail::append_double(out, M(r, c));
    }
  }
  out += "]\n";
}

void append_key_number(std::string& out, const char* key, double value) {
  out += key;
  out += ": ";
  io_detail::append_double(out, value);
  out += '\n';
}

}  // namespace

namespace io_detail {

Eigen::Isometry3d read_yaml_T_BS(const std::filesystem::path& yaml_file) {
  return yaml_T_BS(yaml_file, load_yaml(yaml_file));
}

}  // namespace io_detail

CameraCalibration read_euroc_camera_yaml(const std::filesystem::path& yaml_file) {
  const YAML::Node root = load_yaml(yaml_file);
  CameraCalibration camera;
  camera.T_b_c = yaml_T_BS(yaml_file, root);
  if (const YAML::Node rate = root["rate_hz"]) {
    camera.rate_hz = yaml_number(yaml_file, rate, "rate_hz");
    if (!(camera.rate_hz > 0)) throw DataError(yaml_file, yaml_line(rate), "rate_hz: expected > 0");
  }
  io_detail::yaml_resolution(yaml_file, require_key(yaml_file, root, "resolution"), camera);
  if (const YAML::Node model = root["camera_model"]) {
    if (!model.IsScalar() || model.Scalar() != "pinhole") {
      throw DataError(yaml_file, yaml_line(model), "camera_model: expected 'pinhole'");
    }
  }
  io_detail::yaml_pinhole_intrinsics(yaml_file, require_key(yaml_file, root, "intrinsics"), camera);
  camera.distortion_model = io_detail::yaml_distortion_model(yaml_file, root["distortion_model"]);
  if (camera.distortion_model != DistortionModel::kNone) {
    io_detail::yaml_distortion_coefficients(yaml_file,
                                            require_key(yaml_file, root, "distortion_coefficients"),
                                            "distortion_coefficients", camera);
  }
  return camera;
}

ImuCalibration read_euroc_imu_yaml(const std::filesystem::path& yaml_file) {
  const YAML::Node root = load_yaml(yaml_file);
  ImuCalibration imu;
  imu.T_b_i = yaml_T_BS(yaml_file, root);
  const auto non_negative = [&](const char* key) {
    const YAML::Node node = require_key(yaml_file, root, key);
    const double value = yaml_number(yaml_file, node, key);
    if (value < 0) throw DataError(yaml_file, yaml_line(node), std::string(key) + ": expected >= 0");
    return value;
  };
  imu.gyro_noise_density = non_negative("gyroscope_noise_density");
  imu.gyro_random_walk = non_negative("gyroscope_random_walk");
  imu.accel_noise_density = non_negative("accelerometer_noise_density");
  imu.accel_random_walk = non_negative("accelerometer_random_walk");
  const YAML::Node rate = require_key(yaml_file, root, "rate_hz");
  imu.rate_hz = yaml_number(yaml_file, rate, "rate_hz");
  if (!(imu.rate_hz > 0)) throw DataError(yaml_file, yaml_line(rate), "rate_hz: expected > 0");
  return imu;
}

void write_euroc_camera_yaml(const std::filesystem::path& yaml_file, const CameraCalibration& camera) {
  std::string out = "%YAML:1.0\n# written by loopgate\nsensor_type: camera\ncomment: loopgate camera\n\n";
  append_T_BS(out, camera.T_b_c);
  out += '\n';
  if (camera.rate_hz > 0) append_key_number(out, "rate_hz", camera.rate_hz);  // 0 = unknown, key omitted
  out += "resolution: [" + std::to_string(camera.width_px) + ", " + std::to_string(camera.height_px) + "]\n";
  out += "camera_model: pinhole\nintrinsics: ";
  const double k[4] = {camera.fx, camera.fy, camera.cx, camera.cy};
  append_list(out, k, 4);
  out += " #fu, fv, cu, cv\ndistortion_model: ";
  switch (camera.distortion_model) {
    case DistortionModel::kNone: out += "none"; break;
    case DistortionModel::kRadTan: out += "radial-tangential"; break;
    case DistortionModel::kEquidistant: out += "equidistant"; break;
  }
  out += "\ndistortion_coefficients: ";
  append_list(out, camera.distortion.data(), camera.distortion.size());
  out += '\n';
  io_detail::write_text_file(yaml_file, out);
}

void write_euroc_imu_yaml(const std::filesystem::path& yaml_file, const ImuCalibration& imu) {
  std::string out = "%YAML:1.0\n# written by loopgate\nsensor_type: imu\ncomment: loopgate imu\n\n";
  append_T_BS(out, imu.T_b_i);
  append_key_number(out, "rate_hz", imu.rate_hz);
  out += '\n';
  append_key_number(out, "gyroscope_noise_density", imu.gyro_noise_density);
  append_key_number(out, "gyroscope_random_walk", imu.gyro_random_walk);
  append_key_number(out, "accelerometer_noise_density", imu.accel_noise_density);
  append_key_number(out, "accelerometer_random_walk", imu.accel_random_walk);
  io_detail::write_text_file(yaml_file, out);
}

}  // namespace loopgate
