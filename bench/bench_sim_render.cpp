// Rendering speed of the simulator: frames per second, single thread, along real trajectories when
// the shared data is present (KITTI 00 poses, EuRoC MH_05 ground truth), else along procedural ones.
// The *Night* cases render every frame at full night: the ambient-noise night (ambient light, additive
// noise) and the lamps night (lamps, headlight, photon sensor with auto-exposure), on the same worlds.
#include <benchmark/benchmark.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "sim/illumination.hpp"
#include "sim/lights.hpp"
#include "sim/renderer.hpp"
#include "sim/world.hpp"

namespace {

using loopgate::CameraCalibration;
using loopgate::DistortionModel;
namespace sim = loopgate::sim;

const std::filesystem::path kShared = LOOPGATE_SHARED_DATA_DIR;

std::vector<Eigen::Isometry3d> kitti_poses() {
  std::vector<Eigen::Isometry3d> poses;
  std::ifstream in(kShared / "kitti/00/poses.txt");
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream ss(line);
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 4; ++c) ss >> T.matrix()(r, c);
    }
    poses.push_back(T);
  }
  if (poses.empty()) {  // procedural: a 1 km straight street with gentle curves
    for (int k = 0; k < 1000; ++k) {
      Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
      const double heading = 0.3 * std::sin(k * 0.01);
      T.linear() = Eigen::AngleAxisd(heading, Eigen::Vector3d::UnitY()).toRotationMatrix();
      T.translation() = Eigen::Vector3d(30.0 * std::sin(k * 0.01), 0.0, k * 1.0);
      poses.push_back(T);
    }
  }
  return poses;
}

std::vector<Eigen::Isometry3d> euroc_poses() {
  std::vector<Eigen::Isometry3d> poses;
  Eigen::Isometry3d T_b_c = Eigen::Isometry3d::Identity();
  T_b_c.matrix() << 0.0148655429818, -0.999880929698, 0.00414029679422, -0.0216401454975, 0.999557249008,
      0.0149672133247, 0.025715529948, -0.064676986768, -0.0257744366974, 0.00375618835797, 0.999660727178,
      0.00981073058949, 0.0, 0.0, 0.0, 1.0;
  std::ifstream in(kShared / "euroc/MH_05_difficult/mav0/state_groundtruth_estimate0/data.csv");
  std::string line;
  std::getline(in, line);
  int k = 0;
  while (std::getline(in, line)) {
    if (k++ % 10 != 0) continue;  // 20 Hz like cam0
    for (char& ch : line) ch = ch == ',' ? ' ' : ch;
    std::istringstream ss(line);
    double t = 0, x = 0, y = 0, z = 0, qw = 1, qx = 0, qy = 0, qz = 0;
    ss >> t >> x >> y >> z >> qw >> qx >> qy >> qz;
    Eigen::Isometry3d T_w_b = Eigen::Isometry3d::Identity();
    T_w_b.linear() = Eigen::Quaterniond(qw, qx, qy, qz).normalized().toRotationMatrix();
    T_w_b.translation() = Eigen::Vector3d(x, y, z);
    poses.push_back(T_w_b * T_b_c);
  }
  if (poses.empty()) {  // procedural flight
    for (int i = 0; i < 600; ++i) {
      const double s = i * 0.05;
      Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
      T.linear() = (Eigen::AngleAxisd(0.2 * s, Eigen::Vector3d::UnitZ()) *
                    Eigen::AngleAxisd(-M_PI / 2, Eigen::Vector3d::UnitX()))
                       .toRotationMatrix();
      T.translation() = Eigen::Vector3d(7.0 * std::sin(0.3 * s), 4.0 * std::sin(0.5 * s), 1.2);
      poses.push_back(T);
    }
  }
  return poses;
}

CameraCalibration kitti_camera(int width_px, int height_px) {
  CameraCalibration c;
  const double sx = width_px / 1241.0, sy = height_px / 376.0;
  c.width_px = width_px;
  c.height_px = height_px;
  c.fx = 718.856 * sx;
  c.fy = 718.856 * sx;
  c.cx = 607.19 * sx;
  c.cy = 185.22 * sy;
  return c;
}

CameraCalibration euroc_camera() {
  CameraCalibration c;
  c.width_px = 752;
  c.height_px = 480;
  c.fx = 458.654;
  c.fy = 457.296;
  c.cx = 367.215;
  c.cy = 248.375;
  c.distortion_model = DistortionModel::kRadTan;
  c.distortion = {-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05};
  return c;
}

struct Scene {
  std::vector<Eigen::Isometry3d> poses;
  sim::World world;
};

const Scene& street_scene() {
  static const Scene scene = [] {
    spdlog::set_level(spdlog::level::warn);
    Scene s;
    s.poses = kitti_poses();
    std::vector<Eigen::Vector3d> path;
    for (const auto& T : s.poses) path.push_back(T.translation());
    sim::WorldConfig config;
    config.aliasing_fraction = 0.1;
    s.world = sim::build_world(config, path, Eigen::Vector3d(0, -1, 0));
    return s;
  }();
  return scene;
}

const Scene& hall_scene() {
  static const Scene scene = [] {
    spdlog::set_level(spdlog::level::warn);
    Scene s;
    s.poses = euroc_poses();
    std::vector<Eigen::Vector3d> path;
    for (const auto& T : s.poses) path.push_back(T.translation());
    sim::WorldConfig config;
    config.kind = sim::WorldKind::kHall;
    config.aliasing_fraction = 0.1;
    s.world = sim::build_world(config, path, Eigen::Vector3d(0, 0, 1));
    return s;
  }();
  return scene;
}

void render_along(benchmark::State& state, const Scene& scene, const CameraCalibration& camera) {
  const sim::Renderer renderer(scene.world, camera);
  const sim::IlluminationSchedule schedule;
  // Spread the frames over the whole sequence (day, dusk and night, every part of the route).
  const std::size_t stride = std::max<std::size_t>(1, scene.poses.size() / 97);
  std::size_t k = 0;
  for (auto _ : state) {
    const std::size_t frame = (k * stride) % scene.poses.size();
    const double phase = static_cast<double>(frame) / static_cast<double>(scene.poses.size() - 1);
    cv::Mat image = renderer.render(scene.poses[frame], schedule.at(phase), frame);
    benchmark::DoNotOptimize(image.data);
    ++k;
  }
  state.counters["frames_per_s"] =
      benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}

// Every frame at full night under `night_model`, along the scene's poses.
void render_night(benchmark::State& state, const Scene& scene, const CameraCalibration& camera,
                  sim::NightModel night_model) {
  const sim::Renderer renderer(scene.world, camera);
  sim::IlluminationSchedule schedule;
  schedule.night_model = night_model;
  std::vector<Eigen::Vector3d> path;
  for (const auto& T : scene.poses) path.push_back(T.translation());
  const sim::SceneLighting lighting(schedule, sim::LightsConfig{}, sim::SensorConfig{}, scene.world, path, 1);
  const sim::Illumination light = lighting.illumination(1.0);
  const std::size_t stride = std::max<std::size_t>(1, scene.poses.size() / 97);
  std::size_t k = 0;
  double lights = 0.0;
  for (auto _ : state) {
    const std::size_t frame = (k * stride) % scene.poses.size();
    const std::vector<sim::SpotLight> frame_lights = lighting.lights(1.0, scene.poses[frame]);
    cv::Mat image = renderer.render(scene.poses[frame], light, frame, frame_lights);
    benchmark::DoNotOptimize(image.data);
    lights += static_cast<double>(frame_lights.size());
    ++k;
  }
  state.counters["frames_per_s"] =
      benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
  state.counters["lights_per_frame"] = lights / static_cast<double>(std::max<std::size_t>(1, k));
}

void BM_RenderStreet640x200NightAmbientNoise(benchmark::State& state) {
  render_night(state, street_scene(), kitti_camera(640, 200), sim::NightModel::kAmbientNoise);
}
void BM_RenderStreet640x200NightLamps(benchmark::State& state) {
  render_night(state, street_scene(), kitti_camera(640, 200), sim::NightModel::kLamps);
}
void BM_RenderStreet1241x376NightAmbientNoise(benchmark::State& state) {
  render_night(state, street_scene(), kitti_camera(1241, 376), sim::NightModel::kAmbientNoise);
}
void BM_RenderStreet1241x376NightLamps(benchmark::State& state) {
  render_night(state, street_scene(), kitti_camera(1241, 376), sim::NightModel::kLamps);
}
void BM_RenderHall752x480NightAmbientNoise(benchmark::State& state) {
  render_night(state, hall_scene(), euroc_camera(), sim::NightModel::kAmbientNoise);
}
void BM_RenderHall752x480NightLamps(benchmark::State& state) {
  render_night(state, hall_scene(), euroc_camera(), sim::NightModel::kLamps);
}

void BM_RenderStreet1241x376(benchmark::State& state) {
  render_along(state, street_scene(), kitti_camera(1241, 376));
}
void BM_RenderHall752x480Radtan(benchmark::State& state) {
  render_along(state, hall_scene(), euroc_camera());
}
void BM_RenderStreet640x200(benchmark::State& state) {
  render_along(state, street_scene(), kitti_camera(640, 200));
}

void BM_BuildStreetWorld(benchmark::State& state) {
  spdlog::set_level(spdlog::level::warn);
  std::vector<Eigen::Vector3d> path;
  for (const auto& T : kitti_poses()) path.push_back(T.translation());
  for (auto _ : state) {
    sim::World world = sim::build_world(sim::WorldConfig{}, path, Eigen::Vector3d(0, -1, 0));
    benchmark::DoNotOptimize(world.quads.data());
  }
}

BENCHMARK(BM_RenderStreet1241x376)->Unit(benchmark::kMillisecond)->MeasureProcessCPUTime()->MinTime(3.0);
BENCHMARK(BM_RenderHall752x480Radtan)->Unit(benchmark::kMillisecond)->MeasureProcessCPUTime()->MinTime(3.0);
BENCHMARK(BM_RenderStreet640x200)->Unit(benchmark::kMillisecond)->MeasureProcessCPUTime()->MinTime(3.0);
BENCHMARK(BM_RenderStreet640x200NightAmbientNoise)
    ->Unit(benchmark::kMillisecond)
    ->MeasureProcessCPUTime()
    ->MinTime(3.0);
BENCHMARK(BM_RenderStreet640x200NightLamps)
    ->Unit(benchmark::kMillisecond)
    ->MeasureProcessCPUTime()
    ->MinTime(3.0);
BENCHMARK(BM_RenderStreet1241x376NightAmbientNoise)
    ->Unit(benchmark::kMillisecond)
    ->MeasureProcessCPUTime()
    ->MinTime(3.0);
BENCHMARK(BM_RenderStreet1241x376NightLamps)
    ->Unit(benchmark::kMillisecond)
    ->MeasureProcessCPUTime()
    ->MinTime(3.0);
BENCHMARK(BM_RenderHall752x480NightAmbientNoise)
    ->Unit(benchmark::kMillisecond)
    ->MeasureProcessCPUTime()
    ->MinTime(3.0);
BENCHMARK(BM_RenderHall752x480NightLamps)
    ->Unit(benchmark::kMillisecond)
    ->MeasureProcessCPUTime()
    ->MinTime(3.0);
BENCHMARK(BM_BuildStreetWorld)->Unit(benchmark::kMillisecond)->MeasureProcessCPUTime()->Iterations(2);

}  // namespace

BENCHMARK_MAIN();
