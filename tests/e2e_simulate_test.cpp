// `loopgate simulate` end to end: determinism (same seed -> byte-identical output, other seed -> different),
// the EuRoC files are consistent (frames, IMU, ground truth at every frame), and clear errors for bad
// invocations. Only the binary and its files are used here (the open_euroc read-back of a simulated
// dataset is in sim_simulator_test).
#include <gtest/gtest.h>

#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "test_support.hpp"

namespace {

namespace fs = std::filesystem;
using loopgate::testing::loopgate_binary;
using loopgate::testing::make_temp_dir;
using loopgate::testing::run_command;

std::string read_bytes(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  std::ostringstream buffer;
  buffer << in.rdbuf();
  return buffer.str();
}

// Rows of a EuRoC csv (header and comments skipped), split at commas.
std::vector<std::vector<std::string>> csv_rows(const fs::path& file) {
  std::vector<std::vector<std::string>> rows;
  std::ifstream in(file);
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::vector<std::string> cells;
    std::stringstream row(line);
    std::string cell;
    while (std::getline(row, cell, ',')) cells.push_back(cell);
    rows.push_back(cells);
  }
  return rows;
}

// relative path -> bytes of every regular file under dir.
std::map<std::string, std::string> tree(const fs::path& dir) {
  std::map<std::string, std::string> files;
  for (const auto& entry : fs::recursive_directory_iterator(dir)) {
    if (entry.is_regular_file()) files[fs::relative(entry.path(), dir).string()] = read_bytes(entry.path());
  }
  return files;
}

std::string simulate(const std::string& args, int* status) {
  std::string output;
  *status = run_command(loopgate_binary().string() + " --log-level warn simulate " + args, &output);
  return output;
}

TEST(E2eSimulate, SameSeedIsByteIdenticalOtherSeedDiffers) {
  const fs::path root = make_temp_dir("e2e-simulate");
  int status = -1;
  const std::string out_a =
      simulate("--preset demo --frames 40 --seed 7 --out " + (root / "a").string(), &status);
  ASSERT_EQ(status, 0) << out_a;
  EXPECT_NE(out_a.find("frames        40"), std::string::npos) << out_a;
  EXPECT_NE(out_a.find("distance"), std::string::npos) << out_a;
  EXPECT_NE(out_a.find("loops"), std::string::npos) << out_a;
  ASSERT_EQ(0, run_command(loopgate_binary().string() +
                           " --log-level warn simulate --preset demo --frames 40 "
                           "--seed 7 --out " +
                           (root / "b").string()));
  ASSERT_EQ(0, run_command(loopgate_binary().string() +
                           " --log-level warn simulate --preset demo --frames 40 "
                           "--seed 8 --out " +
                           (root / "c").string()));

  const auto a = tree(root / "a");
  const auto b = tree(root / "b");
  const auto c = tree(root / "c");
  // 40 images + cam0 data.csv/sensor.yaml + imu0 data.csv/sensor.yaml + ground truth + simulation.json +
  // loop_truth.csv.
  EXPECT_EQ(a.size(), 47u);
  EXPECT_EQ(a.count("loop_truth.csv"), 1u);
  ASSERT_EQ(a.size(), b.size());
  for (const auto& [path, bytes] : a) {
    const auto it = b.find(path);
    ASSERT_NE(it, b.end()) << path << " missing in the second run";
    EXPECT_TRUE(it->second == bytes) << path << " differs between two runs with one seed";
  }
  // Another seed: another world, other noise -> other images and IMU.
  ASSERT_EQ(c.size(), a.size());
  std::size_t differing = 0;
  for (const auto& [path, bytes] : a) differing += c.at(path) != bytes ? 1 : 0;
  EXPECT_GE(differing, 40u);
  EXPECT_NE(a.at("mav0/imu0/data.csv"), c.at("mav0/imu0/data.csv"));

  // The EuRoC files agree: 40 frames named by their stamps, IMU at 200 Hz, ground truth at every frame.
  const auto frames = csv_rows(root / "a/mav0/cam0/data.csv");
  ASSERT_EQ(frames.size(), 40u);
  std::set<std::string> gt_stamps;
  const auto gt = csv_rows(root / "a/mav0/state_groundtruth_estimate0/data.csv");
  for (const auto& row : gt) {
    ASSERT_EQ(row.size(), 17u);
    gt_stamps.insert(row[0]);
  }
  for (const auto& row : frames) {
    ASSERT_EQ(row.size(), 2u);
    EXPECT_EQ(row[1], row[0] + ".png");
    EXPECT_TRUE(a.count("mav0/cam0/data/" + row[1])) << row[1];
    EXPECT_TRUE(gt_stamps.count(row[0])) << "no ground truth at frame " << row[0];
  }
  const auto imu = csv_rows(root / "a/mav0/imu0/data.csv");
  ASSERT_GT(imu.size(), 780u);
  EXPECT_EQ(std::stoll(imu[1][0]) - std::stoll(imu[0][0]), 5'000'000);
  const nlohmann::json meta = nlohmann::json::parse(a.at("simulation.json"));
  EXPECT_EQ(meta["seed"], 7);
  EXPECT_EQ(meta["frames"]["count"], 40);
  EXPECT_EQ(meta["illumination"]["phase"].size(), 40u);
  // Frame 0 of the demo: the body sits at camera height above the ground plane z = 0.
  EXPECT_NEAR(std::stod(gt[0][3]), meta["parameters"]["route"]["camera_height_m"].get<double>(), 1e-6);
}

TEST(E2eSimulate, RefusesANonEmptyOutputWithoutForce) {
  const fs::path out = make_temp_dir("e2e-simulate-force");
  std::ofstream(out / "keep.txt") << "user data\n";
  int status = -1;
  const std::string refused = simulate("--preset demo --frames 2 --out " + out.string(), &status);
  EXPECT_EQ(status, 1);
  EXPECT_NE(refused.find("not empty"), std::string::npos) << refused;
  EXPECT_FALSE(fs::exists(out / "mav0"));
  const std::string forced = simulate("--preset demo --frames 2 --force --out " + out.string(), &status);
  EXPECT_EQ(status, 0) << forced;
  EXPECT_TRUE(fs::exists(out / "mav0/cam0/data.csv"));
  EXPECT_TRUE(fs::exists(out / "keep.txt"));  // only the simulation's own outputs are replaced
}

TEST(E2eSimulate, ClearErrorsForABadPresetOrAMissingTrajectory) {
  const fs::path root = make_temp_dir("e2e-simulate-errors");
  int status = -1;
  const std::string bad_preset = simulate("--preset kitti99 --out " + (root / "x").string(), &status);
  EXPECT_EQ(status, 1);
  EXPECT_NE(bad_preset.find("kitti99"), std::string::npos) << bad_preset;
  EXPECT_NE(bad_preset.find("euroc-mh05"), std::string::npos) << bad_preset;
  const std::string missing = simulate(
      "--preset kitti00 --trajectory " + (root / "nope.txt").string() + " --out " + (root / "y").string(),
      &status);
  EXPECT_EQ(status, 1);
  EXPECT_NE(missing.find("nope.txt"), std::string::npos) << missing;
  EXPECT_NE(missing.find("not found"), std::string::npos) << missing;
  std::string help;
  EXPECT_EQ(run_command(loopgate_binary().string() + " simulate --help", &help), 0);
  EXPECT_NE(help.find("--preset"), std::string::npos) << help;
}

TEST(E2eSimulate, TumTrajectoryWithSynthesisedImu) {
  const fs::path root = make_temp_dir("e2e-simulate-tum");
  // A straight 5 m/s drive, 3 s at 10 Hz: identity orientations moving along the optical axis (z) of a
  // KITTI-like camera world (up = -y), written as a TUM file.
  std::ofstream tum(root / "drive.tum");
  for (int i = 0; i <= 30; ++i) tum << i * 0.1 << " 0 0 " << i * 0.5 << " 0 0 0 1\n";
  tum.close();
  int status = -1;
  const std::string out =
      simulate("--preset kitti00 --trajectory " + (root / "drive.tum").string() +
                   " --set camera.width_px=320 --set camera.height_px=96 --set camera.cx=160 "
                   "--set camera.cy=48 --set camera.fx=180 --set camera.fy=180 --out " +
                   (root / "out").string(),
               &status);
  ASSERT_EQ(status, 0) << out;
  EXPECT_NE(out.find("frames        31"), std::string::npos) << out;
  EXPECT_EQ(csv_rows(root / "out/mav0/cam0/data.csv").size(), 31u);
  // Constant velocity: the synthesised accelerometer measures gravity only (up = -y in the body).
  const auto imu = csv_rows(root / "out/mav0/imu0/data.csv");
  ASSERT_GT(imu.size(), 500u);
  const auto& mid = imu[imu.size() / 2];
  ASSERT_EQ(mid.size(), 7u);
  EXPECT_NEAR(std::stod(mid[5]), -9.81, 0.2);
  EXPECT_NEAR(std::stod(mid[4]), 0.0, 0.2);
}

// An EuRoC ground truth without cam0/data.csv beside it makes simulate invent the frame times, and
// it says so loudly; --frame-times gives them, as an EuRoC cam0/data.csv or a plain list (integer ns or
// decimal seconds), and a bad list is an error naming its file and line.
TEST(E2eSimulate, FrameTimesAreGivenOrLoudlyInvented) {
  const fs::path root = make_temp_dir("e2e-simulate-times");
  const fs::path truth = root / "mav0" / "state_groundtruth_estimate0" / "data.csv";
  fs::create_directories(truth.parent_path());
  {
    // 3 s from t = 1 s at 100 Hz, a straight 5 m/s drive along z (a KITTI-like camera world, up = -y).
    std::ofstream gt(truth);
    gt << "#timestamp,p_x,p_y,p_z,q_w,q_x,q_y,q_z,v_x,v_y,v_z,bw_x,bw_y,bw_z,ba_x,ba_y,ba_z\n";
    for (int i = 0; i <= 300; ++i)
      gt << 1'000'000'000LL + i * 10'000'000LL << ",0,0," << i * 0.05 << ",1,0,0,0,0,0,5,0,0,0,0,0,0\n";
  }
  const std::string base =
      "--preset kitti00 --trajectory " + truth.string() +
      " --set camera.width_px=160 --set camera.height_px=48 --set camera.cx=80 "
      "--set camera.cy=24 --set camera.fx=90 --set camera.fy=90 --set simulation.frame_rate_hz=10";
  int status = -1;
  std::string out = simulate(base + " --out " + (root / "invented").string(), &status);
  ASSERT_EQ(status, 0) << out;
  EXPECT_NE(
      out.find("[warning] simulate: no camera times for " + truth.string() +
               " (no cam0/data.csv beside it, simulation.frame_times_file empty): INVENTING 31 frame times "
               "every 1/10 s"),
      std::string::npos)
      << out;
  EXPECT_NE(out.find("--frame-times FILE"), std::string::npos) << out;
  const auto invented = nlohmann::json::parse(read_bytes(root / "invented" / "simulation.json"));
  EXPECT_EQ(invented["frames"]["times"].get<std::string>().rfind("invented", 0), 0u) << invented["frames"];

  // A plain list in seconds, and the same in nanoseconds: frames at exactly those times, no warning.
  std::ofstream(root / "seconds.txt") << "# frame times\n1.5\n1.6\n\n1.75\n2.0\n";
  std::ofstream(root / "ns.txt") << "1500000000\n1600000000\n1750000000\n2000000000\n";
  for (const char* list : {"seconds.txt", "ns.txt"}) {
    SCOPED_TRACE(list);
    const fs::path dir = root / (std::string("from-") + list);
    out = simulate(base + " --frame-times " + (root / list).string() + " --out " + dir.string(), &status);
    ASSERT_EQ(status, 0) << out;
    EXPECT_EQ(out.find("INVENTING"), std::string::npos) << out;
    const auto rows = csv_rows(dir / "mav0/cam0/data.csv");
    ASSERT_EQ(rows.size(), 4u);
    EXPECT_EQ(rows[0][0], "1500000000");
    EXPECT_EQ(rows[2][0], "1750000000");
    EXPECT_EQ(rows[3][0], "2000000000");
    const auto meta = nlohmann::json::parse(read_bytes(dir / "simulation.json"));
    EXPECT_EQ(meta["frames"]["times"].get<std::string>(), (root / list).string());
  }

  // Mixed units and integer seconds: errors naming the file and line.
  std::ofstream(root / "mixed.txt") << "1.5\n1.6\n1700000000\n";
  out =
      simulate(base + " --frame-times " + (root / "mixed.txt").string() + " --out " + (root / "bad").string(),
               &status);
  EXPECT_NE(status, 0);
  EXPECT_NE(
      out.find((root / "mixed.txt").string() + ":3: expected seconds with a decimal point like the first "
                                               "time of the file, got '1700000000'"),
      std::string::npos)
      << out;
  std::ofstream(root / "integers.txt") << "1\n2\n3\n";
  out = simulate(
      base + " --frame-times " + (root / "integers.txt").string() + " --out " + (root / "bad2").string(),
      &status);
  EXPECT_NE(status, 0);
  EXPECT_NE(
      out.find((root / "integers.txt").string() + ":2: frames less than 1 ms apart (above 1000 Hz): integer "
                                                  "times are nanoseconds"),
      std::string::npos)
      << out;
}

}  // namespace
