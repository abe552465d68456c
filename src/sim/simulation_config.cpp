// The simulation's config sections (validation, calibrations) and the presets (configs/sim/<name>.yaml).
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <string>

#include "core/error.hpp"
#include "io/config.hpp"
#include "io/share_dir.hpp"
#include "sim/simulator.hpp"

namespace loopgate::sim {

// ---------------------------------------------------------------------------------------------------------
// Config sections

void SimulationSettings::validate() const {
  require(max_frames >= 0 && max_frames <= 10'000'000, "simulation.max_frames", "in [0, 10000000] (0 = all)",
          std::to_string(max_frames));
  require(imu_padding_s >= 0.0, "simulation.imu_padding_s", ">= 0", std::to_string(imu_padding_s));
  require(frame_rate_hz > 0.0 && frame_rate_hz <= 1000.0, "simulation.frame_rate_hz", "in (0, 1000] Hz",
          std::to_string(frame_rate_hz));
  require(std::isfinite(up_x) && std::isfinite(up_y) && std::isfinite(up_z) &&
              Eigen::Vector3d(up_x, up_y, up_z).norm() > 0.0,
          "simulation.up_x/up_y/up_z", "a non-zero finite vector", "0");
  require(png_compression >= 0 && png_compression <= 9, "simulation.png_compression", "in 0..9",
          std::to_string(png_compression));
  require(render_batch_frames >= 1 && render_batch_frames <= 10'000, "simulation.render_batch_frames",
          "in [1, 10000]", std::to_string(render_batch_frames));
  if (!frame_times_file.empty() && trajectory_format != TrajectorySource::kEuroc &&
      trajectory_format != TrajectorySource::kTum) {
    throw ConfigError(
        "simulation.frame_times_file: frame times replace the poses' times of an euroc or tum "
        "trajectory; trajectory_format " +
        std::string(enum_name(trajectory_format)) + " has its own (" +
        (trajectory_format == TrajectorySource::kKitti ? "times_file, one per pose" : "the route's") + ")");
  }
  if (trajectory_format == TrajectorySource::kProcedural && imu_source == ImuSource::kFile) {
    throw ConfigError("simulation.imu_source: 'file' needs a recorded trajectory (not 'procedural')");
  }
}

void CameraSettings::validate() const {
  require(width_px > 0 && height_px > 0 && width_px <= 8192 && height_px <= 8192, "camera.width_px/height_px",
          "in [1, 8192] px", std::to_string(width_px) + "x" + std::to_string(height_px));
  require(fx > 0.0 && fy > 0.0, "camera.fx/fy", "> 0", std::to_string(fx) + "," + std::to_string(fy));
  require(Eigen::Vector4d(q_b_c_w, q_b_c_x, q_b_c_y, q_b_c_z).norm() > 0.5, "camera.q_b_c_*",
          "a unit quaternion", "~0");
}

Eigen::Isometry3d CameraSettings::T_b_c() const {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::Quaterniond(q_b_c_w, q_b_c_x, q_b_c_y, q_b_c_z).normalized().toRotationMatrix();
  T.translation() = Eigen::Vector3d(t_b_c_x_m, t_b_c_y_m, t_b_c_z_m);
  return T;
}

CameraCalibration CameraSettings::calibration(double rate_hz) const {
  CameraCalibration c;
  c.width_px = width_px;
  c.height_px = height_px;
  c.fx = fx;
  c.fy = fy;
  c.cx = cx;
  c.cy = cy;
  if (distortion_model == SimDistortion::kRadTan) {
    c.distortion_model = DistortionModel::kRadTan;
    c.distortion = {k1, k2, p1, p2};
  }
  c.T_b_c = T_b_c();
  c.rate_hz = rate_hz;
  return c;
}

CameraSettings CameraSettings::from_calibration(const CameraCalibration& c) {
  CameraSettings s;
  s.width_px = c.width_px;
  s.height_px = c.height_px;
  s.fx = c.fx;
  s.fy = c.fy;
  s.cx = c.cx;
  s.cy = c.cy;
  if (c.distortion_model == DistortionModel::kRadTan && c.distortion.size() == 4) {
    s.distortion_model = SimDistortion::kRadTan;
    s.k1 = c.distortion[0];
    s.k2 = c.distortion[1];
    s.p1 = c.distortion[2];
    s.p2 = c.distortion[3];
  } else if (c.distortion_model != DistortionModel::kNone) {
    throw ConfigError(
        "camera.distortion_model: only 'none' and 'radtan' (4 coefficients) are simulated, got '" +
        std::string(to_string(c.distortion_model)) + "'");
  }
  const Eigen::Quaterniond q(c.T_b_c.linear());
  s.q_b_c_w = q.w();
  s.q_b_c_x = q.x();
  s.q_b_c_y = q.y();
  s.q_b_c_z = q.z();
  s.t_b_c_x_m = c.T_b_c.translation().x();
  s.t_b_c_y_m = c.T_b_c.translation().y();
  s.t_b_c_z_m = c.T_b_c.translation().z();
  return s;
}

void ImuNoiseSettings::validate() const {
  require(gyro_noise_density >= 0.0 && gyro_random_walk >= 0.0 && accel_noise_density >= 0.0 &&
              accel_random_walk >= 0.0,
          "imu_noise.*", ">= 0", "negative");
}

ImuCalibration ImuNoiseSettings::calibration(double rate_hz) const {
  ImuCalibration c;
  c.gyro_noise_density = gyro_noise_density;
  c.gyro_random_walk = gyro_random_walk;
  c.accel_noise_density = accel_noise_density;
  c.accel_random_walk = accel_random_walk;
  c.rate_hz = rate_hz;
  return c;
}

void LoopTruthSettings::validate() const {
  require(radius_m > 0.0, "loops.radius_m", "> 0", std::to_string(radius_m));
  require(min_gap_frames >= 1, "loops.min_gap_frames", ">= 1", std::to_string(min_gap_frames));
  revisit.validate("loops.min_travel_m");
  require(max_view_angle_deg > 0.0 && max_view_angle_deg <= 180.0, "loops.max_view_angle_deg", "in (0, 180]",
          std::to_string(max_view_angle_deg));
}

void SimulationConfig::validate() const {
  sections(*this, [](std::string_view, const auto& section) { section.validate(); });
  if (route.revisit_lateral_offset_m != 0.0 &&
      simulation.trajectory_format != TrajectorySource::kProcedural) {
    throw ConfigError(
        "route.revisit_lateral_offset_m: needs simulation.trajectory_format procedural (it is '" +
        std::string(enum_name(simulation.trajectory_format)) +
        "': the revisits of a recorded trajectory stay as recorded)");
  }
}

// ---------------------------------------------------------------------------------------------------------
// Presets: configs/sim/<name>.yaml

std::filesystem::path preset_dir() {
  return io::share_dir() / "configs" / "sim";
}

std::vector<std::string> preset_names() {
  std::vector<std::string> names;
  std::error_code ec;
  for (std::filesystem::directory_iterator it(preset_dir(), ec), end; !ec && it != end; it.increment(ec)) {
    if (it->path().extension() == ".yaml") names.push_back(it->path().stem().string());
  }
  std::sort(names.begin(), names.end());
  return names;
}

std::filesystem::path preset_file(const std::string& name_or_file) {
  const std::filesystem::path file = name_or_file;
  if (file.extension() == ".yaml" || file.extension() == ".yml") return file;
  const std::vector<std::string> names = preset_names();
  if (std::find(names.begin(), names.end(), name_or_file) == names.end()) {
    std::string known;
    for (const std::string& name : names) known += (known.empty() ? "" : "|") + name;
    throw ConfigError("preset '" + name_or_file + "': not one of " + (known.empty() ? "(none)" : known) +
                      " (the *.yaml files of " + preset_dir().string() + ") nor a preset file (.yaml)");
  }
  return preset_dir() / (name_or_file + ".yaml");
}

std::filesystem::path default_shared_data_dir() {
  if (const char* env = std::getenv("LOOPGATE_SHARED_DATA"); env != nullptr && *env != '\0') return env;
  return std::filesystem::path("..") / "shared" / "data";
}

SimulationConfig make_preset(const std::string& name_or_file, const std::filesystem::path& shared_data_dir) {
  const std::filesystem::path file = preset_file(name_or_file);
  SimulationConfig c;
  c.simulation.preset = file.stem().string();
  apply_config(RawConfig::from_yaml_file(file), c);
  // Input files of a preset are relative to the shared-data folder (absolute ones stay as they are).
  SimulationSettings& s = c.simulation;
  for (std::string* input :
       {&s.trajectory_file, &s.times_file, &s.frame_times_file, &s.camera_yaml, &s.imu_file, &s.imu_yaml}) {
    if (!input->empty()) *input = (shared_data_dir / *input).string();
  }
  return c;
}

}  // namespace loopgate::sim
