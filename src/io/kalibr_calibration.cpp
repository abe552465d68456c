#include "io/kalibr_calibration.hpp"

#include <spdlog/spdlog.h>

#include <optional>
#include <string>

#include "core/error.hpp"
#include "io/yaml_fields.hpp"

namespace loopgate {

namespace {

namespace fs = std::filesystem;
using io_detail::yaml_line;

// A section of the file (cam0, imu0) with the line of its key, for messages.
struct Section {
  YAML::Node node;
  std::string name;
  std::size_t line = 0;
};

// The section `name` of `root`, or nullopt; its line is that of its key.
std::optional<Section> find_section(const YAML::Node& root, const std::string& name) {
  for (auto it = root.begin(); it != root.end(); ++it) {
    if (it->first.IsScalar() && it->first.Scalar() == name) {
      return Section{it->second, name, yaml_line(it->first)};
    }
  }
  return std::nullopt;
}

// The names of the top-level keys that look like camera sections (cam0, cam1, ...), for messages.
std::string camera_sections(const YAML::Node& root) {
  std::string names;
  for (auto it = root.begin(); it != root.end(); ++it) {
    if (!it->first.IsScalar() || it->first.Scalar().rfind("cam", 0) != 0) continue;
    names += (names.empty() ? "" : ", ") + it->first.Scalar();
  }
  return names.empty() ? "none" : names;
}

YAML::Node require(const fs::path& file, const Section& section, const char* key) {
  const YAML::Node node = section.node[key];
  if (!node) {
    throw DataError(file, section.line, section.name + ": missing key '" + std::string(key) + "'");
  }
  return node;
}

// Kalibr writes 4x4 transforms as a list of 4 rows of 4 numbers.
Eigen::Isometry3d kalibr_transform(const fs::path& file, const YAML::Node& node, const std::string& what) {
  if (!node.IsSequence() || node.size() != 4) {
    throw DataError(file, yaml_line(node), what + ": expected 4 rows of 4 numbers");
  }
  Eigen::Matrix4d M;
  for (std::size_t r = 0; r < 4; ++r) {
    const std::vector<double> row =
        io_detail::yaml_numbers(file, node[r], what + " row " + std::to_string(r + 1), 4);
    for (std::size_t c = 0; c < 4; ++c) M(static_cast<int>(r), static_cast<int>(c)) = row[c];
  }
  return io_detail::rigid_transform(file, yaml_line(node), M, what);
}

double non_negative(const fs::path& file, const Section& section, const char* key) {
  const YAML::Node node = require(file, section, key);
  const double value = io_detail::yaml_number(file, node, key);
  if (value < 0) throw DataError(file, yaml_line(node), std::string(key) + ": expected >= 0");
  return value;
}

}  // namespace

CameraCalibration read_kalibr_camchain(const fs::path& yaml_file, int camera_index) {
  const YAML::Node root = io_detail::load_yaml(yaml_file);
  const std::string name = "cam" + std::to_string(camera_index);
  const std::optional<Section> cam = find_section(root, name);
  if (!cam) {
    throw DataError(
        yaml_file, yaml_line(root),
        "no section '" + name + "' (camera sections here: " + camera_sections(root) +
            "), expected a Kalibr camchain with " + name +
            ": camera_model, intrinsics, distortion_model, distortion_coeffs, resolution, T_cam_imu");
  }
  if (!cam->node.IsMap()) {
    throw DataError(yaml_file, cam->line, name + ": expected a mapping of camera keys");
  }
  CameraCalibration camera;
  const YAML::Node model = require(yaml_file, *cam, "camera_model");
  if (!model.IsScalar() || model.Scalar() != "pinhole") {
    throw DataError(yaml_file, yaml_line(model),
                    name + ".camera_model: " + quote_excerpt(model.IsScalar() ? model.Scalar() : "?") +
                        ", expected pinhole (omni, ds and eucm are not supported)");
  }
  io_detail::yaml_pinhole_intrinsics(yaml_file, require(yaml_file, *cam, "intrinsics"), camera);
  camera.distortion_model = io_detail::yaml_distortion_model(yaml_file, cam->node["distortion_model"]);
  if (camera.distortion_model != DistortionModel::kNone) {
    io_detail::yaml_distortion_coefficients(yaml_file, require(yaml_file, *cam, "distortion_coeffs"),
                                            "distortion_coeffs", camera);
  }
  io_detail::yaml_resolution(yaml_file, require(yaml_file, *cam, "resolution"), camera);
  // Kalibr writes T_cam_imu; OpenVINS' kalibr_imucam_chain.yaml writes its inverse, T_imu_cam.
  if (const YAML::Node T_i_c_node = cam->node["T_imu_cam"]; T_i_c_node && !cam->node["T_cam_imu"]) {
    camera.T_b_c = kalibr_transform(yaml_file, T_i_c_node, name + ".T_imu_cam");
  } else if (!cam->node["T_cam_imu"]) {
    throw DataError(yaml_file, cam->line,
                    name +
                        ": no T_cam_imu (Kalibr) or T_imu_cam (OpenVINS): the camera-IMU transform is "
                        "missing");
  } else {
    const Eigen::Isometry3d T_c_i =
        kalibr_transform(yaml_file, require(yaml_file, *cam, "T_cam_imu"), name + ".T_cam_imu");
    camera.T_b_c = T_c_i.inverse();
  }
  if (const YAML::Node shift = cam->node["timeshift_cam_imu"]) {
    const double shift_s = io_detail::yaml_number(yaml_file, shift, name + ".timeshift_cam_imu");
    if (shift_s != 0) {
      spdlog::warn("{}:{}: {}.timeshift_cam_imu = {} s is not applied: frame times are used as recorded",
                   yaml_file.string(), yaml_line(shift), name, shift_s);
    }
  }
  return camera;
}

ImuCalibration read_kalibr_imu(const fs::path& yaml_file) {
  const YAML::Node root = io_detail::load_yaml(yaml_file);
  std::optional<Section> section = find_section(root, "imu0");
  if (!section) section = Section{root, "imu", yaml_line(root)};
  if (!section->node.IsMap()) {
    throw DataError(yaml_file, section->line, section->name + ": expected a mapping of IMU keys");
  }
  ImuCalibration imu;
  imu.gyro_noise_density = non_negative(yaml_file, *section, "gyroscope_noise_density");
  imu.gyro_random_walk = non_negative(yaml_file, *section, "gyroscope_random_walk");
  imu.accel_noise_density = non_negative(yaml_file, *section, "accelerometer_noise_density");
  imu.accel_random_walk = non_negative(yaml_file, *section, "accelerometer_random_walk");
  const YAML::Node rate = require(yaml_file, *section, "update_rate");
  imu.rate_hz = io_detail::yaml_number(yaml_file, rate, "update_rate");
  if (!(imu.rate_hz > 0)) throw DataError(yaml_file, yaml_line(rate), "update_rate: expected > 0");
  return imu;
}

}  // namespace loopgate
