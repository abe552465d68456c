#include "sim/simulator.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <nlohmann/json.hpp>
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

double estimate_rate_hz(const std::vector<Timestamp>& t_ns, double fallback_hz) {
  if (t_ns.size() < 2 || t_ns.back() <= t_ns.front()) return fallback_hz;
  return static_cast<double>(t_ns.size() - 1) / ns_to_s(t_ns.back() - t_ns.front());
}

}  // namespace

// ---------------------------------------------------------------------------------------------------------
// Planning: trajectory, frames, IMU, ground truth

namespace {

// Calibration files (camera and IMU sensor.yaml) complete the config.
void apply_calibration_files(SimulationConfig& config) {
  SimulationSettings& s = config.simulation;
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
}

// The recorded or procedural trajectory the frames follow.
struct TrajectoryInput {
  std::vector<StampedPose> samples;
  std::vector<GroundTruthState> recorded_states;  // euroc: biases for the ground truth
  std::string name;                               // for messages
};

// Trajectory samples, and the frame times into plan (checked: at least one, strictly increasing).
TrajectoryInput load_trajectory(const SimulationConfig& config, SimulationPlan& plan) {
  const SimulationSettings& s = config.simulation;
  TrajectoryInput input;
  std::vector<StampedPose>& samples = input.samples;
  std::vector<GroundTruthState>& recorded_states = input.recorded_states;
  if (s.trajectory_format == TrajectorySource::kProcedural) {
    samples = make_procedural_route(config.route);
    if (config.route.revisit_lateral_offset_m != 0.0)
      plan.revisit_shift_w = apply_revisit_offset(config.route, samples);
    for (const StampedPose& pose : samples) plan.frame_t_ns.push_back(pose.t_ns);
    plan.frame_times = "the procedural route";
  } else if (s.trajectory_format == TrajectorySource::kKitti) {
    require_file(s.trajectory_file, "KITTI poses file");
    require_file(s.times_file, "KITTI times file");
    samples = load_kitti_trajectory(s.trajectory_file, s.times_file);
    for (const StampedPose& pose : samples) plan.frame_t_ns.push_back(pose.t_ns);
    plan.frame_times = s.times_file;
  } else if (s.trajectory_format == TrajectorySource::kTum) {
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
  input.name =
      s.trajectory_format == TrajectorySource::kProcedural ? std::string("<procedural>") : s.trajectory_file;
  if (samples.size() < 2) throw DataError(input.name, "needs at least 2 poses");
  if (plan.frame_t_ns.empty()) throw DataError(input.name, "no frames to render");
  for (std::size_t i = 1; i < plan.frame_t_ns.size(); ++i) {
    if (plan.frame_t_ns[i] <= plan.frame_t_ns[i - 1]) {
      throw DataError(input.name, i + 1,
                      "frame timestamps must strictly increase (frame " + std::to_string(i) + ")");
    }
  }

  return input;
}

// The spline through the trajectory samples; frames, their poses and illumination phases into plan.
SplineTrajectory fit_frames(const SimulationConfig& config, const TrajectoryInput& input,
                            SimulationPlan& plan) {
  const SimulationSettings& s = config.simulation;
  const std::vector<StampedPose>& samples = input.samples;
  const std::string& trajectory_name = input.name;
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

  return trajectory;
}

// IMU samples over the frames (synthesised from the spline or read from the recording), then the ground truth
// at the IMU times inside the trajectory span and at every frame time.
void plan_imu_and_ground_truth(const SimulationConfig& config, const SplineTrajectory& trajectory,
                               const TrajectoryInput& input, SimulationPlan& plan) {
  const SimulationSettings& s = config.simulation;
  const std::vector<GroundTruthState>& recorded_states = input.recorded_states;
  const Timestamp first_frame_ns = plan.frame_t_ns.front();
  const Timestamp last_frame_ns = plan.frame_t_ns[plan.frames_used - 1];
  const Timestamp pad_ns = s_to_ns(s.imu_padding_s);
  plan.imu_calibration = config.imu_noise.calibration(config.imu.rate_hz);
  std::vector<Eigen::Vector3d> imu_gyro_bias;
  std::vector<Eigen::Vector3d> imu_accel_bias;
  if (s.imu_source == ImuSource::kSynthesised) {
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
}

}  // namespace

SimulationPlan plan_simulation(SimulationConfig& config) {
  SimulationSettings& s = config.simulation;
  config.world.seed = s.seed;  // one seed drives the whole dataset
  // The lamps light the ground around the camera, where the legacy ground cell keys leave holes.
  if (config.illumination.night_model == NightModel::kLamps) config.world.street_ground_exact_cells = true;
  config.validate();
  apply_calibration_files(config);
  config.validate();

  SimulationPlan plan;
  plan.up_w = up_vector(s);
  const TrajectoryInput input = load_trajectory(config, plan);
  const SplineTrajectory trajectory = fit_frames(config, input, plan);
  plan_imu_and_ground_truth(config, trajectory, input, plan);
  return plan;
}

namespace {

// --out must be absent, or a directory that is empty apart from the lock of the command writing into it
// (io/file_guard.hpp); with --force a previous simulation's files in it are removed.
void prepare_out_dir(const std::filesystem::path& out_dir, bool force) {
  std::error_code ec;
  if (!std::filesystem::exists(out_dir, ec)) return;
  if (!std::filesystem::is_directory(out_dir, ec))
    throw DataError(out_dir, "--out exists and is not a directory");
  bool empty = true;
  for (const auto& entry : std::filesystem::directory_iterator(out_dir, ec))
    empty = empty && entry.path().filename() == OutputLock::kFileName;
  if (empty) return;
  if (!force) throw DataError(out_dir, "output directory is not empty (use --force to overwrite)");
  std::filesystem::remove_all(out_dir / "mav0", ec);
  std::filesystem::remove(out_dir / "simulation.json", ec);
  std::filesystem::remove(out_dir / kLoopTruthFile, ec);
}

// What rendering the frames gives besides the images.
struct RenderedFrames {
  std::vector<EurocImageEntry> entries;  // cam0/data.csv rows
  std::vector<RenderStats> stats;        // per frame
  double render_s = 0.0;                 // wall time spent rendering and encoding
};

// Renders the plan's frames in parallel batches, encodes them in parallel and writes them in frame order.
RenderedFrames render_frames(const SimulationPlan& plan, const SimulationSettings& s,
                             const Renderer& renderer, const SceneLighting& lighting,
                             const std::filesystem::path& image_dir) {
  const std::size_t n = plan.frames_used;
  const std::size_t batch = static_cast<std::size_t>(s.render_batch_frames);
  const std::vector<int> png_params = {cv::IMWRITE_PNG_COMPRESSION, s.png_compression};
  std::vector<std::vector<unsigned char>> encoded(batch);
  RenderedFrames out;
  out.entries.reserve(n);
  out.stats.resize(n);
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
          mix_seed(static_cast<std::uint64_t>(s.seed), kFrameNoiseStream, f), lights, &out.stats[f]);
      if (!cv::imencode(".png", image, encoded[index], png_params)) {
        throw std::runtime_error("PNG encoding failed for frame " + std::to_string(f));
      }
    });
    out.render_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - t_render).count();
    for (std::size_t f = begin; f < end; ++f) {
      const std::string name = std::to_string(plan.frame_t_ns[f]) + ".png";
      const std::filesystem::path file = image_dir / name;
      std::ofstream image_out(file, std::ios::binary);
      image_out.write(reinterpret_cast<const char*>(encoded[f - begin].data()),
                      static_cast<std::streamsize>(encoded[f - begin].size()));
      if (!image_out) throw DataError(file, "cannot write image");
      out.entries.push_back(EurocImageEntry{plan.frame_t_ns[f], name});
    }
    const std::size_t progress_step = std::max<std::size_t>(1, n / kProgressReports);
    if (end == n || end / progress_step != begin / progress_step) {
      spdlog::info("simulate: {}/{} frames written ({:.1f} frames/s)", end, n,
                   out.render_s > 0.0 ? static_cast<double>(end) / out.render_s : 0.0);
    }
  }
  return out;
}

SimulationSummary summarize(const SimulationPlan& plan, const std::vector<LoopInterval>& loops,
                            const std::filesystem::path& out_dir) {
  const std::size_t n = plan.frames_used;
  SimulationSummary summary;
  summary.frames = n;
  summary.duration_s = ns_to_s(plan.frame_t_ns[n - 1] - plan.frame_t_ns.front());
  for (std::size_t f = 1; f < n; ++f) {
    summary.distance_m += (plan.T_w_c[f].translation() - plan.T_w_c[f - 1].translation()).norm();
  }
  for (const LoopInterval& loop : loops)
    summary.loop_pairs += static_cast<std::size_t>(loop.last - loop.first + 1);
  std::int64_t last_query = -1;
  for (const LoopInterval& loop : loops) {
    if (loop.query != last_query) ++summary.loop_query_frames;
    last_query = loop.query;
  }
  summary.imu_samples = plan.imu.size();
  summary.ground_truth_rows = plan.ground_truth.size();
  summary.out_dir = out_dir;
  return summary;
}

// The parameters' echo: keys added after the first datasets are echoed only when used, so that datasets
// which do not use them keep the bytes they had before those keys existed.
nlohmann::json metadata_parameters(const SimulationConfig& config, bool lamps_model) {
  nlohmann::json parameters = config_to_json(config);
  if (!lamps_model) {
    // The keys of the lamps model do nothing under the ambient-noise night (or at their defaults).
    parameters.erase("lights");
    parameters.erase("sensor");
    parameters["illumination"].erase("night_model");
  }
  if (!config.world.street_ground_exact_cells) parameters["world"].erase("street_ground_exact_cells");
  if (config.route.revisit_lateral_offset_m == 0.0) {
    for (const char* key :
         {"revisit_lateral_offset_m", "revisit_radius_m", "revisit_min_travel_m", "revisit_lane_change_m"})
      parameters["route"].erase(key);
  }
  return parameters;
}

nlohmann::json metadata_world(const SimulationConfig& config, const World& world,
                              const Eigen::Vector3d& up_w) {
  nlohmann::json meta = {{"kind", enum_name(config.world.kind)},
                         {"quads", world.quads.size()},
                         {"structures", world.structures.size()},
                         {"aliasable_structures", world.aliasable_structure_count()},
                         {"aliased_structures", world.aliased_structure_count()},
                         {"up_w", {up_w.x(), up_w.y(), up_w.z()}}};
  if (config.world.alias_copy_radius_m > 0.0) {
    // Which structures the place copy aliased: [target structure, source structure, texture seed].
    nlohmann::json copies = nlohmann::json::array();
    for (std::size_t k = 0; k < world.structures.size(); ++k) {
      const Structure& st = world.structures[k];
      if (st.copied) copies.push_back({k, st.aliased_from, st.texture_seed});
    }
    meta["place_copy"] = {{"copied_structures", world.copied_structure_count()},
                          {"columns", {"target", "source", "texture_seed"}},
                          {"structures", copies}};
  }
  return meta;
}

nlohmann::json metadata_illumination(const SimulationConfig& config, const SimulationPlan& plan,
                                     const SceneLighting& lighting, const std::vector<RenderStats>& stats) {
  const std::size_t n = plan.frames_used;
  nlohmann::json phases = nlohmann::json::array();
  nlohmann::json night = nlohmann::json::array();
  for (std::size_t f = 0; f < n; ++f) {
    phases.push_back(plan.illumination_phase[f]);
    night.push_back(config.illumination.night_factor(plan.illumination_phase[f]));
  }
  nlohmann::json meta = {
      {"schedule", enum_name(config.illumination.kind)}, {"phase", phases}, {"night_factor", night}};
  if (!lighting.lamps_model()) return meta;
  // Per frame: the auto-exposure's exposure time and analogue gain, and whether lamps and headlight shone.
  nlohmann::json exposure = nlohmann::json::array(), gain = nlohmann::json::array();
  nlohmann::json lamps_on = nlohmann::json::array(), headlight_on = nlohmann::json::array();
  for (std::size_t f = 0; f < n; ++f) {
    exposure.push_back(stats[f].exposure_time);
    gain.push_back(stats[f].gain);
    lamps_on.push_back(lighting.lamps_on(plan.illumination_phase[f]));
    headlight_on.push_back(lighting.headlight_on(plan.illumination_phase[f]));
  }
  meta["night_model"] = enum_name(config.illumination.night_model);
  meta["lamps"] = {{"count", lighting.lamps().lights.size()},
                   {"out_for_the_night", lighting.lamps().out_count()}};
  meta["exposure_time"] = exposure;
  meta["gain"] = gain;
  meta["lamps_on"] = lamps_on;
  meta["headlight_on"] = headlight_on;
  return meta;
}

nlohmann::json metadata_loops(const LoopTruthSettings& settings, const std::vector<LoopInterval>& loops,
                              const SimulationSummary& summary) {
  nlohmann::json intervals = nlohmann::json::array();
  for (const LoopInterval& loop : loops) intervals.push_back({loop.query, loop.first, loop.last});
  return {{"definition",
           "query frame j revisits reference frames i in [first, last]: j - i >= min_gap_frames and camera "
           "positions within radius_m"},
          {"radius_m", settings.radius_m},
          {"min_gap_frames", settings.min_gap_frames},
          {"horizontal_only", settings.horizontal_only},
          {"max_view_angle_deg", settings.max_view_angle_deg},
          {"pairs", summary.loop_pairs},
          {"query_frames", summary.loop_query_frames},
          {"intervals_columns", {"query", "first", "last"}},
          {"intervals", intervals}};
}

// simulation.json (no wall-clock values: the file is part of the byte-identical output).
nlohmann::json simulation_metadata(const SimulationConfig& config, const SimulationPlan& plan,
                                   const World& world, const SceneLighting& lighting,
                                   const std::vector<RenderStats>& stats,
                                   const std::vector<LoopInterval>& loops, const SimulationSummary& summary) {
  const SimulationSettings& s = config.simulation;
  const std::size_t n = plan.frames_used;
  nlohmann::json meta;
  meta["format"] = "loopgate-simulation";
  meta["version"] = kMetadataVersion;
  meta["preset"] = s.preset;
  meta["seed"] = s.seed;
  meta["parameters"] = metadata_parameters(config, lighting.lamps_model());
  meta["world"] = metadata_world(config, world, plan.up_w);
  meta["trajectory"] = {{"format", enum_name(s.trajectory_format)},
                        {"samples", plan.trajectory_samples},
                        {"start_t_ns", plan.trajectory_start_t_ns},
                        {"end_t_ns", plan.trajectory_end_t_ns},
                        {"spline_controls", plan.spline_controls},
                        {"frames_outside_trajectory", plan.frames_outside_trajectory}};
  meta["frames"] = {{"count", n},
                    {"times", plan.frame_times},
                    {"total_in_sequence", plan.frame_t_ns.size()},
                    {"first_t_ns", plan.frame_t_ns.front()},
                    {"last_t_ns", plan.frame_t_ns[n - 1]},
                    {"rate_hz", plan.camera.rate_hz},
                    {"duration_s", summary.duration_s},
                    {"distance_m", summary.distance_m}};
  meta["illumination"] = metadata_illumination(config, plan, lighting, stats);
  meta["imu"] = {
      {"source", enum_name(s.imu_source)}, {"samples", plan.imu.size()}, {"rate_hz", config.imu.rate_hz}};
  meta["loops"] = metadata_loops(config.loops, loops, summary);
  return meta;
}

}  // namespace

SimulationSummary run_simulation(SimulationConfig config, const std::filesystem::path& out_dir,
                                 const SimulationRunOptions& options) {
  const auto t_start = std::chrono::steady_clock::now();
  prepare_out_dir(out_dir, options.force);

  SimulationPlan plan = plan_simulation(config);
  const SimulationSettings& s = config.simulation;
  log_config_lines(config_to_lines(config));

  // World from the whole path (so that a prefix run renders the same images as the full run).
  std::vector<Eigen::Vector3d> path_w;
  path_w.reserve(plan.T_w_c.size());
  for (std::size_t f = 0; f < plan.T_w_c.size(); ++f) path_w.push_back(plan.street_T_w_c(f).translation());
  const World world = build_world(config.world, path_w, plan.up_w);
  const Renderer renderer(world, plan.camera);
  spdlog::info("simulate: world '{}' with {} quads, {} structures ({} aliased)", enum_name(config.world.kind),
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
  const RenderedFrames frames = render_frames(plan, s, renderer, lighting, image_dir);

  write_euroc_camera_csv(cam_dir / "data.csv", frames.entries);
  write_euroc_camera_yaml(cam_dir / "sensor.yaml", plan.camera);
  write_euroc_imu(mav0 / "imu0" / "data.csv", plan.imu);
  write_euroc_imu_yaml(mav0 / "imu0" / "sensor.yaml", plan.imu_calibration);
  write_euroc_groundtruth(mav0 / "state_groundtruth_estimate0" / "data.csv", plan.ground_truth);

  // Ground-truth loops over the frames written.
  const std::vector<LoopInterval> loops = plan_loop_truth(plan, config.loops);
  SimulationSummary summary = summarize(plan, loops, out_dir);
  write_json_file(out_dir / "simulation.json",
                  simulation_metadata(config, plan, world, lighting, frames.stats, loops, summary));
  write_loop_truth_pairs(out_dir / kLoopTruthFile, loops);

  summary.render_s = frames.render_s;
  summary.elapsed_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
  return summary;
}

}  // namespace loopgate::sim
