// The simulator driver: presets, planning (frames, ground truth, IMU), ground-truth loops, and a small
// run into the EuRoC layout read back through open_euroc.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>
#include <set>

#include "core/error.hpp"
#include "core/geometry.hpp"
#include "io/config.hpp"
#include "io/dataset.hpp"
#include "io/trajectory_io.hpp"
#include "sim/renderer.hpp"
#include "sim/simulator.hpp"
#include "test_support.hpp"

namespace loopgate::sim {
namespace {

std::filesystem::path shared() {
  return loopgate::testing::shared_data_dir();
}

double pose_error(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  return (a.translation() - b.translation()).norm() + so3_log(a.linear().transpose() * b.linear()).norm();
}

// Corners (Shi-Tomasi) of frame f tracked by pyramidal KLT into frame f + 1 of the preset, forward-backward
// checked (0.5 px).
int klt_tracked_between_consecutive_frames(SimulationConfig config, std::size_t frame) {
  const SimulationPlan plan = plan_simulation(config);
  std::vector<Eigen::Vector3d> path_w;
  for (const Eigen::Isometry3d& T : plan.T_w_c) path_w.push_back(T.translation());
  const World world = build_world(config.world, path_w, plan.up_w);
  const Renderer renderer(world, plan.camera);
  const double phase = static_cast<double>(frame) / static_cast<double>(plan.frame_t_ns.size() - 1);
  const cv::Mat a = renderer.render(plan.T_w_c[frame], config.illumination.at(phase), 1);
  const cv::Mat b = renderer.render(plan.T_w_c[frame + 1], config.illumination.at(phase), 2);
  std::vector<cv::Point2f> corners;
  cv::goodFeaturesToTrack(a, corners, 500, 0.01, 8.0);
  if (corners.empty()) return 0;
  std::vector<cv::Point2f> forward, backward;
  std::vector<unsigned char> status_f, status_b;
  std::vector<float> err;
  cv::calcOpticalFlowPyrLK(a, b, corners, forward, status_f, err);
  cv::calcOpticalFlowPyrLK(b, a, forward, backward, status_b, err);
  int good = 0;
  for (std::size_t i = 0; i < corners.size(); ++i) {
    if (status_f[i] && status_b[i] && cv::norm(corners[i] - backward[i]) < 0.5) ++good;
  }
  return good;
}

TEST(SimulatorPresets, KltTracksConsecutiveFramesOfEachPreset) {
  SimulationConfig demo = make_preset("demo-dusk", "");
  const int demo_day = klt_tracked_between_consecutive_frames(demo, 120);
  const int demo_night = klt_tracked_between_consecutive_frames(demo, 480);
  std::printf("KLT tracks: demo-dusk day %d, dusk %d\n", demo_day, demo_night);
  EXPECT_GE(demo_day, 100);
  EXPECT_GE(demo_night, 100);
  if (!shared().empty() && std::filesystem::exists(shared() / "kitti/00/poses.txt")) {
    const int kitti = klt_tracked_between_consecutive_frames(make_preset("kitti00", shared()), 1000);
    std::printf("KLT tracks: kitti00 frame 1000 -> 1001: %d\n", kitti);
    EXPECT_GE(kitti, 100);
  }
  if (!shared().empty() && std::filesystem::exists(shared() / "euroc/MH_05_difficult/mav0/imu0/data.csv")) {
    const int mh05 = klt_tracked_between_consecutive_frames(make_preset("euroc-mh05", shared()), 1000);
    std::printf("KLT tracks: euroc-mh05 frame 1000 -> 1001: %d\n", mh05);
    EXPECT_GE(mh05, 100);
  }
}

TEST(SimulatorPresets, KnownNamesAndClearErrorForOthers) {
  ASSERT_EQ(preset_names(), (std::vector<std::string>{"aliasing", "demo", "demo-dusk", "euroc-mh05",
                                                      "kitti00", "night-loop"}));
  for (const std::string& name : preset_names()) {
    SimulationConfig c = make_preset(name, "/nonexistent");
    EXPECT_EQ(c.simulation.preset, name);
    EXPECT_NO_THROW(c.validate()) << name;
  }
  try {
    make_preset("kitti01", "/nonexistent");
    FAIL() << "expected ConfigError";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("demo"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("kitti01"), std::string::npos) << e.what();
  }
  SimulationConfig bad = make_preset("demo", "");
  bad.simulation.imu_source = ImuSource::kFile;  // a file IMU needs a recorded trajectory
  EXPECT_THROW(bad.validate(), ConfigError);
}

TEST(SimulatorPresets, KittiAndEurocPresetParameters) {
  const SimulationConfig k = make_preset("kitti00", "/data");
  EXPECT_EQ(k.simulation.trajectory_file, "/data/kitti/00/poses.txt");
  EXPECT_EQ(k.camera.width_px, 1241);
  EXPECT_EQ(k.camera.height_px, 376);
  EXPECT_DOUBLE_EQ(k.camera.fx, 718.856);
  EXPECT_DOUBLE_EQ(k.camera.cx, 607.1928);
  EXPECT_DOUBLE_EQ(k.simulation.up_y, -1.0);
  EXPECT_EQ(k.world.kind, sim::WorldKind::kStreet);
  const SimulationConfig e = make_preset("euroc-mh05", "/data");
  EXPECT_EQ(e.simulation.imu_source, sim::ImuSource::kFile);
  EXPECT_EQ(e.world.kind, sim::WorldKind::kHall);
  EXPECT_EQ(e.camera.distortion_model, SimDistortion::kRadTan);
}

// Frames (of the first `frames`) whose camera is within radius_m (horizontally) of c, as [first, last] runs.
std::vector<std::pair<std::size_t, std::size_t>> passes_near(const std::vector<Eigen::Isometry3d>& T_w_c,
                                                             std::size_t frames, const Eigen::Vector2d& c,
                                                             double radius_m) {
  std::vector<std::pair<std::size_t, std::size_t>> runs;
  for (std::size_t f = 0; f < frames; ++f) {
    if ((T_w_c[f].translation().head<2>() - c).norm() > radius_m) continue;
    if (!runs.empty() && runs.back().second + 1 == f) {
      runs.back().second = f;
    } else {
      runs.emplace_back(f, f);
    }
  }
  return runs;
}

TEST(SimulatorPresets, AliasingPresetCopiesOnePlaceOntoAFarPlaceDrivenOnce) {
  SimulationConfig config = make_preset("aliasing", "");
  const SimulationPlan plan = plan_simulation(config);
  ASSERT_EQ(plan.frames_used, 490u);
  EXPECT_EQ(plan.camera.width_px, 320);
  EXPECT_EQ(plan.camera.height_px, 100);
  EXPECT_EQ(config.world.aliasing_fraction, 0.0);  // only the deterministic copy aliases
  std::vector<Eigen::Vector3d> path_w;
  for (const Eigen::Isometry3d& T : plan.T_w_c) path_w.push_back(T.translation());
  const World world = build_world(config.world, path_w, plan.up_w);

  // Every aliased structure is a copied facade whose source shares its texture seed, style and texture
  // and stands more than 50 m away (around place A, while the copy stands around place B).
  const Eigen::Vector2d place_a(config.world.alias_copy_source_x_m, config.world.alias_copy_source_y_m);
  const Eigen::Vector2d place_b(config.world.alias_copy_target_x_m, config.world.alias_copy_target_y_m);
  EXPECT_GT((place_a - place_b).norm(), 50.0);
  const auto centre = [&](int structure) {
    for (const Quad& q : world.quads) {
      if (q.structure == structure)
        return Eigen::Vector2d((q.origin_w + 0.5f * q.width_m * q.axis_u_w).head<2>().cast<double>());
    }
    return Eigen::Vector2d(NAN, NAN);
  };
  std::vector<Eigen::Vector2d> copies, sources;
  for (std::size_t k = 0; k < world.structures.size(); ++k) {
    const Structure& s = world.structures[k];
    if (s.aliased_from < 0) continue;
    EXPECT_TRUE(s.copied) << k;
    EXPECT_EQ(s.kind, StructureKind::kFacade);
    const Structure& src = world.structures[static_cast<std::size_t>(s.aliased_from)];
    EXPECT_EQ(s.texture_seed, src.texture_seed);
    EXPECT_EQ(s.style, src.style);
    EXPECT_EQ(s.texture, src.texture);
    const Eigen::Vector2d c = centre(static_cast<int>(k));
    const Eigen::Vector2d c_src = centre(s.aliased_from);
    EXPECT_LE((c - place_b).norm(), config.world.alias_copy_radius_m);
    EXPECT_GT((c - c_src).norm(), 50.0) << "structure " << k;
    // Rotated by 180 degrees about the place centres: the mirror position, within the facade pitch phase.
    EXPECT_LE((c_src - (place_a - (c - place_b))).norm(), config.world.alias_copy_tolerance_m);
    copies.push_back(c);
    sources.push_back(c_src);
  }
  EXPECT_EQ(world.copied_structure_count(), 10);  // both sides of ~50 m of street
  EXPECT_EQ(world.aliased_structure_count(), 10);

  // Each place is driven once (one pass of the rendered frames near every copy and every source), and the
  // pass by each source comes more than 150 frames (configs/aliasing.yaml match.margin) after the pass by its
  // copy, so that full DIRD compares the two.
  std::size_t b_first = plan.frames_used, b_last = 0, a_first = plan.frames_used, a_last = 0;
  for (std::size_t k = 0; k < copies.size(); ++k) {
    const auto at_b = passes_near(plan.T_w_c, plan.frames_used, copies[k], 12.0);
    const auto at_a = passes_near(plan.T_w_c, plan.frames_used, sources[k], 12.0);
    ASSERT_EQ(at_b.size(), 1u) << "copy " << k << " at " << copies[k].transpose();
    ASSERT_EQ(at_a.size(), 1u) << "source " << k << " at " << sources[k].transpose();
    EXPECT_GT(at_a[0].first, at_b[0].second + 150) << "copy " << k;
    b_first = std::min(b_first, at_b[0].first);
    b_last = std::max(b_last, at_b[0].second);
    a_first = std::min(a_first, at_a[0].first);
    a_last = std::max(a_last, at_a[0].second);
  }
  std::printf("aliasing preset: place B driven at frames %zu-%zu, place A at %zu-%zu\n", b_first, b_last,
              a_first, a_last);
  EXPECT_GT(a_first, b_last);
  // Nowhere along the passes are the cameras at A and B closer than 50 m.
  for (std::size_t i = a_first; i <= a_last; ++i) {
    for (std::size_t j = b_first; j <= b_last; ++j) {
      ASSERT_GT((plan.T_w_c[i].translation() - plan.T_w_c[j].translation()).norm(), 50.0) << i << " " << j;
    }
  }

  // The genuine loop: ground-truth revisits exist, all of them after the first lap and none near A or B.
  const std::vector<LoopInterval> loops = find_loop_truth(
      std::vector<Eigen::Isometry3d>(plan.T_w_c.begin(), plan.T_w_c.begin() + 490), plan.up_w, config.loops);
  ASSERT_FALSE(loops.empty());
  for (const LoopInterval& loop : loops) {
    EXPECT_GT(static_cast<std::size_t>(loop.query), a_last) << loop.query;
    EXPECT_LT(static_cast<std::size_t>(loop.last), b_first) << loop.last;
  }
  EXPECT_GE(loops.back().query - loops.front().query, 50);  // a revisit of 50+ frames
}

TEST(SimulatorPresets, DemoPresetShowsARevisitAtNightNewStreetsAndAnAliasedPlace) {
  SimulationConfig config = make_preset("demo", "");
  const SimulationPlan plan = plan_simulation(config);
  ASSERT_EQ(plan.frames_used, 600u);
  EXPECT_EQ(plan.camera.width_px, 640);
  EXPECT_EQ(plan.camera.height_px, 200);
  EXPECT_EQ(config.route.shape, sim::RouteShape::kWaypoints);

  // 1. One genuine revisit: every ground-truth query frame lies in one run of frames late in the drive, at
  // full night (night factor 1), and revisits frames of the first loop, by day, more than 200 frames (the
  // configs/demo.yaml match margin) earlier.
  const std::vector<LoopInterval> loops = find_loop_truth(plan.T_w_c, plan.up_w, config.loops);
  ASSERT_FALSE(loops.empty());
  const std::int64_t q_first = loops.front().query, q_last = loops.back().query;
  std::set<std::int64_t> queries;
  for (const LoopInterval& loop : loops) {
    queries.insert(loop.query);
    EXPECT_LT(loop.last, 200) << loop.query;
    EXPECT_GT(loop.query - loop.last, 200) << loop.query;
    EXPECT_EQ(config.illumination.night_factor(plan.illumination_phase[static_cast<std::size_t>(loop.query)]),
              1.0);
    EXPECT_EQ(config.illumination.night_factor(plan.illumination_phase[static_cast<std::size_t>(loop.first)]),
              0.0);
  }
  EXPECT_EQ(static_cast<std::int64_t>(queries.size()), q_last - q_first + 1);  // one run
  EXPECT_GE(queries.size(), 60u);
  std::printf("demo preset: %zu revisit query frames (%lld-%lld)\n", queries.size(),
              static_cast<long long>(q_first), static_cast<long long>(q_last));

  // 2. Most of the drive is never revisited: the frames involved in a revisit (queries and references, with
  // 20 frames of margin on each side) are less than half of the drive.
  std::set<std::int64_t> involved;
  for (const LoopInterval& loop : loops) {
    for (std::int64_t f = loop.query - 20; f <= loop.query + 20; ++f) involved.insert(f);
    for (std::int64_t f = loop.first - 20; f <= loop.last + 20; ++f) involved.insert(f);
  }
  EXPECT_LT(involved.size(), 300u);

  // 3. The aliased place: copies of far facades, each standing where its source stands relative to the road
  // (the same translation for all, within 0.75 m), more than 100 m from it, passed by day more than 200
  // frames after its source and more than 20 m (the gate threshold is 5-8 m) from every frame at least 30
  // frames (the gate gap) older.
  std::vector<Eigen::Vector3d> path_w;
  for (const Eigen::Isometry3d& T : plan.T_w_c) path_w.push_back(T.translation());
  const World world = build_world(config.world, path_w, plan.up_w);
  const auto centre = [&](int structure) {
    Eigen::Vector2d sum = Eigen::Vector2d::Zero();
    int n = 0;
    for (const Quad& q : world.quads) {
      if (q.structure != structure) continue;
      sum += (q.origin_w + 0.5f * q.width_m * q.axis_u_w).head<2>().cast<double>();
      ++n;
    }
    return Eigen::Vector2d(sum / std::max(1, n));
  };
  const Eigen::Vector2d shift(config.world.alias_copy_target_x_m - config.world.alias_copy_source_x_m,
                              config.world.alias_copy_target_y_m - config.world.alias_copy_source_y_m);
  int facades = 0;
  for (std::size_t k = 0; k < world.structures.size(); ++k) {
    const Structure& s = world.structures[k];
    if (s.aliased_from < 0) continue;
    EXPECT_TRUE(s.copied) << k;
    const Structure& src = world.structures[static_cast<std::size_t>(s.aliased_from)];
    EXPECT_EQ(s.texture, src.texture);
    const Eigen::Vector2d c = centre(static_cast<int>(k));
    const Eigen::Vector2d c_src = centre(s.aliased_from);
    EXPECT_GT((c - c_src).norm(), 100.0) << k;
    if (s.kind != StructureKind::kFacade) continue;
    ++facades;
    EXPECT_LT((c - (c_src + shift)).norm(), 0.75) << "facade " << k << " at " << c.transpose();
    const auto at_copy = passes_near(plan.T_w_c, plan.frames_used, c, 12.0);
    const auto at_source = passes_near(plan.T_w_c, plan.frames_used, c_src, 12.0);
    ASSERT_EQ(at_copy.size(), 1u) << "copy " << k;
    ASSERT_FALSE(at_source.empty()) << "source " << k;
    EXPECT_GT(at_copy[0].first, at_source[0].second + 200) << "copy " << k;
    for (std::size_t f = at_copy[0].first; f <= at_copy[0].second; ++f) {
      EXPECT_EQ(config.illumination.night_factor(plan.illumination_phase[f]), 0.0) << f;
      for (std::size_t g = 0; g + 30 <= f; ++g) {
        ASSERT_GT((plan.T_w_c[f].translation() - plan.T_w_c[g].translation()).norm(), 20.0) << f << " " << g;
      }
    }
  }
  EXPECT_GE(facades, 8);
}

// Ground-truth loops of the frames a preset renders.
std::vector<LoopInterval> preset_loops(SimulationConfig& config, SimulationPlan* plan) {
  *plan = plan_simulation(config);
  return find_loop_truth(
      std::vector<Eigen::Isometry3d>(plan->T_w_c.begin(),
                                     plan->T_w_c.begin() + static_cast<std::ptrdiff_t>(plan->frames_used)),
      plan->up_w, config.loops);
}

TEST(SimulatorPresets, NightLoopClosesTheLoopAtFullNightUnderLamps) {
  SimulationConfig config = make_preset("night-loop", "");
  EXPECT_EQ(config.illumination.night_model, sim::NightModel::kLamps);
  SimulationPlan plan;
  const std::vector<LoopInterval> loops = preset_loops(config, &plan);
  ASSERT_EQ(plan.frames_used, 470u);
  EXPECT_EQ(plan.camera.width_px, 640);
  EXPECT_EQ(plan.camera.height_px, 200);
  EXPECT_TRUE(config.world.street_ground_exact_cells);  // set by the lamps model
  // Every revisit: a night query (lamps and headlight on) of a day reference; the second lap revisits the
  // first almost all along (200+ query frames).
  std::vector<Eigen::Vector3d> path;
  for (const Eigen::Isometry3d& T : plan.T_w_c) path.push_back(T.translation());
  const World world = build_world(config.world, path, plan.up_w);
  const SceneLighting lighting(config.illumination, config.lights, config.sensor, world, path, 1);
  ASSERT_FALSE(loops.empty());
  std::set<std::int64_t> queries;
  for (const LoopInterval& loop : loops) {
    queries.insert(loop.query);
    const double query_phase = plan.illumination_phase[static_cast<std::size_t>(loop.query)];
    EXPECT_EQ(config.illumination.night_factor(query_phase), 1.0) << loop.query;
    EXPECT_TRUE(lighting.lamps_on(query_phase) && lighting.headlight_on(query_phase)) << loop.query;
    for (const std::int64_t f : {loop.first, loop.last}) {
      EXPECT_EQ(config.illumination.night_factor(plan.illumination_phase[static_cast<std::size_t>(f)]), 0.0)
          << loop.query << " revisits " << f;
    }
  }
  EXPECT_GE(queries.size(), 200u);
  EXPECT_GE(lighting.lamps().lights.size(), 8u);
  std::printf("night-loop preset: %zu night query frames (%lld-%lld), %zu lamps (%zu out)\n", queries.size(),
              static_cast<long long>(*queries.begin()), static_cast<long long>(*queries.rbegin()),
              lighting.lamps().lights.size(), lighting.lamps().out_count());
}

TEST(SimulatorPresets, TheDemoIsTheDuskDemoWithItsRevisitAtFullNight) {
  SimulationConfig demo = make_preset("demo-dusk", "");
  SimulationConfig night = make_preset("demo", "");
  // The same drive, world and loops: every section but the illumination is the demo's (the lamps model
  // keys the ground cells exactly: the demo's ground has holes where the legacy keys collide).
  nlohmann::json a = config_to_json(demo), b = config_to_json(night);
  for (nlohmann::json* j : {&a, &b}) {
    j->erase("illumination");
    (*j)["simulation"].erase("preset");
  }
  EXPECT_EQ(a, b);
  EXPECT_EQ(night.illumination.night_model, sim::NightModel::kLamps);
  SimulationPlan plan;
  const std::vector<LoopInterval> loops = preset_loops(night, &plan);
  SimulationPlan demo_plan;
  const std::vector<LoopInterval> demo_loops = preset_loops(demo, &demo_plan);
  ASSERT_EQ(loops.size(), demo_loops.size());
  for (std::size_t k = 0; k < loops.size(); ++k) {
    EXPECT_EQ(loops[k].query, demo_loops[k].query);
    EXPECT_EQ(loops[k].first, demo_loops[k].first);
    EXPECT_EQ(loops[k].last, demo_loops[k].last);
    EXPECT_EQ(
        night.illumination.night_factor(plan.illumination_phase[static_cast<std::size_t>(loops[k].query)]),
        1.0);
  }
  // Street B (the aliased place, frames 335-400) by day, the lamps on before the revisit (frame 492).
  std::vector<Eigen::Vector3d> path;
  for (const Eigen::Isometry3d& T : plan.T_w_c) path.push_back(T.translation());
  night.world.street_ground_exact_cells = true;
  const World world = build_world(night.world, path, plan.up_w);
  const SceneLighting lighting(night.illumination, night.lights, night.sensor, world, path, 1);
  for (std::size_t f = 335; f <= 400; ++f)
    EXPECT_EQ(night.illumination.night_factor(plan.illumination_phase[f]), 0.0);
  std::size_t first_lamps = 0, first_headlight = 0;
  while (!lighting.lamps_on(plan.illumination_phase[first_lamps])) ++first_lamps;
  while (!lighting.headlight_on(plan.illumination_phase[first_headlight])) ++first_headlight;
  EXPECT_EQ(first_lamps, 447u);  // as configs/sim/demo.yaml says
  EXPECT_EQ(first_headlight, 439u);
}

TEST(LoopTruth, OutAndBackAlongALine) {
  // 0..49 go along x, 50..99 come back along the same line 0.5 m to the side.
  std::vector<Eigen::Isometry3d> T_w_c(100, Eigen::Isometry3d::Identity());
  for (int i = 0; i < 50; ++i)
    T_w_c[static_cast<std::size_t>(i)].translation() = Eigen::Vector3d(i, 0.0, 0.0);
  for (int i = 50; i < 100; ++i) {
    T_w_c[static_cast<std::size_t>(i)].translation() = Eigen::Vector3d(99 - i, 0.0, 0.5);
    T_w_c[static_cast<std::size_t>(i)].linear() =
        Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitY()).toRotationMatrix();
  }
  LoopTruthSettings settings;
  settings.radius_m = 1.2;
  settings.min_gap_frames = 20;
  settings.horizontal_only = false;
  const auto loops = find_loop_truth(T_w_c, Eigen::Vector3d::UnitY(), settings);
  // Query 99 (x = 0) revisits frames 0 and 1 (x = 0, 1 at 0.5 m and ~1.1 m).
  ASSERT_FALSE(loops.empty());
  EXPECT_EQ(loops.back().query, 99);
  EXPECT_EQ(loops.back().first, 0);
  EXPECT_EQ(loops.back().last, 1);
  for (const LoopInterval& l : loops) EXPECT_GE(l.query - l.last, 20);
  // Facing the opposite way: no loop once the view angle is limited.
  settings.max_view_angle_deg = 90.0;
  EXPECT_TRUE(find_loop_truth(T_w_c, Eigen::Vector3d::UnitY(), settings).empty());
  // Horizontal distance only (up = z ignores the 0.5 m in z).
  settings.max_view_angle_deg = 180.0;
  settings.horizontal_only = true;
  settings.radius_m = 0.1;
  const auto horizontal = find_loop_truth(T_w_c, Eigen::Vector3d::UnitZ(), settings);
  ASSERT_FALSE(horizontal.empty());
  EXPECT_EQ(horizontal.back().first, 0);
  EXPECT_EQ(horizontal.back().last, 0);
}

TEST(LoopTruth, StandingStillIsNotARevisitWithMinTravel) {
  const std::vector<Eigen::Isometry3d> parked(60, Eigen::Isometry3d::Identity());
  LoopTruthSettings settings;
  settings.min_gap_frames = 20;
  EXPECT_EQ(find_loop_truth(parked, Eigen::Vector3d::UnitZ(), settings).size(), 40u);  // every j >= 20
  settings.revisit.min_travel_m = 1.0;
  EXPECT_TRUE(find_loop_truth(parked, Eigen::Vector3d::UnitZ(), settings).empty());
  settings.revisit.min_travel_m = -1.0;
  EXPECT_THROW(settings.validate(), ConfigError);
}

TEST(SimulatorPlan, DemoFramesGroundTruthAndImuAgree) {
  SimulationConfig config = make_preset("demo", "");
  config.simulation.seed = 3;
  const SimulationPlan plan = plan_simulation(config);
  EXPECT_EQ(config.world.seed, 3);
  ASSERT_EQ(plan.frame_t_ns.size(), 600u);
  EXPECT_EQ(plan.frames_used, 600u);
  EXPECT_EQ(plan.frames_outside_trajectory, 0u);
  EXPECT_DOUBLE_EQ(plan.illumination_phase.back(), 1.0);
  EXPECT_NEAR(plan.camera.rate_hz, 10.0, 1e-9);
  // 59.9 s at 200 Hz.
  EXPECT_EQ(plan.imu.size(), 11981u);
  // Ground truth contains every frame time, and body * T_b_c is the camera pose rendered.
  const Eigen::Isometry3d T_b_c = plan.camera.T_b_c;
  for (std::size_t f = 0; f < plan.frames_used; f += 37) {
    const auto it = std::find_if(plan.ground_truth.begin(), plan.ground_truth.end(),
                                 [&](const GroundTruthState& s) { return s.t_ns == plan.frame_t_ns[f]; });
    ASSERT_NE(it, plan.ground_truth.end()) << "frame " << f;
    EXPECT_LT(pose_error(it->T_w_b * T_b_c, plan.T_w_c[f]), 1e-12);
  }
  // The camera looks forward along the motion (optical axis . velocity > 0) and is level.
  const Eigen::Vector3d motion = plan.T_w_c[101].translation() - plan.T_w_c[99].translation();
  EXPECT_GT(plan.T_w_c[100].linear().col(2).dot(motion.normalized()), 0.99);
  EXPECT_NEAR(plan.T_w_c[100].linear().col(1).z(), -1.0, 1e-3);  // image y (down) = -up
  // A town drive: 640 m in 60 s, 9-12.5 m/s (33-45 km/h) all along.
  double min_speed = 1e9, max_speed = 0.0;
  for (const GroundTruthState& gt : plan.ground_truth) {
    min_speed = std::min(min_speed, gt.v_w_mps.norm());
    max_speed = std::max(max_speed, gt.v_w_mps.norm());
  }
  EXPECT_GT(min_speed, 8.0);
  EXPECT_LT(max_speed, 13.0);
}

TEST(SimulatorPlan, PrefixRunMatchesTheFullRun) {
  SimulationConfig full = make_preset("demo", "");
  SimulationConfig prefix = make_preset("demo", "");
  prefix.simulation.max_frames = 40;
  const SimulationPlan a = plan_simulation(full);
  const SimulationPlan b = plan_simulation(prefix);
  ASSERT_EQ(b.frames_used, 40u);
  EXPECT_EQ(b.frame_t_ns.size(), 600u);
  for (std::size_t f = 0; f < 40; ++f) {
    EXPECT_EQ(a.T_w_c[f].matrix(), b.T_w_c[f].matrix());
    EXPECT_EQ(a.illumination_phase[f], b.illumination_phase[f]);
  }
  // IMU up to the 40th frame plus the padding.
  EXPECT_EQ(b.imu.back().t_ns, b.frame_t_ns[39] + 100'000'000);
  for (std::size_t k = 0; k < b.imu.size(); ++k) {
    ASSERT_EQ(a.imu[k].t_ns, b.imu[k].t_ns);
    ASSERT_EQ(a.imu[k].accel_mps2, b.imu[k].accel_mps2);
  }
}

TEST(SimulatorPlan, MissingTrajectoryFileIsADataError) {
  SimulationConfig config = make_preset("kitti00", "/nonexistent/data");
  try {
    plan_simulation(config);
    FAIL() << "expected DataError";
  } catch (const DataError& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/data/kitti/00/poses.txt"), std::string::npos)
        << e.what();
  }
}

TEST(SimulatorPlan, Kitti00) {
  LOOPGATE_REQUIRE_SHARED_DATA("kitti/00/poses.txt");
  SimulationConfig config = make_preset("kitti00", shared());
  const SimulationPlan plan = plan_simulation(config);
  ASSERT_EQ(plan.frame_t_ns.size(), 4541u);
  EXPECT_EQ(plan.frames_used, 4541u);
  EXPECT_EQ(plan.camera.width_px, 1241);
  EXPECT_NEAR(plan.up_w.y(), -1.0, 1e-12);
  // The smoothed fit stays close to every KITTI pose.
  const auto poses = read_kitti_poses(shared() / "kitti/00/poses.txt", shared() / "kitti/00/times.txt");
  double max_error_m = 0.0;
  for (std::size_t f = 0; f < poses.size(); ++f) {
    max_error_m = std::max(max_error_m, (plan.T_w_c[f].translation() - poses[f].T_w_b.translation()).norm());
  }
  EXPECT_LT(max_error_m, 0.2);
  // The synthesised IMU is car-like: world acceleration R a_b + g_w, 99th percentile below 5 m/s^2.
  EXPECT_GT(plan.ground_truth.size(), plan.imu.size());  // IMU times + frame times
  std::vector<double> accel_w;
  const Eigen::Vector3d g_w = -9.81 * plan.up_w;
  for (const ImuSample& sample : plan.imu) {
    const auto gt = std::lower_bound(plan.ground_truth.begin(), plan.ground_truth.end(), sample.t_ns,
                                     [](const GroundTruthState& s, Timestamp t) { return s.t_ns < t; });
    ASSERT_NE(gt, plan.ground_truth.end());
    ASSERT_EQ(gt->t_ns, sample.t_ns);
    accel_w.push_back((gt->T_w_b.linear() * sample.accel_mps2 + g_w).norm());
  }
  std::sort(accel_w.begin(), accel_w.end());
  const double p99 = accel_w[accel_w.size() * 99 / 100];
  std::printf("kitti00: fit max error %.3f m, |a_w| p99 %.2f m/s^2, %zu IMU samples\n", max_error_m, p99,
              plan.imu.size());
  EXPECT_LT(p99, 5.0);
}

TEST(SimulatorPlan, EurocMh05PassesTheRealImuThrough) {
  LOOPGATE_REQUIRE_SHARED_DATA("euroc/MH_05_difficult/mav0/imu0/data.csv");
  SimulationConfig config = make_preset("euroc-mh05", shared());
  const SimulationPlan plan = plan_simulation(config);
  EXPECT_EQ(plan.frame_t_ns.size(), 2273u);
  EXPECT_EQ(plan.camera.width_px, 752);
  EXPECT_EQ(plan.camera.distortion_model, DistortionModel::kRadTan);
  EXPECT_NEAR(plan.camera.fx, 458.654, 1e-9);
  EXPECT_NEAR(plan.camera.T_b_c.translation().x(), -0.0216401454975, 1e-12);
  EXPECT_NEAR(plan.imu_calibration.gyro_noise_density, 1.6968e-04, 1e-12);
  // Frames before/after the ground truth span hold the end poses.
  EXPECT_GT(plan.frames_outside_trajectory, 0u);
  EXPECT_LT(plan.frames_outside_trajectory, 60u);
  const auto real = read_euroc_imu(shared() / "euroc/MH_05_difficult/mav0/imu0/data.csv");
  ASSERT_GT(plan.imu.size(), 22000u);
  const auto it = std::find_if(real.begin(), real.end(),
                               [&](const ImuSample& s) { return s.t_ns == plan.imu[500].t_ns; });
  ASSERT_NE(it, real.end());
  EXPECT_EQ(it->gyro_radps, plan.imu[500].gyro_radps);
  EXPECT_EQ(it->accel_mps2, plan.imu[500].accel_mps2);
  // Ground truth at a frame inside the span is close to the recorded one.
  const auto recorded =
      read_euroc_groundtruth(shared() / "euroc/MH_05_difficult/mav0/state_groundtruth_estimate0/data.csv");
  const std::size_t f = 1000;
  const auto rec = std::lower_bound(recorded.begin(), recorded.end(), plan.frame_t_ns[f],
                                    [](const GroundTruthState& s, Timestamp t) { return s.t_ns < t; });
  const Eigen::Isometry3d T_w_b = plan.T_w_c[f] * plan.camera.T_b_c.inverse();
  EXPECT_LT((T_w_b.translation() - rec->T_w_b.translation()).norm(), 0.01);
}

TEST(SimulatorRun, WritesTheEurocLayoutThatReadsBack) {
  const auto out = loopgate::testing::make_temp_dir("sim-run") / "demo";
  SimulationConfig config = make_preset("demo", "");
  config.simulation.max_frames = 6;
  config.simulation.seed = 11;
  const SimulationSummary summary = run_simulation(config, out);
  EXPECT_EQ(summary.frames, 6u);
  EXPECT_NEAR(summary.duration_s, 0.5, 1e-9);
  EXPECT_GT(summary.distance_m, 2.0);
  for (const char* rel :
       {"mav0/cam0/data.csv", "mav0/cam0/sensor.yaml", "mav0/imu0/data.csv", "mav0/imu0/sensor.yaml",
        "mav0/state_groundtruth_estimate0/data.csv", "simulation.json"}) {
    EXPECT_TRUE(std::filesystem::is_regular_file(out / rel)) << rel;
  }
  std::size_t pngs = 0;
  for (const auto& entry : std::filesystem::directory_iterator(out / "mav0/cam0/data"))
    pngs += entry.path().extension() == ".png";
  EXPECT_EQ(pngs, 6u);

  std::ifstream json_in(out / "simulation.json");
  const nlohmann::json meta = nlohmann::json::parse(json_in);
  EXPECT_EQ(meta["preset"], "demo");
  EXPECT_EQ(meta["seed"], 11);
  EXPECT_EQ(meta["frames"]["count"], 6);
  EXPECT_EQ(meta["illumination"]["phase"].size(), 6u);
  EXPECT_EQ(meta["parameters"]["world"]["kind"], "street");
  EXPECT_EQ(meta["parameters"]["simulation"]["seed"], 11);

  const auto dataset = open_euroc(out);
  ASSERT_EQ(dataset->frame_count(), 6u);
  EXPECT_TRUE(dataset->has_images());
  const cv::Mat image = dataset->load_image(3);
  EXPECT_EQ(image.cols, 640);
  EXPECT_EQ(image.rows, 200);
  ASSERT_TRUE(dataset->has_ground_truth());
  SimulationConfig same = config;
  const SimulationPlan plan = plan_simulation(same);
  for (std::size_t f = 0; f < 6; ++f) {
    EXPECT_EQ(dataset->frame_t_ns(f), plan.frame_t_ns[f]);
    const auto T_w_b = dataset->ground_truth_T_w_b(f);
    ASSERT_TRUE(T_w_b.has_value());
    EXPECT_LT(pose_error(*T_w_b * plan.camera.T_b_c, plan.T_w_c[f]), 1e-5);
  }
  ASSERT_TRUE(dataset->camera().has_value());
  EXPECT_NEAR(dataset->camera()->fx, 370.0, 1e-9);

  // A non-empty output is refused without force, replaced with it.
  EXPECT_THROW(run_simulation(config, out), DataError);
  SimulationRunOptions force;
  force.force = true;
  config.simulation.max_frames = 3;
  EXPECT_EQ(run_simulation(config, out, force).frames, 3u);
  std::size_t pngs_after = 0;
  for (const auto& entry : std::filesystem::directory_iterator(out / "mav0/cam0/data")) {
    pngs_after += entry.is_regular_file() ? 1 : 0;
  }
  EXPECT_EQ(pngs_after, 3u);
}

}  // namespace
}  // namespace loopgate::sim
