// The simulator driver: presets, trajectory + IMU + world + rendering, and the EuRoC ASL writer with a
// simulation.json metadata file (parameters, illumination schedule, ground-truth loops).
//
// Output layout under DIR:
//   mav0/cam0/data/<t_ns>.png, mav0/cam0/data.csv, mav0/cam0/sensor.yaml,
//   mav0/imu0/data.csv, mav0/imu0/sensor.yaml, mav0/state_groundtruth_estimate0/data.csv,
//   simulation.json
#pragma once

#include <Eigen/Geometry>
#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

#include "core/enum_names.hpp"
#include "core/revisit_rule.hpp"
#include "core/types.hpp"
#include "sim/illumination.hpp"
#include "sim/imu_synth.hpp"
#include "sim/lights.hpp"
#include "sim/sensor.hpp"
#include "sim/trajectory.hpp"
#include "sim/world.hpp"

namespace loopgate::sim {

// simulation.trajectory_format: where the camera path comes from: the procedural route (section route) or a
// recorded trajectory file (KITTI poses, EuRoC ground truth, TUM).
enum class TrajectorySource { kProcedural, kKitti, kEuroc, kTum };
inline constexpr EnumName<TrajectorySource> kTrajectorySourceNames[] = {
    {TrajectorySource::kProcedural, "procedural"},
    {TrajectorySource::kKitti, "kitti"},
    {TrajectorySource::kEuroc, "euroc"},
    {TrajectorySource::kTum, "tum"}};
constexpr std::span<const EnumName<TrajectorySource>> enum_names(TrajectorySource) {
  return kTrajectorySourceNames;
}

// simulation.imu_source: "synthesised" (from the fitted trajectory) or "file" (a recorded EuRoC imu0/data.csv
// passed through).
enum class ImuSource { kSynthesised, kFile };
inline constexpr EnumName<ImuSource> kImuSourceNames[] = {{ImuSource::kSynthesised, "synthesised"},
                                                          {ImuSource::kFile, "file"}};
constexpr std::span<const EnumName<ImuSource>> enum_names(ImuSource) {
  return kImuSourceNames;
}

// camera.distortion_model of the simulated camera: none or radial-tangential ("radtan", k1 k2 p1 p2).
enum class SimDistortion { kNone, kRadTan };
inline constexpr EnumName<SimDistortion> kSimDistortionNames[] = {{SimDistortion::kNone, "none"},
                                                                  {SimDistortion::kRadTan, "radtan"}};
constexpr std::span<const EnumName<SimDistortion>> enum_names(SimDistortion) {
  return kSimDistortionNames;
}

// Section "simulation": what to simulate and from which inputs.
struct SimulationSettings {
  std::string preset = "demo";
  std::int64_t seed = 1;
  std::int64_t max_frames = 0;  // 0 = every frame; N = the first N frames
  // Trajectory source: procedural | kitti | euroc | tum (TrajectorySource).
  TrajectorySource trajectory_format = TrajectorySource::kProcedural;
  std::string trajectory_file;  // kitti poses.txt, euroc ground-truth csv or TUM file
  std::string times_file;       // kitti times.txt
  // euroc or tum trajectories: frames at these times instead of (euroc) frame_rate_hz over the ground truth,
  // said loudly, or (tum) the poses' times; an EuRoC cam0/data.csv or one time per line (integer ns or
  // decimal seconds; io/trajectory_io.hpp read_frame_times).
  std::string frame_times_file;
  std::string camera_yaml;  // when set, the camera section is read from this EuRoC sensor.yaml
  // IMU: synthesised | file (ImuSource).
  ImuSource imu_source = ImuSource::kSynthesised;
  std::string imu_file;
  std::string imu_yaml;        // when set, the imu noise section is read from this EuRoC sensor.yaml
  double imu_padding_s = 0.1;  // IMU kept this far beyond the first/last frame (within the trajectory)
  // Frame rate used when frames are not given by the trajectory samples or a frame-times file.
  double frame_rate_hz = 20.0;
  // World "up" (unit after normalisation): KITTI camera world -y, EuRoC world +z.
  double up_x = 0.0;
  double up_y = 0.0;
  double up_z = 1.0;
  int png_compression = 3;       // zlib level 0..9, fixed so the output is byte-identical per seed
  int render_batch_frames = 32;  // frames rendered in parallel before being written in order

  // The keys, in order, for loading, printing and the JSON echo (Self is SimulationSettings or const
  // SimulationSettings).
  template <class Self, class V>
  static void fields(Self& self, V&& v) {
    v("preset", self.preset);
    v("seed", self.seed);
    v("max_frames", self.max_frames);
    v("trajectory_format", self.trajectory_format);
    v("trajectory_file", self.trajectory_file);
    v("times_file", self.times_file);
    v("frame_times_file", self.frame_times_file);
    v("camera_yaml", self.camera_yaml);
    v("imu_source", self.imu_source);
    v("imu_file", self.imu_file);
    v("imu_yaml", self.imu_yaml);
    v("imu_padding_s", self.imu_padding_s);
    v("frame_rate_hz", self.frame_rate_hz);
    v("up_x", self.up_x);
    v("up_y", self.up_y);
    v("up_z", self.up_z);
    v("png_compression", self.png_compression);
    v("render_batch_frames", self.render_batch_frames);
  }
  void validate() const;
};

// Section "camera": pinhole intrinsics, radtan distortion, camera -> body extrinsic (T_b_c).
struct CameraSettings {
  int width_px = 640;
  int height_px = 200;
  double fx = 370.0;
  double fy = 370.0;
  double cx = 319.5;
  double cy = 99.5;
  SimDistortion distortion_model = SimDistortion::kNone;  // none | radtan
  double k1 = 0.0;
  double k2 = 0.0;
  double p1 = 0.0;
  double p2 = 0.0;
  double t_b_c_x_m = 0.0;
  double t_b_c_y_m = 0.0;
  double t_b_c_z_m = 0.0;
  double q_b_c_w = 1.0;
  double q_b_c_x = 0.0;
  double q_b_c_y = 0.0;
  double q_b_c_z = 0.0;

  // The keys, in order, for loading, printing and the JSON echo (Self is CameraSettings or const
  // CameraSettings).
  template <class Self, class V>
  static void fields(Self& self, V&& v) {
    v("width_px", self.width_px);
    v("height_px", self.height_px);
    v("fx", self.fx);
    v("fy", self.fy);
    v("cx", self.cx);
    v("cy", self.cy);
    v("distortion_model", self.distortion_model);
    v("k1", self.k1);
    v("k2", self.k2);
    v("p1", self.p1);
    v("p2", self.p2);
    v("t_b_c_x_m", self.t_b_c_x_m);
    v("t_b_c_y_m", self.t_b_c_y_m);
    v("t_b_c_z_m", self.t_b_c_z_m);
    v("q_b_c_w", self.q_b_c_w);
    v("q_b_c_x", self.q_b_c_x);
    v("q_b_c_y", self.q_b_c_y);
    v("q_b_c_z", self.q_b_c_z);
  }
  void validate() const;
  Eigen::Isometry3d T_b_c() const;
  CameraCalibration calibration(double rate_hz) const;
  static CameraSettings from_calibration(const CameraCalibration& calibration);
};

// Section "imu_noise": EuRoC-style continuous-time noise densities (ADIS16448 defaults).
struct ImuNoiseSettings {
  double gyro_noise_density = 1.6968e-04;   // rad / s / sqrt(Hz)
  double gyro_random_walk = 1.9393e-05;     // rad / s^2 / sqrt(Hz)
  double accel_noise_density = 2.0000e-03;  // m / s^2 / sqrt(Hz)
  double accel_random_walk = 3.0000e-03;    // m / s^3 / sqrt(Hz)

  // The keys, in order, for loading, printing and the JSON echo (Self is ImuNoiseSettings or const
  // ImuNoiseSettings).
  template <class Self, class V>
  static void fields(Self& self, V&& v) {
    v("gyro_noise_density", self.gyro_noise_density);
    v("gyro_random_walk", self.gyro_random_walk);
    v("accel_noise_density", self.accel_noise_density);
    v("accel_random_walk", self.accel_random_walk);
  }
  void validate() const;
  ImuCalibration calibration(double rate_hz) const;
};

// Section "loops": ground-truth revisits: frame pairs (i < j) with j - i >= min_gap_frames, a camera
// path of at least min_travel_m between them (so that standing still or hovering is not a revisit),
// camera positions within radius_m (horizontal distance when horizontal_only), and optical axes within
// max_view_angle_deg (180 = no check).
struct LoopTruthSettings {
  double radius_m = 2.0;
  int min_gap_frames = 20;
  RevisitRule revisit;  // key min_travel_m
  bool horizontal_only = true;
  double max_view_angle_deg = 180.0;

  // The keys, in order, for loading, printing and the JSON echo (Self is LoopTruthSettings or const
  // LoopTruthSettings).
  template <class Self, class V>
  static void fields(Self& self, V&& v) {
    v("radius_m", self.radius_m);
    v("min_gap_frames", self.min_gap_frames);
    v("min_travel_m", self.revisit.min_travel_m);
    v("horizontal_only", self.horizontal_only);
    v("max_view_angle_deg", self.max_view_angle_deg);
  }
  void validate() const;
};

// Everything a simulation run needs. A top-level configuration for the config system (sections()).
struct SimulationConfig {
  SimulationSettings simulation;
  CameraSettings camera;
  ProceduralRouteConfig route;
  TrajectoryFitConfig fit;
  ImuSynthConfig imu;
  ImuNoiseSettings imu_noise;
  WorldConfig world;
  IlluminationSchedule illumination;
  LightsConfig lights;  // illumination.night_model lamps only
  SensorConfig sensor;  // illumination.night_model lamps only
  LoopTruthSettings loops;

  // The sections, in order, for loading, printing and the JSON echo (Self is SimulationConfig or const
  // SimulationConfig).
  template <class Self, class V>
  static void sections(Self& self, V&& v) {
    v("simulation", self.simulation);
    v("camera", self.camera);
    v("route", self.route);
    v("fit", self.fit);
    v("imu", self.imu);
    v("imu_noise", self.imu_noise);
    v("world", self.world);
    v("illumination", self.illumination);
    v("lights", self.lights);
    v("sensor", self.sensor);
    v("loops", self.loops);
  }
  void validate() const;
};

// Presets are YAML files of this configuration, loaded by the config system (io/config.hpp) over the
// defaults: configs/sim/<name>.yaml of the source tree ("demo", "kitti00", "euroc-mh05", and "aliasing", a
// perceptual-aliasing street: two far places with copied facade textures, each driven once, and one
// genuine revisit), or any such file. In a preset file, the input files of section simulation
// (trajectory_file, times_file, frame_times_file, camera_yaml, imu_file, imu_yaml) are relative to the
// shared-data folder.

// The folder of the shipped presets (configs/sim of the source tree this library was built from).
std::filesystem::path preset_dir();
// Names of the shipped presets: the *.yaml files of preset_dir() without the extension, sorted.
std::vector<std::string> preset_names();
// The file of a preset: `name_or_file` itself when it ends in .yaml or .yml, else preset_dir()/NAME.yaml.
// Throws ConfigError naming the shipped presets for an unknown name.
std::filesystem::path preset_file(const std::string& name_or_file);
// The configuration of a preset (a name or a file, see preset_file()), validated. simulation.preset is
// the file's name without extension unless the file sets it. Relative input files are resolved under
// `shared_data_dir` (see default_shared_data_dir()). Throws ConfigError for an unknown name, an unreadable
// file, and unknown keys, values of the wrong type or invalid values (naming the key, and file:line for
// the first two).
SimulationConfig make_preset(const std::string& name_or_file, const std::filesystem::path& shared_data_dir);
// $LOOPGATE_SHARED_DATA when set, else "../shared/data" relative to the current directory.
std::filesystem::path default_shared_data_dir();

// Ground-truth loops as compact intervals: query frame j revisits reference frames [first, last].
struct LoopInterval {
  std::int64_t query = 0;
  std::int64_t first = 0;
  std::int64_t last = 0;
};
// The ground-truth loops as a pairs file beside simulation.json (OUT/loop_truth.csv, "query,reference"
// 0-based frame numbers, one line per pair): what eval.truth_pairs_file reads, so that a run is scored by the
// simulator's own truth (e.g. a revisit in another lane, whose camera positions are further apart than the
// positions rule's eval.truth_radius_m). Throws DataError when it cannot be written.
inline constexpr const char* kLoopTruthFile = "loop_truth.csv";
void write_loop_truth_pairs(const std::filesystem::path& file, const std::vector<LoopInterval>& loops);
std::vector<LoopInterval> find_loop_truth(const std::vector<Eigen::Isometry3d>& T_w_c,
                                          const Eigen::Vector3d& up_w, const LoopTruthSettings& settings);

// Inputs of a simulation before rendering: frames, fitted trajectory, IMU and ground truth.
struct SimulationPlan {
  std::vector<Timestamp> frame_t_ns;     // all frames of the sequence (before max_frames)
  std::string frame_times;               // where they come from (simulation.json frames.times)
  std::size_t frames_used = 0;           // frames written (max_frames applied)
  std::vector<Eigen::Isometry3d> T_w_c;  // camera pose per frame (all frames)
  // Per frame (all frames): the lateral shift of a revisit in another lane (route.revisit_lateral_offset_m,
  // sim/revisit.hpp) in world coordinates; empty when there is none. The street (world, loop truth) runs
  // through T_w_c minus this shift.
  std::vector<Eigen::Vector3d> revisit_shift_w;
  std::size_t frames_outside_trajectory = 0;   // frames (of those used) before/after the trajectory span
  std::vector<ImuSample> imu;                  // the IMU written (synthesised or passed through)
  std::vector<GroundTruthState> ground_truth;  // at the IMU times within the span and at frame times
  std::vector<double> illumination_phase;      // per used frame
  CameraCalibration camera;
  ImuCalibration imu_calibration;
  Eigen::Vector3d up_w = Eigen::Vector3d::UnitZ();
  Timestamp trajectory_start_t_ns = 0;
  Timestamp trajectory_end_t_ns = 0;
  std::size_t trajectory_samples = 0;
  std::size_t spline_controls = 0;

  // Camera pose of frame f moved back onto the street (without the revisit's lateral shift).
  Eigen::Isometry3d street_T_w_c(std::size_t f) const {
    Eigen::Isometry3d T = T_w_c[f];
    if (!revisit_shift_w.empty()) T.translation() -= revisit_shift_w[f];
    return T;
  }
};

// Loads the inputs named by the config, fits the trajectory, makes / reads the IMU and the ground truth.
// Throws DataError for missing or malformed input files, ConfigError for a bad configuration.
// May update `config` (camera / imu_noise sections read from sensor.yaml files; world.seed = simulation.seed;
// world.street_ground_exact_cells under illumination.night_model lamps).
SimulationPlan plan_simulation(SimulationConfig& config);

// The ground-truth loops of the first plan.frames_used frames, on the street: from plan.street_T_w_c(), so
// that a revisit in another lane (route.revisit_lateral_offset_m) keeps the loop pairs of the same-lane one.
std::vector<LoopInterval> plan_loop_truth(const SimulationPlan& plan, const LoopTruthSettings& settings);

struct SimulationSummary {
  std::size_t frames = 0;
  double duration_s = 0;
  double distance_m = 0;
  std::size_t loop_pairs = 0;
  std::size_t loop_query_frames = 0;
  std::size_t imu_samples = 0;
  std::size_t ground_truth_rows = 0;
  double elapsed_s = 0;
  double render_s = 0;
  std::filesystem::path out_dir;
};

struct SimulationRunOptions {
  bool force = false;  // allow a non-empty output directory (its mav0/ and simulation.json are replaced)
};

// Runs the whole simulation into `out_dir`. Throws DataError (inputs, or a non-empty out_dir without
// force), ConfigError (bad configuration).
SimulationSummary run_simulation(SimulationConfig config, const std::filesystem::path& out_dir,
                                 const SimulationRunOptions& options = {});

}  // namespace loopgate::sim
