#include "sim/simulator.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <nlohmann/json.hpp>
#include <numbers>
#include <opencv2/imgcodecs.hpp>
#include <stdexcept>

#include "core/error.hpp"
#include "core/geometry.hpp"
#include "io/config.hpp"
#include "io/dataset.hpp"
#include "io/file_guard.hpp"
#include "io/share_dir.hpp"
#include "io/trajectory_io.hpp"
#include "io/writers.hpp"
#include "parallel/parallel_handoff.hpp"
#include "sim/renderer.hpp"
#include "sim/revisit.hpp"

namespace loopgate::sim {

namespace {

constexpr int kMetadataVersion = 1;
constexpr std::size_t kProgressReports = 10;  // progress lines logged per run
// Stream identifiers for deriving independent seeds from the simulation seed.
constexpr std::uint64_t kImuStream = 1;
constexpr std::uint64_t kFrameNoiseStream = 2;

std::uint64_t mix_seed(std::uint64_t seed, std::uint64_t stream, std::uint64_t index) {
  GaussianRng rng(seed ^ (stream * 0xD1B54A32D192ED03ULL) ^ (index * 0x8CB92BA72F3D8DD7ULL));
  rng.next_u64();
  return rng.next_u64();
}

bool file_exists(const std::string& path) {
  std::error_code ec;
  return !path.empty() && std::filesystem::is_regular_file(path, ec);
}

void require_file(const std::string& path, const std::string& what) {
  if (path.empty()) throw DataError(std::filesystem::path("<config>"), what + ": no file given");
  if (!file_exists(path)) throw DataError(path, what + " not found (expected a readable file)");
}

Eigen::Vector3d up_vector(const SimulationSettings& s) {
  return Eigen::Vector3d(s.up_x, s.up_y, s.up_z).normalized();
}

// Horizontal component of v (perpendicular to up) or v itself.
Eigen::Vector3d loop_offset(const Eigen::Vector3d& v, const Eigen::Vector3d& up_w, bool horizontal_only) {
  return horizontal_only ? horizontal_part(v, up_w) : v;
}

double estimate_rate_hz(const std::vector<Timestamp>& t_ns, double fallback_hz) {
  if (t_ns.size() < 2 || t_ns.back() <= t_ns.front()) return fallback_hz;
  return static_cast<double>(t_ns.size() - 1) / ns_to_s(t_ns.back() - t_ns.front());
}

}  // namespace

// ---------------------------------------------------------------------------------------------------------
// Config sections

void SimulationSettings::validate() const {
  require_one_of("simulation.trajectory_format", trajectory_format, {"procedural", "kitti", "euroc", "tum"});
  require_one_of("simulation.imu_source", imu_source, {"synthesised", "file"});
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
  if (!frame_times_file.empty() && trajectory_format != "euroc" && trajectory_format != "tum") {
    throw ConfigError(
        "simulation.frame_times_file: frame times replace the poses' times of an euroc or tum "
        "trajectory; trajectory_format " +
        trajectory_format + " has its own (" +
        (trajectory_format == "kitti" ? "times_file, one per pose" : "the route's") + ")");
  }
  if (trajectory_format == "procedural" && imu_source == "file") {
    throw ConfigError("simulation.imu_source: 'file' needs a recorded trajectory (not 'procedural')");
  }
}

void CameraSettings::validate() const {
  require(width_px > 0 && height_px > 0 && width_px <= 8192 && height_px <= 8192, "camera.width_px/height_px",
          "in [1, 8192] px", std::to_string(width_px) + "x" + std::to_string(height_px));
  require(fx > 0.0 && fy > 0.0, "camera.fx/fy", "> 0", std::to_string(fx) + "," + std::to_string(fy));
  require_one_of("camera.distortion_model", distortion_model, {"none", "radtan"});
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
  if (distortion_model == "radtan") {
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
    s.distortion_model = "radtan";
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
  require(min_travel_m >= 0.0, "loops.min_travel_m", ">= 0", std::to_string(min_travel_m));
  require(max_view_angle_deg > 0.0 && max_view_angle_deg <= 180.0, "loops.max_view_angle_deg", "in (0, 180]",
          std::to_string(max_view_angle_deg));
}

void SimulationConfig::validate() const {
  sections(*this, [](std::string_view, const auto& section) { section.validate(); });
  if (route.revisit_lateral_offset_m != 0.0 && simulation.trajectory_format != "procedural") {
    throw ConfigError(
        "route.revisit_lateral_offset_m: needs simulation.trajectory_format procedural (it is '" +
        simulation.trajectory_format + "': the revisits of a recorded trajectory stay as recorded)");
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

// ---------------------------------------------------------------------------------------------------------
// Ground-truth loops

std::vector<LoopInterval> find_loop_truth(const std::vector<Eigen::Isometry3d>& T_w_c,
                                          const Eigen::Vector3d& up_w, const LoopTruthSettings& settings) {
  settings.validate();
  const Eigen::Vector3d up = up_w.normalized();
  const double radius2 = settings.radius_m * settings.radius_m;
  const double cos_max = std::cos(settings.max_view_angle_deg * std::numbers::pi / 180.0);
  const bool check_angle = settings.max_view_angle_deg < 180.0;
  const std::size_t gap = static_cast<std::size_t>(settings.min_gap_frames);
  std::vector<Eigen::Vector3d> p(T_w_c.size());
  std::vector<Eigen::Vector3d> axis(T_w_c.size());
  std::vector<double> travel_m(T_w_c.size(), 0.0);  // camera path length from frame 0
  for (std::size_t i = 0; i < T_w_c.size(); ++i) {
    p[i] = loop_offset(T_w_c[i].translation(), up, settings.horizontal_only);
    axis[i] = T_w_c[i].linear().col(2);
    if (i > 0) travel_m[i] = travel_m[i - 1] + (T_w_c[i].translation() - T_w_c[i - 1].translation()).norm();
  }
  std::vector<LoopInterval> out;
  for (std::size_t j = gap; j < T_w_c.size(); ++j) {
    bool open = false;
    LoopInterval current;
    for (std::size_t i = 0; i + gap <= j; ++i) {
      const bool match = (p[i] - p[j]).squaredNorm() <= radius2 &&
                         travel_m[j] - travel_m[i] >= settings.min_travel_m &&
                         (!check_angle || axis[i].dot(axis[j]) >= cos_max);
      if (match) {
        if (!open) {
          current = LoopInterval{static_cast<std::int64_t>(j), static_cast<std::int64_t>(i),
                                 static_cast<std::int64_t>(i)};
          open = true;
        } else {
          current.last = static_cast<std::int64_t>(i);
        }
      } else if (open) {
        out.push_back(current);
        open = false;
      }
    }
    if (open) out.push_back(current);
  }
  return out;
}

std::vector<LoopInterval> plan_loop_truth(const SimulationPlan& plan, const LoopTruthSettings& settings) {
  std::vector<Eigen::Isometry3d> street_T_w_c;
  street_T_w_c.reserve(plan.frames_used);
  for (std::size_t f = 0; f < plan.frames_used; ++f) street_T_w_c.push_back(plan.street_T_w_c(f));
  return find_loop_truth(street_T_w_c, plan.up_w, settings);
}

void write_loop_truth_pairs(const std::filesystem::path& file, const std::vector<LoopInterval>& loops) {
  std::ofstream out(file, std::ios::binary);
  out << "query,reference\n";
  for (const LoopInterval& loop : loops) {
    for (std::int64_t j = loop.first; j <= loop.last; ++j) out << loop.query << ',' << j << '\n';
  }
  if (!out) throw DataError(file, "cannot write the ground-truth loop pairs");
}

// ---------------------------------------------------------------------------------------------------------
// Planning: trajectory, frames, IMU, ground truth

SimulationPlan plan_simulation(SimulationConfig& config) {
  SimulationSettings& s = config.simulation;
  config.world.seed = s.seed;  // one seed drives the whole dataset
  // The lamps light the ground around the camera, where the legacy ground cell keys leave holes.
  if (config.illumination.night_model == "lamps") config.world.street_ground_exact_cells = true;
  config.validate();

  // Calibration files first: they may complete the config.
  if (!s.camera_yaml.empty()) {
    require_file(s.camera_yaml, "camera sensor.yaml");
    const CameraCalibration cam = read_euroc_camera_yaml(s.camera_yaml);
    config.camera = CameraSettings::from_calibration(cam);
    if (cam.rate_hz > 0.0) s.frame_rate_hz = cam.rate_hz;
  }
  if (!s.imu_yaml.empty()) {
    require_file(s.imu_yaml, "imu sensor.yaml");
    const ImuCalibration imu = read_euroc_imu_yaml(s.imu_yaml);
    if (!imu.T_b_i.isApprox(Eigen::Isometry3d::Identity(), 1e-9)) {
      throw DataError(s.imu_yaml, "T_BS must be the identity (the simulator's body frame is the IMU frame)");
    }
    config.imu_noise.gyro_noise_density = imu.gyro_noise_density;
    config.imu_noise.gyro_random_walk = imu.gyro_random_walk;
    config.imu_noise.accel_noise_density = imu.accel_noise_density;
    config.imu_noise.accel_random_walk = imu.accel_random_walk;
    if (imu.rate_hz > 0.0) config.imu.rate_hz = imu.rate_hz;
  }
  config.validate();

  SimulationPlan plan;
  plan.up_w = up_vector(s);

  // Trajectory samples and frame times.
  std::vector<StampedPose> samples;
  std::vector<GroundTruthState> recorded_states;  // euroc: biases for the ground truth
  if (s.trajectory_format == "procedural") {
    samples = make_procedural_route(config.route);
    if (config.route.revisit_lateral_offset_m != 0.0)
      plan.revisit_shift_w = apply_revisit_offset(config.route, samples);
    for (const StampedPose& pose : samples) plan.frame_t_ns.push_back(pose.t_ns);
    plan.frame_times = "the procedural route";
  } else if (s.trajectory_format == "kitti") {
    require_file(s.trajectory_file, "KITTI poses file");
    require_file(s.times_file, "KITTI times file");
    samples = load_kitti_trajectory(s.trajectory_file, s.times_file);
    for (const StampedPose& pose : samples) plan.frame_t_ns.push_back(pose.t_ns);
    plan.frame_times = s.times_file;
  } else if (s.trajectory_format == "tum") {
    require_file(s.trajectory_file, "TUM trajectory file");
    samples = load_tum_trajectory(s.trajectory_file);
    if (s.frame_times_file.empty()) {
      for (const StampedPose& pose : samples) plan.frame_t_ns.push_back(pose.t_ns);
      plan.frame_times = "the trajectory's poses";
    }
  } else {  // euroc
    require_file(s.trajectory_file, "EuRoC ground-truth csv");
    recorded_states = read_euroc_groundtruth(s.trajectory_file);
    for (const GroundTruthState& st : recorded_states) samples.push_back(StampedPose{st.t_ns, st.T_w_b});
    if (samples.size() < 2) throw DataError(s.trajectory_file, "needs at least 2 ground-truth rows");
    if (s.frame_times_file.empty()) {
      // No camera times: frames at simulation.frame_rate_hz over the ground truth's span. Said loudly:
      // the dataset then does not have the recording's frame times, and nothing else would show it.
      const double period_s = 1.0 / s.frame_rate_hz;
      for (std::int64_t k = 0;; ++k) {
        const Timestamp t = samples.front().t_ns + s_to_ns(static_cast<double>(k) * period_s);
        if (t > samples.back().t_ns) break;
        plan.frame_t_ns.push_back(t);
      }
      plan.frame_times = fmt::format("invented: every 1/{} s over the ground truth", s.frame_rate_hz);
      spdlog::warn(
          "simulate: no camera times for {} (no cam0/data.csv beside it, simulation.frame_times_file empty): "
          "INVENTING {} frame times every 1/{} s (simulation.frame_rate_hz) from its first to its last pose; "
          "give the recording's times with --frame-times FILE (an EuRoC cam0/data.csv, or one time per line: "
          "integer ns or decimal seconds)",
          s.trajectory_file, plan.frame_t_ns.size(), s.frame_rate_hz);
    }
  }
  if (!s.frame_times_file.empty()) {  // euroc and tum (validate() refuses it with the other formats)
    require_file(s.frame_times_file, "frame times file (EuRoC cam0/data.csv or one time per line)");
    plan.frame_t_ns = read_frame_times(s.frame_times_file);
    plan.frame_times = s.frame_times_file;
  }
  const std::string trajectory_name =
      s.trajectory_format == "procedural" ? std::string("<procedural>") : s.trajectory_file;
  if (samples.size() < 2) throw DataError(trajectory_name, "needs at least 2 poses");
  if (plan.frame_t_ns.empty()) throw DataError(trajectory_name, "no frames to render");
  for (std::size_t i = 1; i < plan.frame_t_ns.size(); ++i) {
    if (plan.frame_t_ns[i] <= plan.frame_t_ns[i - 1]) {
      throw DataError(trajectory_name, i + 1,
                      "frame timestamps must strictly increase (frame " + std::to_string(i) + ")");
    }
  }
  plan.trajectory_samples = samples.size();

  SplineTrajectory trajectory = [&] {
    try {
      return SplineTrajectory::fit(samples, config.fit);
    } catch (const std::invalid_argument& e) {
      throw DataError(trajectory_name, e.what());
    }
  }();
  plan.trajectory_start_t_ns = trajectory.start_t_ns();
  plan.trajectory_end_t_ns = trajectory.end_t_ns();
  plan.spline_controls = trajectory.control_count();

  const std::size_t n_total = plan.frame_t_ns.size();
  plan.frames_used =
      s.max_frames > 0 ? std::min<std::size_t>(n_total, static_cast<std::size_t>(s.max_frames)) : n_total;
  const double rate_hz = estimate_rate_hz(plan.frame_t_ns, s.frame_rate_hz);
  plan.camera = config.camera.calibration(rate_hz);
  const Eigen::Isometry3d T_b_c = plan.camera.T_b_c;
  plan.T_w_c.reserve(n_total);
  for (const Timestamp t : plan.frame_t_ns) plan.T_w_c.push_back(trajectory.pose(t) * T_b_c);
  for (std::size_t f = 0; f < plan.frames_used; ++f) {
    const Timestamp t = plan.frame_t_ns[f];
    if (t < trajectory.start_t_ns() || t > trajectory.end_t_ns()) ++plan.frames_outside_trajectory;
    plan.illumination_phase.push_back(n_total > 1 ? static_cast<double>(f) / static_cast<double>(n_total - 1)
                                                  : 0.0);
  }

  // IMU.
  const Timestamp first_frame_ns = plan.frame_t_ns.front();
  const Timestamp last_frame_ns = plan.frame_t_ns[plan.frames_used - 1];
  const Timestamp pad_ns = s_to_ns(s.imu_padding_s);
  plan.imu_calibration = config.imu_noise.calibration(config.imu.rate_hz);
  std::vector<Eigen::Vector3d> imu_gyro_bias;
  std::vector<Eigen::Vector3d> imu_accel_bias;
  if (s.imu_source == "synthesised") {
    const Timestamp t_lo = std::max(trajectory.start_t_ns(), first_frame_ns - pad_ns);
    const Timestamp t_hi = std::min(trajectory.end_t_ns(), last_frame_ns + pad_ns);
    SyntheticImu synth =
        synthesize_imu(trajectory, plan.up_w, plan.imu_calibration, config.imu,
                       mix_seed(static_cast<std::uint64_t>(s.seed), kImuStream, 0), t_lo, t_hi);
    plan.imu = std::move(synth.samples);
    imu_gyro_bias = std::move(synth.gyro_bias_radps);
    imu_accel_bias = std::move(synth.accel_bias_mps2);
  } else {
    require_file(s.imu_file, "IMU csv");
    for (const ImuSample& sample : read_euroc_imu(s.imu_file)) {
      if (sample.t_ns >= first_frame_ns - pad_ns && sample.t_ns <= last_frame_ns + pad_ns)
        plan.imu.push_back(sample);
    }
    if (plan.imu.empty()) throw DataError(s.imu_file, "no IMU sample within the frames' time span");
  }

  // Ground truth at the IMU times inside the trajectory span and at every frame time.
  std::vector<Timestamp> gt_t_ns;
  for (const ImuSample& sample : plan.imu) {
    if (sample.t_ns >= trajectory.start_t_ns() && sample.t_ns <= trajectory.end_t_ns())
      gt_t_ns.push_back(sample.t_ns);
  }
  gt_t_ns.insert(gt_t_ns.end(), plan.frame_t_ns.begin(),
                 plan.frame_t_ns.begin() + static_cast<std::ptrdiff_t>(plan.frames_used));
  std::sort(gt_t_ns.begin(), gt_t_ns.end());
  gt_t_ns.erase(std::unique(gt_t_ns.begin(), gt_t_ns.end()), gt_t_ns.end());
  plan.ground_truth.reserve(gt_t_ns.size());
  for (const Timestamp t : gt_t_ns) {
    const TrajectoryState st = trajectory.evaluate(t);
    GroundTruthState gt;
    gt.t_ns = t;
    gt.T_w_b = st.T_w_b;
    gt.v_w_mps = st.v_w_mps;
    if (!imu_gyro_bias.empty()) {
      // The bias in force at t: that of the last IMU sample at or before t (the first one before it).
      auto it = std::upper_bound(plan.imu.begin(), plan.imu.end(), t,
                                 [](Timestamp a, const ImuSample& b) { return a < b.t_ns; });
      const std::size_t k = it == plan.imu.begin() ? 0 : static_cast<std::size_t>(it - plan.imu.begin()) - 1;
      gt.gyro_bias_radps = imu_gyro_bias[k];
      gt.accel_bias_mps2 = imu_accel_bias[k];
    } else if (!recorded_states.empty()) {
      auto it = std::lower_bound(recorded_states.begin(), recorded_states.end(), t,
                                 [](const GroundTruthState& a, Timestamp b) { return a.t_ns < b; });
      if (it == recorded_states.end()) --it;
      gt.gyro_bias_radps = it->gyro_bias_radps;
      gt.accel_bias_mps2 = it->accel_bias_mps2;
    }
    plan.ground_truth.push_back(gt);
  }
  return plan;
}

// ---------------------------------------------------------------------------------------------------------
// Running

SimulationSummary run_simulation(SimulationConfig config, const std::filesystem::path& out_dir,
                                 const SimulationRunOptions& options) {
  const auto t_start = std::chrono::steady_clock::now();
  std::error_code ec;
  if (std::filesystem::exists(out_dir, ec)) {
    if (!std::filesystem::is_directory(out_dir, ec))
      throw DataError(out_dir, "--out exists and is not a directory");
    // Empty apart from the lock of the command writing into it (io/file_guard.hpp).
    bool empty = true;
    for (const auto& entry : std::filesystem::directory_iterator(out_dir, ec))
      empty = empty && entry.path().filename() == OutputLock::kFileName;
    if (!empty) {
      if (!options.force)
        throw DataError(out_dir, "output directory is not empty (use --force to overwrite)");
      std::filesystem::remove_all(out_dir / "mav0", ec);
      std::filesystem::remove(out_dir / "simulation.json", ec);
      std::filesystem::remove(out_dir / kLoopTruthFile, ec);
    }
  }

  SimulationPlan plan = plan_simulation(config);
  const SimulationSettings& s = config.simulation;
  log_config_lines(config_to_lines(config));

  // World from the whole path (so that a prefix run renders the same images as the full run).
  std::vector<Eigen::Vector3d> path_w;
  path_w.reserve(plan.T_w_c.size());
  for (std::size_t f = 0; f < plan.T_w_c.size(); ++f) path_w.push_back(plan.street_T_w_c(f).translation());
  const World world = build_world(config.world, path_w, plan.up_w);
  const Renderer renderer(world, plan.camera);
  spdlog::info("simulate: world '{}' with {} quads, {} structures ({} aliased)", config.world.kind,
               world.quads.size(), world.structures.size(), world.aliased_structure_count());
  const SceneLighting lighting(config.illumination, config.lights, config.sensor, world, path_w,
                               static_cast<std::uint64_t>(s.seed));
  if (lighting.lamps_model()) {
    spdlog::info("simulate: night model 'lamps': {} lamps ({} out for the night), headlight",
                 lighting.lamps().lights.size(), lighting.lamps().out_count());
  }

  const std::filesystem::path mav0 = out_dir / "mav0";
  const std::filesystem::path cam_dir = mav0 / "cam0";
  const std::filesystem::path image_dir = cam_dir / "data";
  std::filesystem::create_directories(image_dir);
  std::filesystem::create_directories(mav0 / "imu0");
  std::filesystem::create_directories(mav0 / "state_groundtruth_estimate0");

  // Render in parallel batches, encode in parallel, write in frame order.
  const std::size_t n = plan.frames_used;
  const std::size_t batch = static_cast<std::size_t>(s.render_batch_frames);
  const std::vector<int> png_params = {cv::IMWRITE_PNG_COMPRESSION, s.png_compression};
  std::vector<std::vector<unsigned char>> encoded(batch);
  std::vector<EurocImageEntry> entries;
  entries.reserve(n);
  std::vector<RenderStats> frame_stats(n);
  double render_s = 0.0;
  image_codecs_ready();  // OpenCV's codec table built before the render tasks encode (io/dataset.hpp)
  for (std::size_t begin = 0; begin < n; begin += batch) {
    const std::size_t end = std::min(n, begin + batch);
    const auto t_render = std::chrono::steady_clock::now();
    // The hand-over to the render tasks is explicit (parallel_handoff.hpp) so that ThreadSanitizer sees that
    // they read the plan, the world and the lights after this thread built them.
    parallel_for_with_handoff(end - begin, [&](std::size_t index) {
      const std::size_t f = begin + index;
      const double phase = plan.illumination_phase[f];
      const std::vector<SpotLight> lights = lighting.lights(phase, plan.T_w_c[f]);
      const cv::Mat image = renderer.render(
          plan.T_w_c[f], lighting.illumination(phase),
          mix_seed(static_cast<std::uint64_t>(s.seed), kFrameNoiseStream, f), lights, &frame_stats[f]);
      if (!cv::imencode(".png", image, encoded[index], png_params)) {
        throw std::runtime_error("PNG encoding failed for frame " + std::to_string(f));
      }
    });
    render_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - t_render).count();
    for (std::size_t f = begin; f < end; ++f) {
      const std::string name = std::to_string(plan.frame_t_ns[f]) + ".png";
      const std::filesystem::path file = image_dir / name;
      std::ofstream out(file, std::ios::binary);
      out.write(reinterpret_cast<const char*>(encoded[f - begin].data()),
                static_cast<std::streamsize>(encoded[f - begin].size()));
      if (!out) throw DataError(file, "cannot write image");
      entries.push_back(EurocImageEntry{plan.frame_t_ns[f], name});
    }
    const std::size_t progress_step = std::max<std::size_t>(1, n / kProgressReports);
    if (end == n || end / progress_step != begin / progress_step) {
      spdlog::info("simulate: {}/{} frames written ({:.1f} frames/s)", end, n,
                   render_s > 0.0 ? static_cast<double>(end) / render_s : 0.0);
    }
  }

  write_euroc_camera_csv(cam_dir / "data.csv", entries);
  write_euroc_camera_yaml(cam_dir / "sensor.yaml", plan.camera);
  write_euroc_imu(mav0 / "imu0" / "data.csv", plan.imu);
  write_euroc_imu_yaml(mav0 / "imu0" / "sensor.yaml", plan.imu_calibration);
  write_euroc_groundtruth(mav0 / "state_groundtruth_estimate0" / "data.csv", plan.ground_truth);

  // Ground-truth loops over the frames written.
  const std::vector<LoopInterval> loops = plan_loop_truth(plan, config.loops);

  SimulationSummary summary;
  summary.frames = n;
  summary.duration_s = ns_to_s(plan.frame_t_ns[n - 1] - plan.frame_t_ns.front());
  for (std::size_t f = 1; f < n; ++f) {
    summary.distance_m += (plan.T_w_c[f].translation() - plan.T_w_c[f - 1].translation()).norm();
  }
  for (const LoopInterval& loop : loops)
    summary.loop_pairs += static_cast<std::size_t>(loop.last - loop.first + 1);
  {
    std::int64_t last_query = -1;
    for (const LoopInterval& loop : loops) {
      if (loop.query != last_query) ++summary.loop_query_frames;
      last_query = loop.query;
    }
  }
  summary.imu_samples = plan.imu.size();
  summary.ground_truth_rows = plan.ground_truth.size();
  summary.out_dir = out_dir;

  // Metadata (no wall-clock values: the file is part of the byte-identical output).
  nlohmann::json meta;
  meta["format"] = "loopgate-simulation";
  meta["version"] = kMetadataVersion;
  meta["preset"] = s.preset;
  meta["seed"] = s.seed;
  meta["parameters"] = config_to_json(config);
  if (!lighting.lamps_model()) {
    // The keys added with the lamps model do nothing under the ambient-noise night (or at their defaults):
    // they are echoed only when used, so that datasets of the ambient-noise night keep the bytes they had
    // before the lamps model existed.
    meta["parameters"].erase("lights");
    meta["parameters"].erase("sensor");
    meta["parameters"]["illumination"].erase("night_model");
  }
  if (!config.world.street_ground_exact_cells) meta["parameters"]["world"].erase("street_ground_exact_cells");
  if (config.route.revisit_lateral_offset_m == 0.0) {
    // Echoed only when used, so that datasets without a revisit offset keep their bytes.
    for (const char* key :
         {"revisit_lateral_offset_m", "revisit_radius_m", "revisit_min_travel_m", "revisit_lane_change_m"})
      meta["parameters"]["route"].erase(key);
  }
  meta["world"] = {{"kind", config.world.kind},
                   {"quads", world.quads.size()},
                   {"structures", world.structures.size()},
                   {"aliasable_structures", world.aliasable_structure_count()},
                   {"aliased_structures", world.aliased_structure_count()},
                   {"up_w", {plan.up_w.x(), plan.up_w.y(), plan.up_w.z()}}};
  if (config.world.alias_copy_radius_m > 0.0) {
    // Which structures the place copy aliased: [target structure, source structure, texture seed].
    nlohmann::json copies = nlohmann::json::array();
    for (std::size_t k = 0; k < world.structures.size(); ++k) {
      const Structure& st = world.structures[k];
      if (st.copied) copies.push_back({k, st.aliased_from, st.texture_seed});
    }
    meta["world"]["place_copy"] = {{"copied_structures", world.copied_structure_count()},
                                   {"columns", {"target", "source", "texture_seed"}},
                                   {"structures", copies}};
  }
  meta["trajectory"] = {{"format", s.trajectory_format},
                        {"samples", plan.trajectory_samples},
                        {"start_t_ns", plan.trajectory_start_t_ns},
                        {"end_t_ns", plan.trajectory_end_t_ns},
                        {"spline_controls", plan.spline_controls},
                        {"frames_outside_trajectory", plan.frames_outside_trajectory}};
  nlohmann::json phases = nlohmann::json::array();
  nlohmann::json night = nlohmann::json::array();
  for (std::size_t f = 0; f < n; ++f) {
    phases.push_back(plan.illumination_phase[f]);
    night.push_back(config.illumination.night_factor(plan.illumination_phase[f]));
  }
  meta["frames"] = {{"count", n},
                    {"times", plan.frame_times},
                    {"total_in_sequence", plan.frame_t_ns.size()},
                    {"first_t_ns", plan.frame_t_ns.front()},
                    {"last_t_ns", plan.frame_t_ns[n - 1]},
                    {"rate_hz", plan.camera.rate_hz},
                    {"duration_s", summary.duration_s},
                    {"distance_m", summary.distance_m}};
  meta["illumination"] = {{"schedule", config.illumination.kind}, {"phase", phases}, {"night_factor", night}};
  if (lighting.lamps_model()) {
    // Per frame: the auto-exposure's exposure time and analogue gain, and whether lamps and headlight shone.
    nlohmann::json exposure = nlohmann::json::array(), gain = nlohmann::json::array();
    nlohmann::json lamps_on = nlohmann::json::array(), headlight_on = nlohmann::json::array();
    for (std::size_t f = 0; f < n; ++f) {
      exposure.push_back(frame_stats[f].exposure_time);
      gain.push_back(frame_stats[f].gain);
      lamps_on.push_back(lighting.lamps_on(plan.illumination_phase[f]));
      headlight_on.push_back(lighting.headlight_on(plan.illumination_phase[f]));
    }
    meta["illumination"]["night_model"] = config.illumination.night_model;
    meta["illumination"]["lamps"] = {{"count", lighting.lamps().lights.size()},
                                     {"out_for_the_night", lighting.lamps().out_count()}};
    meta["illumination"]["exposure_time"] = exposure;
    meta["illumination"]["gain"] = gain;
    meta["illumination"]["lamps_on"] = lamps_on;
    meta["illumination"]["headlight_on"] = headlight_on;
  }
  meta["imu"] = {{"source", s.imu_source}, {"samples", plan.imu.size()}, {"rate_hz", config.imu.rate_hz}};
  nlohmann::json intervals = nlohmann::json::array();
  for (const LoopInterval& loop : loops) intervals.push_back({loop.query, loop.first, loop.last});
  meta["loops"] = {
      {"definition",
       "query frame j revisits reference frames i in [first, last]: j - i >= min_gap_frames and camera "
       "positions within radius_m"},
      {"radius_m", config.loops.radius_m},
      {"min_gap_frames", config.loops.min_gap_frames},
      {"horizontal_only", config.loops.horizontal_only},
      {"max_view_angle_deg", config.loops.max_view_angle_deg},
      {"pairs", summary.loop_pairs},
      {"query_frames", summary.loop_query_frames},
      {"intervals_columns", {"query", "first", "last"}},
      {"intervals", intervals}};
  write_json_file(out_dir / "simulation.json", meta);
  write_loop_truth_pairs(out_dir / kLoopTruthFile, loops);

  summary.render_s = render_s;
  summary.elapsed_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
  return summary;
}

}  // namespace loopgate::sim
