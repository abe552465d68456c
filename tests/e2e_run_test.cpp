// End-to-end tests of `loopgate run`: the real binary on generated KITTI-layout data, on a small
// simulated demo, and on the shared KITTI 00 thumbnails (skipped when absent).
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <spdlog/fmt/fmt.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <set>
#include <sstream>

#include "test_support.hpp"

namespace loopgate {
namespace {

namespace fs = std::filesystem;

using testing::read_csv;
using testing::read_file;

// A KITTI-layout dataset: image_0/NNNNNN.png (64 x 32 textured), times.txt (10 Hz), poses.txt (a drive
// along z). Frames in `corrupt` get a file that is not a PNG.
fs::path make_kitti_dataset(int frames, const std::vector<int>& corrupt = {}) {
  const fs::path dir = testing::make_temp_dir("e2e-kitti");
  fs::create_directories(dir / "image_0");
  std::ofstream times(dir / "times.txt");
  std::ofstream poses(dir / "poses.txt");
  for (int i = 0; i < frames; ++i) {
    char name[32];
    std::snprintf(name, sizeof(name), "%06d.png", i);
    if (std::find(corrupt.begin(), corrupt.end(), i) != corrupt.end()) {
      std::ofstream(dir / "image_0" / name) << "this is not a png";
    } else {
      cv::Mat image(32, 64, CV_8UC1);
      for (int r = 0; r < image.rows; ++r) {
        for (int c = 0; c < image.cols; ++c)
          image.at<std::uint8_t>(r, c) = static_cast<std::uint8_t>((r * 9 + c * 5 + i) % 200);
      }
      cv::imwrite((dir / "image_0" / name).string(), image);
    }
    times << std::scientific << 0.1 * i << "\n";
    poses << "1 0 0 " << 0.05 * std::sin(0.1 * i) << " 0 1 0 0 0 0 1 " << 1.0 * i << "\n";
  }
  return dir;
}

std::string run(const std::string& args, int* status) {
  std::string output;
  *status = testing::run_command(testing::loopgate_binary().string() + " " + args, &output);
  return output;
}

TEST(E2eRun, GeneratedKittiEveryFrameOnceAndBadImageReported) {
  const fs::path dataset = make_kitti_dataset(60, {25});
  const fs::path out = testing::make_temp_dir("e2e-run-out");
  int status = -1;
  const std::string output =
      run("run --config " + std::string(LOOPGATE_SOURCE_DIR) + "/configs/kitti00-thumbs.yaml --dataset " +
              dataset.string() + " --out " + out.string() +
              " --set run.decode=all --set match.margin=20 --threads 2 --trace",
          &status);
  ASSERT_EQ(status, 0) << output;
  const auto rows = read_csv(out / "frames.csv");
  ASSERT_EQ(rows.size(), 60u) << output;
  for (std::size_t i = 0; i < rows.size(); ++i) {
    EXPECT_EQ(rows[i][0], std::to_string(i));
    EXPECT_EQ(rows[i][1], std::to_string(i));
    EXPECT_EQ(rows[i][15], i == 25 ? "error" : "ok") << i << ": " << rows[i][16];
  }
  EXPECT_NE(rows[25][16].find("000025.png"), std::string::npos) << rows[25][16];
  const auto summary = nlohmann::json::parse(read_file(out / "summary.json"));
  EXPECT_EQ(summary["frames_in"].get<int>(), 60);
  EXPECT_EQ(summary["frames_processed"].get<int>(), 60);
  EXPECT_EQ(summary["frames_dropped"].get<int>(), 0);
  EXPECT_EQ(summary["counts"]["frames_error"].get<int>(), 1);
  EXPECT_EQ(summary["data_issues"]["image_errors"].get<int>(), 1);
  EXPECT_EQ(summary["config"]["run"]["decode"].get<std::string>(), "all");
  EXPECT_NEAR(summary["data_s"].get<double>(), 5.9, 1e-6);
  for (const char* stage : {"sync", "decode", "odometry", "sink"}) {
    EXPECT_EQ(summary["stages"][stage]["calls"].get<int>(), 60) << stage;
  }
  EXPECT_EQ(read_csv(out / "timing.csv").size(), 60u);
  // trace.json: the process named (method, mode, dataset), every stage of every frame a span on a
  // named track, the end-of-stream work as spans on the producer's track.
  const auto trace = nlohmann::json::parse(read_file(out / "trace.json"));
  std::string process_name;
  std::map<int, std::string> track_names;
  std::map<std::string, int> stage_spans;
  std::set<std::string> end_of_stream;
  std::set<int> tracks_used;
  for (const auto& event : trace["traceEvents"]) {
    if (event["ph"] == "M" && event["name"] == "process_name") process_name = event["args"]["name"];
    if (event["ph"] == "M" && event["name"] == "thread_name")
      track_names[event["tid"]] = event["args"]["name"];
    if (event["ph"] != "X") continue;
    tracks_used.insert(event["tid"].get<int>());
    if (event["cat"] == "stage") ++stage_spans[event["name"]];
    if (event["cat"] == "end_of_stream") {
      end_of_stream.insert(event["name"].get<std::string>());
      EXPECT_EQ(track_names.count(event["tid"].get<int>()), 1u);
    }
  }
  EXPECT_NE(process_name.find("loopgate run: dird-seqslam (gated) on " + dataset.string()), std::string::npos)
      << process_name;
  for (const char* stage : {"sync", "decode", "odometry", "gate", "describe", "match", "sink"})
    EXPECT_EQ(stage_spans[stage], 60) << stage;
  for (const int tid : tracks_used) EXPECT_EQ(track_names.count(tid), 1u) << "track " << tid << " unnamed";
  EXPECT_EQ(end_of_stream.count("end of stream: method (matcher flush, search)"), 1u);
  EXPECT_EQ(end_of_stream.count("end of stream: evaluation"), 1u);
  EXPECT_NE(std::find_if(track_names.begin(), track_names.end(),
                         [](const auto& named) { return named.second == "producer, end of stream"; }),
            track_names.end());
  EXPECT_NE(output.find("p99 ms"), std::string::npos) << "profiler table on stderr";
}

// A folder holding another run's outputs is refused (nothing in it changes) unless --force, which
// replaces them; the same for compare.
TEST(E2eRun, AnotherRunsOutputsAreRefusedUnlessForced) {
  const fs::path dataset = make_kitti_dataset(30);
  const fs::path out = testing::make_temp_dir("e2e-run-refuse");
  // A margin the 30 frames exceed: a run that cannot compare any pair fails.
  const std::string base =
      "run --dataset " + dataset.string() + " --out " + out.string() + " --set match.margin=20";
  int status = -1;
  std::string output = run(base + " --mode full", &status);
  ASSERT_EQ(status, 0) << output;
  const std::string frames_before = read_file(out / "frames.csv");
  const std::string summary_before = read_file(out / "summary.json");
  output = run(base + " --mode gated", &status);
  EXPECT_EQ(status, 1) << output;
  EXPECT_NE(output.find("already holds another run's outputs (frames.csv, loops.csv"), std::string::npos)
      << output;
  EXPECT_NE(output.find("--force"), std::string::npos) << output;
  EXPECT_EQ(read_file(out / "frames.csv"), frames_before);
  EXPECT_EQ(read_file(out / "summary.json"), summary_before);
  output = run(base + " --mode gated --force", &status);
  EXPECT_EQ(status, 0) << output;
  const auto summary = nlohmann::json::parse(read_file(out / "summary.json"));
  EXPECT_EQ(summary["config"]["run"]["mode"].get<std::string>(), "gated");

  const fs::path compare_out = testing::make_temp_dir("e2e-compare-refuse");
  const std::string compare = "compare --dataset " + dataset.string() + " --out " + compare_out.string() +
                              " --no-plots --methods full --set match.margin=20";
  ASSERT_EQ((run(compare, &status), status), 0);
  output = run(compare, &status);
  EXPECT_EQ(status, 1) << output;
  EXPECT_NE(output.find("compare: --out"), std::string::npos) << output;
  output = run(compare + " --force", &status);
  EXPECT_EQ(status, 0) << output;

  // The two-sequence compare (the same check of its folder).
  const fs::path two_out = testing::make_temp_dir("e2e-compare-two-refuse");
  const std::string two = "compare --reference " + dataset.string() + " --query " + dataset.string() +
                          " --out " + two_out.string() + " --no-plots --methods full";
  ASSERT_EQ((run(two, &status), status), 0);
  const std::string compare_json = read_file(two_out / "compare.json");
  output = run(two, &status);
  EXPECT_EQ(status, 1) << output;
  EXPECT_NE(output.find("already holds another run's outputs (compare.json, full"), std::string::npos)
      << output;
  EXPECT_EQ(read_file(two_out / "compare.json"), compare_json);
  output = run(two + " --force", &status);
  EXPECT_EQ(status, 0) << output;
}

TEST(E2eRun, ConfigErrorsNameTheKey) {
  const fs::path dataset = make_kitti_dataset(3);
  const fs::path out = testing::make_temp_dir("e2e-run-bad");
  int status = -1;
  std::string output = run(
      "run --dataset " + dataset.string() + " --out " + out.string() + " --set odometry.sigma=1", &status);
  EXPECT_EQ(status, 1);
  EXPECT_NE(output.find("unknown key 'odometry.sigma'"), std::string::npos) << output;
  output = run("run --dataset " + dataset.string() + " --out " + out.string() + " --rate fast", &status);
  EXPECT_EQ(status, 1);
  EXPECT_NE(output.find("run.rate"), std::string::npos) << output;
}

TEST(E2eRun, SigintDrainsWritesOutputsAndExits130) {
  const fs::path dataset = make_kitti_dataset(100);  // 10 s of data, replayed in real time
  const fs::path out = testing::make_temp_dir("e2e-run-int");
  const std::string binary = testing::loopgate_binary().string();
  // The signal comes on an event (the progress line: a frame is through the sink), not after a timer.
  testing::Child child({binary, "run", "--dataset", dataset.string(), "--out", out.string(), "--rate", "1.0",
                        "--set", "odometry.heading_axis=y", "--set", "output.progress=on"});
  ASSERT_TRUE(child.wait_for_output("[run] ")) << child.output();
  child.send(SIGINT);
  EXPECT_EQ(child.wait(), 130) << child.output();
  const auto summary = nlohmann::json::parse(read_file(out / "summary.json"));
  EXPECT_TRUE(summary["interrupted"].get<bool>());
  const int processed = summary["frames_processed"].get<int>();
  EXPECT_GT(processed, 0);
  EXPECT_LT(processed, 100);
  EXPECT_EQ(summary["frames_in"].get<int>(), processed);
  EXPECT_EQ(read_csv(out / "frames.csv").size(), static_cast<std::size_t>(processed));
  EXPECT_EQ(read_csv(out / "timing.csv").size(), static_cast<std::size_t>(processed));
}

TEST(E2eRun, SimulatedDemoWithImu) {
  const fs::path sim = testing::make_temp_dir("e2e-run-sim");
  int status = -1;
  std::string output = run("simulate --preset demo --frames 30 --force --out " + sim.string(), &status);
  ASSERT_EQ(status, 0) << output;
  const fs::path out = testing::make_temp_dir("e2e-run-sim-out");
  output = run("run --config " + std::string(LOOPGATE_SOURCE_DIR) + "/configs/demo.yaml --dataset " +
                   sim.string() + " --out " + out.string() + " --set run.decode=all --set match.margin=20",
               &status);
  ASSERT_EQ(status, 0) << output;
  const auto rows = read_csv(out / "frames.csv");
  ASSERT_EQ(rows.size(), 30u);
  for (std::size_t i = 0; i < rows.size(); ++i) {
    EXPECT_EQ(rows[i][1], std::to_string(i));
    EXPECT_EQ(rows[i][15], "ok") << rows[i][16];
    EXPECT_EQ(rows[i][14], "y");
    if (i > 0) {
      EXPECT_GE(std::stoi(rows[i][13]), 2);  // IMU samples between consecutive images
    }
  }
  const auto summary = nlohmann::json::parse(read_file(out / "summary.json"));
  EXPECT_EQ(summary["frames_processed"].get<int>(), 30);
  EXPECT_TRUE(summary["dataset"]["has_imu"].get<bool>());
  // Provenance: how this output was made.
  const auto& provenance = summary.at("provenance");
  EXPECT_NE(provenance.at("command_line").get<std::string>().find(" run --config "), std::string::npos)
      << provenance.dump();
  EXPECT_NE(provenance.at("command_line").get<std::string>().find(out.string()), std::string::npos);
  EXPECT_EQ(provenance.at("version").get<std::string>().rfind(LOOPGATE_PROJECT_VERSION " (", 0), 0u)
      << provenance.dump();
  EXPECT_EQ(provenance.at("config_hash").get<std::string>().size(), 16u);
  EXPECT_FALSE(provenance.at("start_time_utc").get<std::string>().empty());

  // Damage the IMU file: drop 60 rows (0.3 s at 200 Hz) in the middle and cut the last line in half.
  const fs::path imu_csv = sim / "mav0" / "imu0" / "data.csv";
  std::istringstream original(read_file(imu_csv));
  std::vector<std::string> lines;
  for (std::string line; std::getline(original, line);) lines.push_back(line);
  ASSERT_GT(lines.size(), 500u);
  std::ofstream damaged(imu_csv, std::ios::trunc);
  for (std::size_t i = 0; i + 1 < lines.size(); ++i) {
    if (i < 300 || i >= 360) damaged << lines[i] << "\n";
  }
  damaged << lines.back().substr(0, lines.back().size() / 2);
  damaged.close();
  const fs::path out2 = testing::make_temp_dir("e2e-run-sim-bad");
  output = run("run --config " + std::string(LOOPGATE_SOURCE_DIR) + "/configs/demo.yaml --dataset " +
                   sim.string() + " --out " + out2.string() + " --set match.margin=20",
               &status);
  ASSERT_EQ(status, 0) << output;
  const auto rows2 = read_csv(out2 / "frames.csv");
  ASSERT_EQ(rows2.size(), 30u);
  int gap_frames = 0;
  for (const auto& row : rows2) {
    if (row[16].find("IMU gap") != std::string::npos) {
      ++gap_frames;
      EXPECT_EQ(row[15], "warning");
    }
  }
  EXPECT_GE(gap_frames, 3);  // a 0.3 s gap overlaps at least 3 frame intervals of 0.1 s
  const auto summary2 = nlohmann::json::parse(read_file(out2 / "summary.json"));
  EXPECT_EQ(summary2["data_issues"]["imu_gaps"].get<int>(), gap_frames);
  EXPECT_GE(summary2["data_issues"]["dataset_issue_count"].get<int>(), 1) << summary2["data_issues"].dump();
  EXPECT_EQ(summary2["frames_processed"].get<int>(), 30);
}

// trajectory.tum holds only the poses the odometry estimated: the EKF initialises from ground
// truth, which here begins at frame 10, so frames 0-9 are "initialising" and had been written as identity
// poses (evo then failed on a short EuRoC excerpt). Every row of trajectory.tum is a tracking frame's pose.
TEST(E2eRun, TrajectoryHoldsOnlyEstimatedPoses) {
  const fs::path sim = testing::make_temp_dir("e2e-run-ekf");
  int status = -1;
  std::string output =
      run("--log-level warn simulate --preset demo --frames 40 --force --out " + sim.string(), &status);
  ASSERT_EQ(status, 0) << output;
  std::vector<std::string> frame_times;
  {
    std::istringstream cam(read_file(sim / "mav0/cam0/data.csv"));
    for (std::string line; std::getline(cam, line);)
      if (!line.empty() && line[0] != '#') frame_times.push_back(line.substr(0, line.find(',')));
  }
  ASSERT_EQ(frame_times.size(), 40u);
  // Ground truth from frame 10's time on.
  const fs::path truth = sim / "mav0/state_groundtruth_estimate0/data.csv";
  std::istringstream in(read_file(truth));
  std::string kept;
  for (std::string line; std::getline(in, line);) {
    if (line.empty() || line[0] == '#' ||
        std::stoll(line.substr(0, line.find(','))) >= std::stoll(frame_times[10])) {
      kept += line + "\n";
    }
  }
  std::ofstream(truth, std::ios::trunc) << kept;

  const fs::path out = testing::make_temp_dir("e2e-run-ekf-out");
  output = run("--log-level warn run --dataset " + sim.string() + " --mode odometry --out " + out.string() +
                   " --set odometry.source=ekf --set ekf.init_mode=ground_truth --set output.progress=off",
               &status);
  ASSERT_EQ(status, 0) << output;
  std::vector<std::string> header;
  const auto rows = read_csv(out / "frames.csv", &header);
  ASSERT_EQ(rows.size(), 40u);
  const std::size_t t_column = testing::column_index(header, "t_ns");
  const std::size_t odom_column = testing::column_index(header, "odom_status");
  std::vector<std::string> tracking_times;
  for (std::size_t i = 0; i < rows.size(); ++i) {
    if (i < 10) {
      EXPECT_EQ(rows[i][odom_column], "initialising") << i;
    }
    if (rows[i][odom_column] == "tracking") tracking_times.push_back(rows[i][t_column]);
  }
  ASSERT_GT(tracking_times.size(), 20u) << output;
  std::vector<std::string> tum_times;
  std::istringstream tum(read_file(out / "trajectory.tum"));
  for (std::string line; std::getline(tum, line);) {
    std::istringstream row(line);
    double t_s = 0, x = 0, y = 0, z = 0;
    row >> t_s >> x >> y >> z;
    tum_times.push_back(std::to_string(std::llround(t_s * 1e9)));
  }
  ASSERT_EQ(tum_times.size(), tracking_times.size());
  for (std::size_t k = 0; k < tum_times.size(); ++k)
    EXPECT_NEAR(std::stod(tum_times[k]), std::stod(tracking_times[k]), 1e3) << k;  // TUM: seconds, 9 decimals
}

// --calibration FILE sets dataset.calibration: a missing file is an error naming the key and the file before
// anything runs; a KITTI sequence, which has its own calib.txt, refuses a Kalibr chain and names it.
TEST(E2eRun, CalibrationOptionIsCheckedAndNamed) {
  const fs::path dataset = make_kitti_dataset(20);
  const fs::path dir = testing::make_temp_dir("e2e-run-calibration");
  const std::string base = "run --config " + std::string(LOOPGATE_SOURCE_DIR) +
                           "/configs/kitti00-thumbs.yaml --dataset " + dataset.string() +
                           " --set output.progress=off --calibration ";
  int status = -1;
  std::string output =
      run(base + (dir / "missing.yaml").string() + " --out " + (dir / "out-missing").string(), &status);
  EXPECT_NE(status, 0) << output;
  EXPECT_NE(output.find("dataset.calibration"), std::string::npos) << output;
  EXPECT_NE(output.find((dir / "missing.yaml").string()), std::string::npos) << output;
  std::ofstream(dir / "camchain-imucam-lab.yaml") << "cam0:\n  camera_model: pinhole\n";
  output = run(base + (dir / "camchain-imucam-lab.yaml").string() + " --out " + (dir / "out-kitti").string(),
               &status);
  EXPECT_NE(status, 0) << output;
  EXPECT_NE(output.find((dir / "camchain-imucam-lab.yaml").string() + ": --calibration"), std::string::npos)
      << output;
  EXPECT_NE(output.find("is a KITTI sequence"), std::string::npos) << output;
}

// eval.truth_pairs_file: the published (query, reference) pairs are the run's loop ground truth;
// the key is printed at start and echoed in summary.json; a pair naming a frame the dataset does not have is
// an error naming the file and line, before anything is written.
TEST(E2eRun, TruthPairsFileIsTheGroundTruth) {
  const fs::path dataset = make_kitti_dataset(60);
  for (int i = 40; i < 60; ++i) {  // frames 40..59 revisit 0..19 (the same pixels)
    char from[32], to[32];
    std::snprintf(from, sizeof(from), "%06d.png", i - 40);
    std::snprintf(to, sizeof(to), "%06d.png", i);
    fs::copy_file(dataset / "image_0" / from, dataset / "image_0" / to, fs::copy_options::overwrite_existing);
  }
  const fs::path dir = testing::make_temp_dir("e2e-run-pairs");
  {
    std::ofstream pairs(dir / "gt.csv");
    pairs << "query_index0,match_index0,query_file,match_file\n";
    for (int i = 40; i < 60; ++i) pairs << i << "," << i - 40 << ",q.png,r.png\n";
  }
  const std::string base =
      "run --config " + std::string(LOOPGATE_SOURCE_DIR) + "/configs/kitti00-thumbs.yaml --dataset " +
      dataset.string() +
      " --mode full --set match.margin=20 --set output.progress=off --set eval.truth_pairs_file=";
  int status = -1;
  std::string output = run(base + (dir / "gt.csv").string() + " --out " + (dir / "out").string(), &status);
  ASSERT_EQ(status, 0) << output;
  // The effective configuration is in the run folder (config.yaml), not on the console.
  EXPECT_NE(
      read_file(dir / "out" / "config.yaml").find("truth_pairs_file: \"" + (dir / "gt.csv").string() + "\""),
      std::string::npos)
      << read_file(dir / "out" / "config.yaml");
  EXPECT_EQ(output.find("eval.truth_pairs_file = "), std::string::npos) << output;
  const auto summary = nlohmann::json::parse(read_file(dir / "out" / "summary.json"));
  EXPECT_EQ(summary["config"]["eval"]["truth_pairs_file"], (dir / "gt.csv").string());
  const auto& evaluation = summary["evaluation"];
  ASSERT_TRUE(evaluation["available"].get<bool>()) << evaluation.dump();
  EXPECT_EQ(evaluation["truth"]["pairs_file"], (dir / "gt.csv").string());
  EXPECT_EQ(evaluation["truth"]["pairs"], 20);
  EXPECT_EQ(evaluation["truth"]["pairs_in_run"], 20);
  EXPECT_EQ(evaluation["truth"]["positives"], 20);
  const auto& truth = evaluation["loop_truth"];
  EXPECT_EQ(truth["loops"].get<int>(), truth["loops_true"].get<int>() + truth["loops_false"].get<int>());
  const auto truth_loops = read_csv(dir / "out" / "truth_loops.csv");
  ASSERT_EQ(truth_loops.size(), 20u);
  EXPECT_EQ(truth_loops[0], (std::vector<std::string>{"40", "0"}));
  // --frames 30: leaves out the pairs whose frames the run does not have, and says how many it used.
  output =
      run(base + (dir / "gt.csv").string() + " --frames 0:50 --out " + (dir / "out-range").string(), &status);
  ASSERT_EQ(status, 0) << output;
  const auto ranged = nlohmann::json::parse(read_file(dir / "out-range" / "summary.json"));
  EXPECT_EQ(ranged["evaluation"]["truth"]["pairs_in_run"], 10);

  std::ofstream(dir / "other.csv") << "40,0\n75,3\n";
  output = run(base + (dir / "other.csv").string() + " --out " + (dir / "bad").string(), &status);
  EXPECT_EQ(status, 1) << output;
  EXPECT_NE(output.find((dir / "other.csv").string() +
                        ":2: frame 75 is not a frame of the dataset (its frames are numbered 0..59)"),
            std::string::npos)
      << output;
  EXPECT_FALSE(fs::exists(dir / "bad" / "frames.csv"));
}

// The lines a run prints on stdout (stderr, where the logs and the stage table go, left out).
std::vector<std::string> stdout_lines(const std::string& args, int* status) {
  std::string output;
  *status =
      testing::run_command("(" + testing::loopgate_binary().string() + " " + args + " 2>/dev/null)", &output);
  std::vector<std::string> lines;
  std::istringstream in(output);
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

std::string joined(const std::vector<std::string>& lines) {
  std::string text;
  for (const auto& line : lines) text += line + "\n";
  return text;
}

// At its end `run` prints a short result block on stdout: frames and real-time factor, loops true/false,
// AP / R@1 / R@100P (n/a where no true loop exists), ATE, problems, the output folder; the configuration goes
// to OUT/config.yaml (loadable again as --config) and to --log-level debug, not to the console.
TEST(E2eRun, ConsoleShowsTheResultBlockNotTheConfiguration) {
  const fs::path dataset = make_kitti_dataset(60);
  for (int i = 40; i < 60; ++i) {  // frames 40..59 revisit 0..19 (the same pixels and poses)
    char from[32], to[32];
    std::snprintf(from, sizeof(from), "%06d.png", i - 40);
    std::snprintf(to, sizeof(to), "%06d.png", i);
    fs::copy_file(dataset / "image_0" / from, dataset / "image_0" / to, fs::copy_options::overwrite_existing);
  }
  {
    std::ifstream in(dataset / "poses.txt");
    std::vector<std::string> rows;
    for (std::string row; std::getline(in, row);) rows.push_back(row);
    std::ofstream out(dataset / "poses.txt");
    for (int i = 0; i < 60; ++i) out << rows[static_cast<std::size_t>(i < 40 ? i : i - 40)] << "\n";
  }
  const fs::path dir = testing::make_temp_dir("e2e-run-result");
  const std::string args = "run --config " + std::string(LOOPGATE_SOURCE_DIR) +
                           "/configs/kitti00-thumbs.yaml --mode full --set match.margin=20 "
                           "--set output.progress=off --set eval.truth_gap_frames=10 --dataset " +
                           dataset.string();
  int status = -1;
  const auto lines = stdout_lines(args + " --out " + (dir / "a").string(), &status);
  ASSERT_EQ(status, 0) << joined(lines);
  ASSERT_GE(lines.size(), 6u) << joined(lines);
  EXPECT_LE(lines.size(), 12u) << joined(lines);
  const auto summary = nlohmann::json::parse(read_file(dir / "a" / "summary.json"));
  const std::string text = joined(lines);
  EXPECT_NE(text.find("frames     60 of 60 processed"), std::string::npos) << text;
  EXPECT_NE(text.find("real-time factor"), std::string::npos) << text;
  const auto& truth = summary["evaluation"]["loop_truth"];
  EXPECT_GT(truth["loops_true"].get<int>(), 0) << summary["evaluation"].dump();
  EXPECT_NE(text.find(fmt::format("loops      {}: {} true, {} false", summary["loops"].get<int>(),
                                  truth["loops_true"].get<int>(), truth["loops_false"].get<int>())),
            std::string::npos)
      << text;
  EXPECT_NE(text.find(fmt::format(
                "AP {:.3f}", summary["evaluation"]["precision_recall"]["average_precision"].get<double>())),
            std::string::npos)
      << text;
  EXPECT_NE(text.find("R@100P"), std::string::npos) << text;
  EXPECT_NE(text.find("ATE        odometry"), std::string::npos) << text;
  EXPECT_NE(text.find("problems   none"), std::string::npos) << text;
  EXPECT_NE(text.find("outputs    " + (dir / "a").string()), std::string::npos) << text;
  // No configuration echo on the console at the default log level, even on stderr.
  std::string everything;
  ASSERT_EQ(
      testing::run_command(
          testing::loopgate_binary().string() + " " + args + " --out " + (dir / "b").string(), &everything),
      0);
  EXPECT_EQ(everything.find("posegraph.max_iterations"), std::string::npos) << everything;
  EXPECT_EQ(everything.find("configuration:"), std::string::npos) << everything;
  // ... but in config.yaml, which runs again to the same loops, and at --log-level debug.
  const std::string config = read_file(dir / "a" / "config.yaml");
  EXPECT_NE(config.find("posegraph:"), std::string::npos) << config;
  EXPECT_NE(config.find("  margin: 20"), std::string::npos) << config;
  ASSERT_EQ(testing::run_command(testing::loopgate_binary().string() + " --log-level debug run --config " +
                                     (dir / "a" / "config.yaml").string() + " --out " + (dir / "c").string(),
                                 &everything),
            0)
      << everything;
  EXPECT_NE(everything.find("posegraph.max_iterations = "), std::string::npos) << everything;
  const auto again = nlohmann::json::parse(read_file(dir / "c" / "summary.json"));
  EXPECT_EQ(again["loops"], summary["loops"]);
  EXPECT_EQ(again["config"], summary["config"]);

  // Without a true loop in the range, AP and recall are n/a, not 0.
  const auto none = stdout_lines(args + " --frames 0:30 --out " + (dir / "d").string(), &status);
  ASSERT_EQ(status, 0) << joined(none);
  EXPECT_NE(joined(none).find("AP n/a, R@1 n/a, R@100P n/a"), std::string::npos) << joined(none);
}

TEST(E2eRun, KittiThumbsEveryFrameOnceInOrder) {
  LOOPGATE_REQUIRE_SHARED_DATA("kitti/00/thumbs");
  const fs::path out = testing::make_temp_dir("e2e-run-thumbs");
  int status = -1;
  const std::string output =
      run("run --config " + std::string(LOOPGATE_SOURCE_DIR) + "/configs/kitti00-thumbs.yaml --dataset " +
              (testing::shared_data_dir() / "kitti/00/thumbs").string() + " --out " + out.string() +
              " --set run.decode=all",
          &status);
  ASSERT_EQ(status, 0) << output;
  const auto rows = read_csv(out / "frames.csv");
  ASSERT_EQ(rows.size(), 4540u);
  for (std::size_t i = 0; i < rows.size(); ++i) {
    ASSERT_EQ(rows[i][0], std::to_string(i));
    ASSERT_EQ(rows[i][1], std::to_string(i));
    ASSERT_EQ(rows[i][15], "ok");
  }
  const auto summary = nlohmann::json::parse(read_file(out / "summary.json"));
  EXPECT_EQ(summary["frames_in"].get<int>(), 4540);
  EXPECT_EQ(summary["frames_processed"].get<int>() + summary["frames_dropped"].get<int>(),
            summary["frames_in"].get<int>());
  EXPECT_GT(summary["realtime_factor"].get<double>(), 0.0);
}

}  // namespace
}  // namespace loopgate
