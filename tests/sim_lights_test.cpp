// The lamps night model: spot lights (inverse-square fall-off, cones, the headlight attached to the camera),
// the photon sensor through the renderer (noise variance = gain x signal + read^2), lamps placed in both
// worlds and switched by the schedule, determinism whatever the thread count, and the ambient-noise night
// left as it was.
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <cmath>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <sstream>

#include "core/error.hpp"
#include "io/config.hpp"
#include "sim/lights.hpp"
#include "sim/renderer.hpp"
#include "sim/sensor.hpp"
#include "sim/simulator.hpp"
#include "test_support.hpp"

namespace loopgate::sim {
namespace {

namespace fs = std::filesystem;

constexpr std::uint8_t kWallTexel = 200;  // albedo 200 / 255

// A camera at the origin looking along +z (image down = +y), 320 x 240, 60 degrees wide.
CameraCalibration test_camera() {
  CameraCalibration c;
  c.width_px = 320;
  c.height_px = 240;
  c.fx = c.fy = 277.0;
  c.cx = 159.5;
  c.cy = 119.5;
  return c;
}

// A uniform wall (albedo 200/255) of 40 m x 40 m in the plane z = wall_z, centred on the optical axis,
// plus (optionally) a second one behind the camera at z = -wall_z.
World wall_world(float wall_z, bool wall_behind = false) {
  World world;
  world.up_w = Eigen::Vector3d(0.0, -1.0, 0.0);
  const int px = 64;
  world.textures.emplace_back(
      px, px, std::vector<std::uint8_t>(static_cast<std::size_t>(px * px), kWallTexel), false);
  Structure s;
  s.kind = StructureKind::kWall;
  world.structures.push_back(s);
  for (const float z : wall_behind ? std::vector<float>{wall_z, -wall_z} : std::vector<float>{wall_z}) {
    Quad q;
    q.origin_w = Eigen::Vector3f(-20.0f, -20.0f, z);
    q.axis_u_w = q.dual_u_w = Eigen::Vector3f::UnitX();
    q.axis_v_w = q.dual_v_w = Eigen::Vector3f::UnitY();
    q.normal_w = Eigen::Vector3f::UnitZ();
    q.width_m = q.height_m = 40.0f;
    q.texels_per_m = 1.6f;
    world.quads.push_back(q);
  }
  rebuild_acceleration(&world);
  return world;
}

// No haze: the walls keep their radiance.
RendererConfig no_haze() {
  RendererConfig config;
  config.haze_distance_m = 0.0;
  return config;
}

// Linear light: gamma 1, no vignetting, no noise, no sun; `ambient` only.
Illumination linear_light(double exposure, double ambient) {
  Illumination light;
  light.exposure = exposure;
  light.gamma = 1.0;
  light.ambient = ambient;
  light.sun_intensity = 0.0;
  light.sky_brightness = 0.0;
  light.vignetting = 0.0;
  light.noise_sigma = 0.0;
  return light;
}

// A round spot at position pointing along axis, with a wide flat cone (no fall-off within 70 degrees) and a
// far range (no window within 10 m).
SpotLight wide_spot(const Eigen::Vector3f& position, const Eigen::Vector3f& axis, float intensity) {
  SpotLight light;
  light.position_w = position;
  light.axis_w = axis.normalized();
  light.side_w = Eigen::Vector3f::UnitX();
  light.across_w = light.axis_w.cross(light.side_w);
  light.intensity = intensity;
  light.tan_half_width = light.tan_half_height = std::tan(80.0f * 3.14159265f / 180.0f);
  light.inner_fraction = std::tan(70.0f * 3.14159265f / 180.0f) / light.tan_half_width;
  light.range_m = 1000.0f;
  return light;
}

// Mean grey of a (2 r + 1)^2 patch around (u, v).
double patch_mean(const cv::Mat& image, int u, int v, int r = 2) {
  return cv::mean(image(cv::Rect(u - r, v - r, 2 * r + 1, 2 * r + 1)))[0];
}

// Pixel of world point p_w seen from the identity pose.
cv::Point pixel_of(const Renderer& renderer, const Eigen::Vector3d& p_w) {
  Eigen::Vector2d uv;
  EXPECT_TRUE(renderer.camera().project(p_w, &uv));
  return cv::Point(static_cast<int>(std::lround(uv.x())), static_cast<int>(std::lround(uv.y())));
}

TEST(Lights, LampBrightensTheWallNearItWithInverseSquareFallOff) {
  const float wall_z = 10.0f;
  const World world = wall_world(wall_z);
  const Renderer renderer(world, test_camera(), no_haze());
  const Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  const Illumination light = linear_light(4.0, 0.0);
  // The light 2 m then 4 m in front of the wall point (0, 0, 10), pointing at the wall.
  const auto lit = [&](float distance, const Eigen::Vector3d& at) {
    const SpotLight lamp =
        wide_spot(Eigen::Vector3f(0.0f, 0.0f, wall_z - distance), Eigen::Vector3f::UnitZ(), 0.8f);
    const cv::Mat image = renderer.render(T, light, 1, std::vector<SpotLight>{lamp});
    const cv::Point px = pixel_of(renderer, at);
    return patch_mean(image, px.x, px.y);
  };
  const Eigen::Vector3d foot(0.0, 0.0, wall_z);
  const double albedo = kWallTexel / 255.0;
  const double near = lit(2.0f, foot), far = lit(4.0f, foot);
  // Expected 255 * exposure * albedo * I / d^2: 160 and 40.
  EXPECT_NEAR(near, 255.0 * 4.0 * albedo * 0.8 / 4.0, 1.0);
  EXPECT_NEAR(near / far, 4.0, 0.08) << "inverse square: twice the distance, a quarter of the light";
  // Along the wall, 2 m to the side of the foot at 2 m: the distance grows by sqrt(2) and the incidence is 45
  // degrees: irradiance / 2^(3/2).
  const double side = lit(2.0f, Eigen::Vector3d(2.0, 0.0, wall_z));
  EXPECT_NEAR(near / side, std::pow(2.0, 1.5), 0.1);
  // Without the lamp the wall is black (no ambient), so everything above comes from the lamp.
  const cv::Mat dark = renderer.render(T, light, 1);
  EXPECT_EQ(cv::countNonZero(dark), 0);
}

TEST(Lights, SpotIrradianceFollowsTheModel) {
  const SpotLight lamp = wide_spot(Eigen::Vector3f(0.0f, 5.0f, 0.0f), -Eigen::Vector3f::UnitY(), 3.0f);
  const Eigen::Vector3f up = Eigen::Vector3f::UnitY();
  // Below the lamp at 5 m: I / 25; the back of the surface gets nothing; nothing above the lamp.
  EXPECT_NEAR(spot_irradiance(lamp, Eigen::Vector3f::Zero(), up), 3.0f / 25.0f, 1e-6f);
  EXPECT_EQ(spot_irradiance(lamp, Eigen::Vector3f::Zero(), -up), 0.0f);
  EXPECT_EQ(spot_irradiance(lamp, Eigen::Vector3f(0.0f, 8.0f, 0.0f), -up), 0.0f);
  // The smooth cone: full inside the inner cone, less in the transition, nothing beyond the outer cone.
  SpotLight narrow = lamp;
  narrow.tan_half_width = narrow.tan_half_height = 1.0f;  // 45 degrees
  narrow.inner_fraction = 0.5f;
  const float axis = spot_irradiance(narrow, Eigen::Vector3f::Zero(), up);
  const float inside = spot_irradiance(narrow, Eigen::Vector3f(2.0f, 0.0f, 0.0f), up);      // r = 0.4
  const float transition = spot_irradiance(narrow, Eigen::Vector3f(4.0f, 0.0f, 0.0f), up);  // r = 0.8
  const float outside = spot_irradiance(narrow, Eigen::Vector3f(6.0f, 0.0f, 0.0f), up);     // r = 1.2
  EXPECT_NEAR(inside, axis * std::pow(25.0f / 29.0f, 1.5f), 1e-6f);                         // geometry only
  EXPECT_GT(transition, 0.0f);
  EXPECT_LT(transition, axis * std::pow(25.0f / 41.0f, 1.5f) * 0.5f);
  EXPECT_EQ(outside, 0.0f);
  // The range window ends the light smoothly.
  narrow.range_m = 5.2f;
  EXPECT_LT(spot_irradiance(narrow, Eigen::Vector3f::Zero(), up), 0.1f * axis);
  narrow.range_m = 5.0f;
  EXPECT_EQ(spot_irradiance(narrow, Eigen::Vector3f::Zero(), up), 0.0f);
}

TEST(Lights, HeadlightLightsWhatIsInFrontNotBehind) {
  const LightsConfig config;
  const Eigen::Isometry3d T = Eigen::Isometry3d::Identity();  // KITTI-like: x right, y down, z forward
  const SpotLight beam = make_headlight(WorldKind::kStreet, config, T);
  EXPECT_NEAR(beam.position_w.y(), config.headlight_below_camera_m, 1e-6);
  EXPECT_GT(beam.axis_w.z(), 0.99f);
  EXPECT_GT(beam.axis_w.y(), 0.0f);  // pitched down
  const Eigen::Vector3f facing_car = -Eigen::Vector3f::UnitZ();
  const auto at = [&](float x, float z) {
    return spot_irradiance(beam, Eigen::Vector3f(x, beam.position_w.y(), z),
                           z > 0.0f ? facing_car : -facing_car);
  };
  // In front: lit, less further away and less off the axis; behind and far to the side: nothing.
  EXPECT_GT(at(0.0f, 10.0f), 0.0f);
  EXPECT_GT(at(0.0f, 10.0f), 3.0f * at(0.0f, 20.0f));
  EXPECT_GT(at(0.0f, 20.0f), at(6.0f, 20.0f));
  EXPECT_EQ(at(0.0f, -10.0f), 0.0f);
  EXPECT_EQ(at(20.0f, 10.0f), 0.0f);  // 63 degrees to the side

  // Rendered: a wall 10 m ahead is brighter with the headlight; looking back at a wall 10 m behind, the
  // headlight (still on the car looking forward) adds nothing.
  const World world = wall_world(10.0f, true);
  const Renderer renderer(world, test_camera(), no_haze());
  const Illumination light = linear_light(4.0, 0.01);
  const std::vector<SpotLight> lights{beam};
  const cv::Mat ahead_off = renderer.render(T, light, 1), ahead_on = renderer.render(T, light, 1, lights);
  Eigen::Isometry3d back = T;
  back.linear() = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitY()).toRotationMatrix();
  const cv::Mat behind_off = renderer.render(back, light, 1),
                behind_on = renderer.render(back, light, 1, lights);
  EXPECT_GT(patch_mean(ahead_on, 160, 122, 10), patch_mean(ahead_off, 160, 122, 10) + 20.0);
  EXPECT_EQ(cv::norm(behind_on, behind_off, cv::NORM_L1), 0.0);
}

// Mean and variance of a central 200 x 160 patch of a flat wall under the photon sensor at a fixed exposure
// scale (exposure_time fixed, gain forced to `gain` by an unreachable target) and gamma 1.
struct PatchStats {
  double mean = 0.0;
  double variance = 0.0;
};
PatchStats flat_patch(double ambient, double gain, const SensorConfig& base, std::uint64_t seed) {
  static const World world = wall_world(10.0f);
  static const Renderer renderer(world, test_camera(), no_haze());
  Illumination light = linear_light(1.0, ambient);
  light.photon_sensor = true;
  light.sensor = base;
  light.sensor.ae_min_exposure = light.sensor.ae_max_exposure = 1.0;
  light.sensor.ae_max_gain = gain;
  light.sensor.ae_target_grey = 254.9;
  RenderStats stats;
  const cv::Mat image = renderer.render(Eigen::Isometry3d::Identity(), light, seed, {}, &stats);
  EXPECT_DOUBLE_EQ(stats.gain, gain);
  cv::Scalar mean, sd;
  cv::meanStdDev(image(cv::Rect(60, 40, 200, 160)), mean, sd);
  return {mean[0], sd[0] * sd[0]};
}

TEST(Sensor, NoiseVarianceIsGainTimesSignalPlusReadNoise) {
  SensorConfig sensor;
  sensor.full_well_e = 5000.0;
  sensor.read_noise_e = 4.0;
  const double albedo = kWallTexel / 255.0;
  for (const double gain : {1.0, 8.0}) {
    const double dn_per_e = 255.0 * gain / sensor.full_well_e;
    for (const double signal_dn : {20.0, 60.0, 150.0}) {
      const double ambient = signal_dn / (255.0 * gain * albedo);
      const PatchStats patch = flat_patch(ambient, gain, sensor, 3);
      // var = G S + (G r)^2 in linear grey levels, plus 1/12 of rounding to integers.
      const double expected = dn_per_e * signal_dn + std::pow(dn_per_e * sensor.read_noise_e, 2) + 1.0 / 12.0;
      EXPECT_NEAR(patch.mean, signal_dn, 0.3) << "gain " << gain;
      EXPECT_NEAR(patch.variance / expected, 1.0, 0.08)
          << "gain " << gain << ", signal " << signal_dn << ": variance " << patch.variance << " expected "
          << expected;
      std::printf("gain %.0f signal %5.1f: variance %6.2f (model %6.2f)\n", gain, signal_dn, patch.variance,
                  expected);
    }
  }
  // The same mean grey is noisier at a higher gain (fewer electrons behind it).
  const double albedo_signal = 100.0 / (255.0 * albedo);
  EXPECT_GT(flat_patch(albedo_signal / 8.0, 8.0, sensor, 4).variance,
            4.0 * flat_patch(albedo_signal, 1.0, sensor, 4).variance);
}

SimulationConfig night_loop(std::int64_t frames) {
  SimulationConfig config = make_preset("night-loop", "");
  config.simulation.max_frames = frames;
  return config;
}

TEST(Lights, LampsAlongTheStreetAndUnderTheHallCeiling) {
  // Street: one lamp per kerb post, above it and towards the road, pointing down; 10% out (seeded).
  SimulationConfig config = night_loop(0);
  const SimulationPlan plan = plan_simulation(config);
  std::vector<Eigen::Vector3d> path;
  for (const Eigen::Isometry3d& T : plan.T_w_c) path.push_back(T.translation());
  const World street = build_world(config.world, path, plan.up_w);
  int posts = 0;
  for (const Structure& s : street.structures) posts += s.kind == StructureKind::kPole ? 1 : 0;
  const Lamps lamps = make_lamps(street, config.lights, path, 1);
  ASSERT_EQ(static_cast<int>(lamps.lights.size()), posts);
  ASSERT_GE(posts, 8);
  for (const SpotLight& lamp : lamps.lights) {
    EXPECT_NEAR(lamp.position_w.z(),
                config.world.street_pole_height_m + config.lights.street_lamp_above_post_m, 1e-3);
    EXPECT_LT(lamp.axis_w.z(), -0.9f);
    // Over the road side of its post: nearer the path than the post (6.5 m from its place on the path)
    // by the arm, and clear of the path.
    double nearest = 1e9;
    for (const Eigen::Vector3d& p : path) {
      nearest = std::min(nearest, (p - lamp.position_w.cast<double>()).head<2>().norm());
    }
    EXPECT_LE(nearest, config.world.street_pole_offset_m - config.lights.street_lamp_arm_m + 0.05);
    EXPECT_GE(nearest, config.world.street_clearance_m - config.lights.street_lamp_arm_m);
  }
  EXPECT_EQ(lamps.out_count(), make_lamps(street, config.lights, path, 1).out_count());
  std::size_t out_total = 0, lamps_total = 0;
  for (std::uint64_t seed = 1; seed <= 20; ++seed) {
    out_total += make_lamps(street, config.lights, path, seed).out_count();
    lamps_total += lamps.lights.size();
  }
  EXPECT_NEAR(static_cast<double>(out_total) / static_cast<double>(lamps_total),
              config.lights.lamp_out_fraction, 0.05);

  // Hall: a grid under the ceiling, pointing down.
  WorldConfig hall_config;
  hall_config.kind = sim::WorldKind::kHall;
  std::vector<Eigen::Vector3d> flight;
  for (int k = 0; k < 200; ++k) flight.emplace_back(8.0 * std::sin(0.03 * k), 5.0 * std::cos(0.05 * k), 1.5);
  const World hall = build_world(hall_config, flight, Eigen::Vector3d::UnitZ());
  const Lamps hall_lamps = make_lamps(hall, config.lights, flight, 1);
  // The room is 16 + 2 x 4 = 24 m by 10 + 8 = 18 m: 2 x 2 lamps at 10 m spacing.
  ASSERT_EQ(hall_lamps.lights.size(), 4u);
  for (const SpotLight& lamp : hall_lamps.lights) {
    EXPECT_NEAR(lamp.position_w.z(),
                1.5 + hall_config.hall_ceiling_above_m - config.lights.hall_lamp_below_ceiling_m, 1e-4);
    EXPECT_LT(lamp.axis_w.z(), -0.999f);
  }
}

TEST(Lights, TheScheduleSwitchesLampsAndHeadlight) {
  SimulationConfig config = night_loop(0);
  const SimulationPlan plan = plan_simulation(config);
  std::vector<Eigen::Vector3d> path;
  for (const Eigen::Isometry3d& T : plan.T_w_c) path.push_back(T.translation());
  const World world = build_world(config.world, path, plan.up_w);
  const SceneLighting lighting(config.illumination, config.lights, config.sensor, world, path, 1);
  ASSERT_TRUE(lighting.lamps_model());
  // Day: no lights, the photon sensor, the day's ambient. Night: lamps near the camera and the headlight, the
  // lamps model's dark ambient.
  const Illumination day = lighting.illumination(0.0), night = lighting.illumination(1.0);
  EXPECT_TRUE(day.photon_sensor);
  EXPECT_DOUBLE_EQ(day.ambient, config.illumination.day_ambient);
  EXPECT_DOUBLE_EQ(night.ambient, config.lights.night_ambient);
  EXPECT_DOUBLE_EQ(night.sky_brightness, config.lights.night_sky_brightness);
  EXPECT_TRUE(lighting.lights(0.0, plan.T_w_c[10]).empty());
  const std::vector<SpotLight> on = lighting.lights(1.0, plan.T_w_c[300]);
  std::size_t working = 0;
  for (const char w : lighting.lamps().working) working += w ? 1u : 0u;
  EXPECT_EQ(on.size(), working + 1);  // every working lamp of the block is within 250 m, and the headlight
  EXPECT_EQ(on.back().head_radius_m, 0.0f);  // the headlight has no visible head
  // Rendered at night: the lamps and the headlight make the street brighter than the ambient light alone.
  const Renderer renderer(world, plan.camera);
  const cv::Mat lit = renderer.render(plan.T_w_c[300], night, 1, on);
  const cv::Mat unlit = renderer.render(plan.T_w_c[300], night, 1);
  EXPECT_GT(cv::mean(lit)[0], cv::mean(unlit)[0] + 20.0);
}

std::string read_bytes(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  std::ostringstream buffer;
  buffer << in.rdbuf();
  return buffer.str();
}

std::map<std::string, std::string> tree(const fs::path& dir) {
  std::map<std::string, std::string> files;
  for (const auto& entry : fs::recursive_directory_iterator(dir)) {
    if (entry.is_regular_file()) files[fs::relative(entry.path(), dir).string()] = read_bytes(entry.path());
  }
  return files;
}

TEST(Lights, NightFramesAreTheSameBytesWhateverTheThreadCount) {
  const fs::path root = loopgate::testing::make_temp_dir("sim-lights-determinism");
  // The first 6 frames of the night loop, at night; rendered with 1 thread, then twice with 2 threads in
  // batches of 3 frames.
  SimulationConfig config = night_loop(6);
  config.illumination.jump_phase = 0.0;  // night from frame 0
  config.simulation.render_batch_frames = 3;
  std::map<std::string, std::string> runs[3];
  for (int run = 0; run < 3; ++run) {
    const int threads = run == 0 ? 1 : 2;
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism,
                              static_cast<std::size_t>(threads));
    const fs::path out = root / std::to_string(run);
    run_simulation(config, out);
    runs[run] = tree(out);
  }
  ASSERT_EQ(runs[0].size(), 6u + 7u);  // 6 images + 7 other files (loop_truth.csv among them)
  for (int run = 1; run < 3; ++run) {
    ASSERT_EQ(runs[run].size(), runs[0].size());
    for (const auto& [path, bytes] : runs[0]) {
      EXPECT_TRUE(runs[run].at(path) == bytes) << path << " differs in run " << run;
    }
  }
  // Night frames: lamps on, headlight on, the gain up.
  const nlohmann::json meta = nlohmann::json::parse(runs[0].at("simulation.json"));
  EXPECT_EQ(meta["illumination"]["night_model"], "lamps");
  for (std::size_t f = 0; f < 6; ++f) {
    EXPECT_TRUE(meta["illumination"]["lamps_on"][f].get<bool>());
    EXPECT_TRUE(meta["illumination"]["headlight_on"][f].get<bool>());
    EXPECT_GT(meta["illumination"]["gain"][f].get<double>(), 2.0);
  }
  EXPECT_TRUE(meta["parameters"].contains("lights"));
  EXPECT_TRUE(meta["parameters"]["world"]["street_ground_exact_cells"].get<bool>());
  // Another seed: other noise (and other lamps out).
  config.simulation.seed = 2;
  run_simulation(config, root / "seed2");
  const auto other = tree(root / "seed2");
  std::size_t differing = 0;
  for (const auto& [path, bytes] : runs[0]) differing += other.at(path) != bytes ? 1 : 0;
  EXPECT_GE(differing, 6u);
}

TEST(Lights, TheAmbientNoiseNightIsTheDefaultAndUnchanged) {
  // The default night model renders exactly what the renderer renders without lights (as before the lamps
  // model), and its simulation.json carries none of the lamps model's keys.
  SimulationConfig config = make_preset("demo-dusk", "");
  EXPECT_EQ(config.illumination.night_model, sim::NightModel::kAmbientNoise);
  const SimulationPlan plan = plan_simulation(config);
  EXPECT_FALSE(config.world.street_ground_exact_cells);
  std::vector<Eigen::Vector3d> path;
  for (const Eigen::Isometry3d& T : plan.T_w_c) path.push_back(T.translation());
  const World world = build_world(config.world, path, plan.up_w);
  const SceneLighting lighting(config.illumination, config.lights, config.sensor, world, path, 1);
  EXPECT_FALSE(lighting.lamps_model());
  EXPECT_TRUE(lighting.lamps().lights.empty());
  const Renderer renderer(world, plan.camera);
  for (const double phase : {0.0, 0.75, 1.0}) {
    EXPECT_TRUE(lighting.lights(phase, plan.T_w_c[500]).empty());
    const Illumination a = lighting.illumination(phase), b = config.illumination.at(phase);
    EXPECT_FALSE(a.photon_sensor);
    EXPECT_EQ(a.ambient, b.ambient);
    EXPECT_EQ(a.noise_sigma, b.noise_sigma);
    EXPECT_EQ(cv::norm(renderer.render(plan.T_w_c[500], a, 9, lighting.lights(phase, plan.T_w_c[500])),
                       renderer.render(plan.T_w_c[500], b, 9), cv::NORM_L1),
              0.0);
  }
  const fs::path out = loopgate::testing::make_temp_dir("sim-lights-default") / "demo";
  config.simulation.max_frames = 3;
  run_simulation(config, out);
  std::ifstream in(out / "simulation.json");
  const nlohmann::json meta = nlohmann::json::parse(in);
  EXPECT_FALSE(meta["parameters"].contains("lights"));
  EXPECT_FALSE(meta["parameters"].contains("sensor"));
  EXPECT_FALSE(meta["parameters"]["illumination"].contains("night_model"));
  EXPECT_FALSE(meta["parameters"]["world"].contains("street_ground_exact_cells"));
  EXPECT_FALSE(meta["illumination"].contains("gain"));
}

TEST(Lights, AnyPresetSwitchesToTheLampsNightWithSet) {
  for (const std::string name : {"kitti00", "euroc-mh05", "demo-dusk", "aliasing"}) {
    SimulationConfig config = make_preset(name, "/data");
    RawConfig raw;
    raw.apply_override("illumination.night_model=lamps");
    apply_config(raw, config);
    EXPECT_EQ(config.illumination.night_model, sim::NightModel::kLamps) << name;
  }
  SimulationConfig config = make_preset("demo", "");
  RawConfig raw;
  raw.apply_override("illumination.night_model=moonlight");
  try {
    apply_config(raw, config);
    FAIL() << "expected ConfigError";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("illumination.night_model"), std::string::npos) << e.what();
  }
  raw = RawConfig{};
  raw.apply_override("lights.lamp_out_fraction=1.5");
  EXPECT_THROW(apply_config(raw, config), ConfigError);
}

}  // namespace
}  // namespace loopgate::sim
