// The simulator presets are YAML files (configs/sim/<name>.yaml) read by the config system: every shipped
// file loads and validates, holds what the presets were when they were C++ (a few key values per preset;
// rendered datasets were compared byte for byte when they moved), resolves its input files under the
// shared-data folder, and a bad key or value names the file and line.
#include <gtest/gtest.h>

#include <fstream>
#include <string>
#include <vector>

#include "core/error.hpp"
#include "io/config.hpp"
#include "sim/simulator.hpp"
#include "test_support.hpp"

namespace loopgate::sim {
namespace {

namespace fs = std::filesystem;

fs::path write_file(const fs::path& file, const std::string& text) {
  std::ofstream(file) << text;
  return file;
}

std::string error_of(const std::string& name_or_file) {
  try {
    make_preset(name_or_file, "/data");
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "";
}

TEST(SimPresets, EveryShippedPresetFileLoadsAndValidates) {
  EXPECT_EQ(preset_dir(), fs::path(LOOPGATE_SOURCE_DIR) / "configs" / "sim");
  ASSERT_EQ(preset_names(), (std::vector<std::string>{"aliasing", "demo", "demo-dusk", "euroc-mh05",
                                                      "kitti00", "night-loop"}));
  for (const std::string& name : preset_names()) {
    const fs::path file = preset_dir() / (name + ".yaml");
    EXPECT_EQ(preset_file(name), file);
    const SimulationConfig by_name = make_preset(name, "/data");
    EXPECT_EQ(by_name.simulation.preset, name);
    EXPECT_NO_THROW(by_name.validate()) << name;
    // The same file given as a path is the same preset.
    EXPECT_EQ(config_to_json(make_preset(file.string(), "/data")), config_to_json(by_name)) << name;
  }
}

TEST(SimPresets, FilesHoldWhatTheCodePresetsSet) {
  const SimulationConfig demo = make_preset("demo", "");
  EXPECT_EQ(demo.route.shape, sim::RouteShape::kWaypoints);
  EXPECT_EQ(demo.route.waypoints,
            "-25,-25; 40,-25; 40,25; -40,25; -40,-140.6; 40,-140.6; 40,25; -5,25; -5,60");
  EXPECT_EQ(demo.route.frames, 600);
  EXPECT_EQ(demo.simulation.frame_rate_hz, demo.route.rate_hz);
  EXPECT_EQ(demo.world.street_camera_height_m, demo.route.camera_height_m);
  // Camera z forward = body x, camera x right = body -y, camera y down = body -z.
  Eigen::Matrix3d R_b_c;
  R_b_c << 0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, -1.0, 0.0;
  EXPECT_TRUE(demo.camera.T_b_c().linear().isApprox(R_b_c, 1e-15));
  EXPECT_EQ(demo.camera.q_b_c_w, -0.5);  // exactly what Eigen's Quaterniond(R_b_c) gave
  EXPECT_EQ(demo.world.alias_copy_target_y_m, -140.6);
  EXPECT_EQ(demo.illumination.transition_start, 0.70);
  EXPECT_EQ(demo.illumination.night_model, sim::NightModel::kLamps);
  EXPECT_EQ(make_preset("demo-dusk", "").illumination.night_noise_sigma, 3.0);
  EXPECT_EQ(demo.loops.revisit.min_travel_m, 10.0);

  const SimulationConfig aliasing = make_preset("aliasing", "");
  EXPECT_EQ(aliasing.simulation.max_frames, 490);
  EXPECT_EQ(aliasing.route.frames, 824);
  EXPECT_EQ(aliasing.camera.width_px, 320);
  EXPECT_EQ(aliasing.world.alias_copy_target_x_m, 51.3);
  EXPECT_EQ(aliasing.world.alias_copy_rotation_deg, 180.0);
  EXPECT_EQ(aliasing.world.street_pole_spacing_m, 0.0);
  EXPECT_EQ(aliasing.illumination.kind, sim::IlluminationKind::kConstant);

  // Input files under the shared-data folder, as the code joined them (simulation.json records them).
  const SimulationConfig kitti = make_preset("kitti00", "../shared/data");
  EXPECT_EQ(kitti.simulation.trajectory_file, "../shared/data/kitti/00/poses.txt");
  EXPECT_EQ(kitti.simulation.times_file, "../shared/data/kitti/00/times.txt");
  EXPECT_EQ(kitti.camera.fx, 718.856);
  EXPECT_EQ(kitti.camera.cy, 185.2157);
  EXPECT_EQ(kitti.simulation.up_y, -1.0);
  EXPECT_EQ(kitti.world.aliasing_fraction, 0.05);

  const SimulationConfig mh05 = make_preset("euroc-mh05", "/data");
  const std::string mav0 = "/data/euroc/MH_05_difficult/mav0/";
  EXPECT_EQ(mh05.simulation.trajectory_file, mav0 + "state_groundtruth_estimate0/data.csv");
  EXPECT_EQ(mh05.simulation.frame_times_file, mav0 + "cam0/data.csv");
  EXPECT_EQ(mh05.simulation.camera_yaml, mav0 + "cam0/sensor.yaml");
  EXPECT_EQ(mh05.simulation.imu_file, mav0 + "imu0/data.csv");
  EXPECT_EQ(mh05.simulation.imu_yaml, mav0 + "imu0/sensor.yaml");
  EXPECT_EQ(mh05.simulation.times_file, "");
  EXPECT_EQ(mh05.camera.p2, 1.76187114e-05);
  EXPECT_EQ(mh05.fit.knot_spacing_s, 0.025);
  EXPECT_EQ(mh05.loops.radius_m, 0.2);
  EXPECT_FALSE(mh05.loops.horizontal_only);
}

TEST(SimPresets, AnyPresetFile) {
  const fs::path dir = loopgate::testing::make_temp_dir("sim-presets");
  const fs::path file = write_file(dir / "my-street.yaml",
                                   "simulation:\n"
                                   "  trajectory_format: tum\n"
                                   "  trajectory_file: drives/a.tum\n"
                                   "  imu_file: /abs/imu.csv\n"
                                   "camera:\n"
                                   "  width_px: 64\n");
  const SimulationConfig c = make_preset(file.string(), "/data");
  EXPECT_EQ(c.simulation.preset, "my-street");  // the file name unless the file sets it
  EXPECT_EQ(c.simulation.trajectory_file, "/data/drives/a.tum");
  EXPECT_EQ(c.simulation.imu_file, "/abs/imu.csv");
  EXPECT_EQ(c.camera.width_px, 64);
  EXPECT_EQ(c.camera.height_px, CameraSettings{}.height_px);  // the rest are the defaults
  write_file(dir / "named.yml", "simulation:\n  preset: other\n");
  EXPECT_EQ(make_preset((dir / "named.yml").string(), "").simulation.preset, "other");
}

TEST(SimPresets, BadKeysAndValuesNameTheFileAndLine) {
  const fs::path dir = loopgate::testing::make_temp_dir("sim-presets-bad");
  const std::string key = write_file(dir / "key.yaml", "camera:\n  width_px: 64\n  widht_px: 65\n").string();
  std::string error = error_of(key);
  EXPECT_NE(error.find("unknown key 'camera.widht_px'"), std::string::npos) << error;
  EXPECT_NE(error.find(key + ":3"), std::string::npos) << error;

  const std::string type =
      write_file(dir / "type.yaml", "loops:\n  radius_m: 2\n  min_gap_frames: many\n").string();
  error = error_of(type);
  EXPECT_NE(error.find("loops.min_gap_frames: expected an integer"), std::string::npos) << error;
  EXPECT_NE(error.find(type + ":3"), std::string::npos) << error;

  const std::string section = write_file(dir / "section.yaml", "\nrender:\n  fast: true\n").string();
  error = error_of(section);
  EXPECT_NE(error.find("unknown section 'render'"), std::string::npos) << error;
  EXPECT_NE(error.find(section + ":3"), std::string::npos) << error;

  const std::string invalid = write_file(dir / "invalid.yaml", "simulation:\n  imu_source: magic\n").string();
  EXPECT_NE(error_of(invalid).find("simulation.imu_source"), std::string::npos);

  EXPECT_NE(error_of((dir / "absent.yaml").string()).find("absent.yaml"), std::string::npos);
  error = error_of("kitti01");
  EXPECT_NE(error.find("kitti01"), std::string::npos) << error;
  EXPECT_NE(error.find("aliasing|demo|demo-dusk|euroc-mh05|kitti00|night-loop"), std::string::npos) << error;
}

}  // namespace
}  // namespace loopgate::sim
