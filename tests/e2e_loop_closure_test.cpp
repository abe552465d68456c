// The loop closer end to end: on a short rendered street drive, loops forced by a small match
// margin (pairs a few metres apart, which do share geometry) are verified and corrected identically with 1
// and 2 threads, and the outputs carry their columns; thumbnail-size images skip verification with a reason;
// the aliasing preset's copied street verifies in the images and is rejected by the odometry check; without
// verify.enabled no loop-closure output appears; compare's loop correction after a run gives the
// files the run gives.
#include <gtest/gtest.h>

#include <Eigen/Core>
#include <algorithm>
#include <iostream>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "io/g2o_file.hpp"
#include "io/trajectory_io.hpp"
#include "stages/posegraph/pose_graph.hpp"
#include "test_support.hpp"

namespace loopgate {
namespace {

namespace fs = std::filesystem;
using testing::read_csv;
using testing::read_file;

std::string run(const std::string& args, int* status) {
  std::string output;
  *status = testing::run_command(testing::loopgate_binary().string() + " --log-level warn " + args, &output);
  return output;
}

fs::path simulate(const std::string& name, const std::string& extra) {
  const fs::path sim = testing::make_temp_dir(name);
  int status = -1;
  const std::string output =
      run("simulate --preset demo --frames 60 --force --out " + sim.string() + " " + extra, &status);
  EXPECT_EQ(status, 0) << output;
  return sim;
}

// configs/demo.yaml with verify.enabled=true (the demo config has it off) in full mode with loops forced
// between frames ~5 m apart. Such loops tell the pose graph nothing the odometry does not know, so the
// loop closer would skip them (verify.min_information_gain, tested below): here every one is verified.
fs::path run_forced(const fs::path& sim, int threads, const std::string& extra = "") {
  const fs::path out = testing::make_temp_dir("e2e-closure-out-" + std::to_string(threads));
  int status = -1;
  const std::string output =
      run("run --config " + std::string(LOOPGATE_SOURCE_DIR) + "/configs/demo.yaml --dataset " +
              sim.string() + " --out " + out.string() + " --mode full --threads " + std::to_string(threads) +
              " --set match.margin=4 --set dird_seqslam.min_score=0 --set output.progress=off --set "
              "verify.enabled=true --set verify.min_information_gain=0 " +
              extra,
          &status);
  EXPECT_EQ(status, 0) << output;
  return out;
}

// compare of dird-seqslam on two threads with run_forced()'s settings: each method's run without
// verification, then its loops verified and its trajectory corrected after the run. `output`: what it
// printed.
fs::path compare_forced(const fs::path& sim, const std::string& name, const std::string& extra,
                        std::string* output) {
  const fs::path out = testing::make_temp_dir(name);
  int status = -1;
  *output = run("compare --config " + std::string(LOOPGATE_SOURCE_DIR) + "/configs/demo.yaml --dataset " +
                    sim.string() + " --out " + out.string() +
                    " --methods dird-seqslam --no-plots --threads 2 --set match.margin=4 --set "
                    "dird_seqslam.min_score=0 --set output.progress=off --set verify.enabled=true --set "
                    "verify.min_information_gain=0 " +
                    extra,
                &status);
  EXPECT_EQ(status, 0) << *output;
  return out;
}

std::vector<std::string> header(const fs::path& csv) {
  std::vector<std::string> h;
  read_csv(csv, &h);
  return h;
}

std::size_t line_count(const fs::path& file) {
  const std::string text = read_file(file);
  return static_cast<std::size_t>(std::count(text.begin(), text.end(), '\n'));
}

// loop_edges.csv without its verify_ms column (a timing).
std::vector<std::vector<std::string>> edges_without_timing(const fs::path& out) {
  auto rows = read_csv(out / "loop_edges.csv");
  for (auto& row : rows) row.pop_back();
  return rows;
}

// pose_graph.g2o holds the final solve's graph: solved again as it stands (the same loss on the edges that
// join non-consecutive nodes, the loops), it gives trajectory_corrected.tum's poses at its nodes.
void expect_graph_file_gives_the_corrected_trajectory(const fs::path& out) {
  const G2oGraph file = read_g2o(out / "pose_graph.g2o");
  std::vector<std::string> frames_header;
  const auto frames = read_csv(out / "frames.csv", &frames_header);
  const auto column = [&](const std::string& name) {
    return static_cast<std::size_t>(std::find(frames_header.begin(), frames_header.end(), name) -
                                    frames_header.begin());
  };
  std::map<std::int64_t, Timestamp> t_of_frame;
  for (const auto& row : frames)
    t_of_frame[std::stoll(row[column("frame")])] = std::stoll(row[column("t_ns")]);
  std::map<Timestamp, Eigen::Isometry3d> corrected;
  for (const StampedPose& p : read_tum(out / "trajectory_corrected.tum")) corrected[p.t_ns] = p.T_w_b;

  ASSERT_GE(file.vertices.size(), 2u);
  ASSERT_EQ(file.fixed, std::vector<std::int64_t>{file.vertices.front().id});
  PoseGraph graph{PoseGraphConfig{}};
  std::map<std::int64_t, std::size_t> node_of;
  for (const G2oVertex& v : file.vertices) node_of[v.id] = graph.add_node(v.T_w_b);
  std::size_t loops = 0;
  for (const G2oEdge& e : file.edges) {
    const std::size_t a = node_of.at(e.a), b = node_of.at(e.b);
    const bool odometry = b == a + 1;
    loops += odometry ? 0 : 1;
    graph.add_edge(a, b, odometry ? EdgeKind::kOdometry : EdgeKind::kLoop, e.T_a_b, e.information.inverse());
  }
  EXPECT_EQ(file.edges.size() - loops, file.vertices.size() - 1);  // a chain of odometry edges
  EXPECT_GT(loops, 0u);
  graph.optimize(true, 0.0);
  double worst_m = 0;
  for (const G2oVertex& v : file.vertices) {
    const auto t = t_of_frame.find(v.id);
    ASSERT_NE(t, t_of_frame.end()) << "vertex " << v.id << " is not a frame of frames.csv";
    // trajectory_corrected.tum keeps 1 ns.
    const auto it = corrected.lower_bound(t->second - 1);
    ASSERT_NE(it, corrected.end());
    ASSERT_LE(std::abs(it->first - t->second), 1) << "vertex " << v.id;
    worst_m = std::max(worst_m, (graph.pose(node_of[v.id]).translation() - it->second.translation()).norm());
  }
  EXPECT_LT(worst_m, 1e-3);
}

TEST(E2eLoopClosure, SameOutputsWithOneAndTwoThreadsAndTheirColumns) {
  const fs::path sim = simulate("e2e-closure-sim", "");
  const fs::path one = run_forced(sim, 1);
  const fs::path two = run_forced(sim, 2);

  const auto summary = nlohmann::json::parse(read_file(one / "summary.json"));
  ASSERT_TRUE(summary.contains("loops_verified")) << summary.dump();
  EXPECT_GT(summary["loops_verified"].get<int>(), 0);
  EXPECT_TRUE(summary.contains("loops_rejected_geometry"));
  EXPECT_TRUE(summary.contains("loops_skipped_geometry"));
  ASSERT_TRUE(summary.contains("trajectory_accuracy_corrected"));
  EXPECT_TRUE(summary["trajectory_accuracy_corrected"].contains("rmse_m"));
  EXPECT_GT(summary["loop_closure"]["verify"]["count"].get<int>(), 0);
  // The demo's first 60 frames are lit alike: ORB verifies or rejects, the tracking fallback never runs.
  EXPECT_EQ(summary["loop_closure"]["verified_by_tracking"].get<int>(), 0);
  // The odometry edges carry the odometry's own covariance (drift source here), scaled by what the loops
  // show.
  EXPECT_EQ(summary["loop_closure"]["odometry_cov"], "odometry");
  EXPECT_GE(summary["loop_closure"]["odometry_cov_scale"].get<double>(), 1.0);

  EXPECT_EQ(header(one / "loop_edges.csv"), (std::vector<std::string>{"i",
                                                                      "j",
                                                                      "neighbour",
                                                                      "verified",
                                                                      "inliers",
                                                                      "matches",
                                                                      "points",
                                                                      "reason",
                                                                      "x_m",
                                                                      "y_m",
                                                                      "z_m",
                                                                      "qx",
                                                                      "qy",
                                                                      "qz",
                                                                      "qw",
                                                                      "sigma_position_m",
                                                                      "sigma_rotation_rad",
                                                                      "graph_outlier",
                                                                      "chi2",
                                                                      "verify_ms"}));
  const std::vector<std::string> loops_header = header(one / "loops.csv");
  const std::vector<std::string> tail{
      "verified", "inliers", "geometry_reason", "x_m", "y_m", "z_m", "qx", "qy", "qz", "qw"};
  ASSERT_GE(loops_header.size(), tail.size());
  EXPECT_EQ(std::vector<std::string>(loops_header.end() - static_cast<std::ptrdiff_t>(tail.size()),
                                     loops_header.end()),
            tail);
  EXPECT_EQ(header(one / "frames.csv").back(), "geometry");
  // Every loop is in loop_edges.csv once: verified (y), rejected (n) or skipped.
  const auto edges = read_csv(one / "loop_edges.csv");
  EXPECT_EQ(edges.size(), summary["loops"].get<std::size_t>());
  for (const auto& row : edges) {
    EXPECT_TRUE(row[3] == "y" || row[3] == "n" || row[3] == "skipped") << row[3];
    if (row[3] == "skipped") {
      EXPECT_EQ(row[7].rfind("skipped: ", 0), 0u) << row[7];
    } else if (row[3] == "n") {
      EXPECT_EQ(row[7].rfind("geometry: ", 0), 0u) << row[7];
    }
  }
  EXPECT_EQ(line_count(one / "trajectory_corrected.tum"), line_count(one / "trajectory.tum"));

  // timing.csv: the loop-closure columns, one row per frame, and the verification booked on the query frames
  // adds up to the summary's total (4 decimals per cell).
  std::vector<std::string> timing_header;
  const auto timing = read_csv(one / "timing.csv", &timing_header);
  ASSERT_GE(timing_header.size(), 2u);
  EXPECT_EQ(timing_header[timing_header.size() - 2], "loop_verify_ms");
  EXPECT_EQ(timing_header.back(), "loop_optimize_ms");
  EXPECT_EQ(timing.size(), summary["frames_processed"].get<std::size_t>());
  double verify_ms = 0, optimize_ms = 0;
  for (const auto& row : timing) {
    verify_ms += std::stod(row[row.size() - 2]);
    optimize_ms += std::stod(row.back());
  }
  EXPECT_NEAR(verify_ms, summary["loop_closure"]["verify"]["total_ms"].get<double>(),
              1e-3 + 1e-4 * static_cast<double>(timing.size()));
  const auto& streaming = summary["loop_closure"]["optimize_streaming"];
  EXPECT_NEAR(optimize_ms, streaming.value("total_ms", 0.0),
              1e-3 + 1e-4 * static_cast<double>(timing.size()));

  expect_graph_file_gives_the_corrected_trajectory(one);

  // Loops verified after the stream ended have their three frames' features detected on both threads at once
  // (LoopCloser::prefetch_features), on one thread one after the other: the same results.
  const auto summary_two = nlohmann::json::parse(read_file(two / "summary.json"));
  const auto& drain_one = summary["loop_closure"]["end_of_stream"];
  const auto& drain_two = summary_two["loop_closure"]["end_of_stream"];
  std::cerr << "end of stream, 1 thread: " << drain_one.dump() << "; 2 threads: " << drain_two.dump() << "\n";
  EXPECT_EQ(drain_one["features_detected_in_parallel"].get<int>(), 0);
  EXPECT_EQ(edges_without_timing(one), edges_without_timing(two));
  for (const char* file :
       {"trajectory_corrected.tum", "pose_graph.g2o", "loops.csv", "frames.csv", "trajectory.tum"})
    EXPECT_EQ(read_file(one / file), read_file(two / file)) << file;
}

// compare runs the methods without verification (their timing is the detectors'), then corrects each
// method's trajectory with its loops: the same loop_edges.csv and trajectory_corrected.tum as `run` with
// verify.enabled, the ATE before and after in compare.json and the table.
TEST(E2eLoopClosure, CompareCorrectsEachMethodLikeRun) {
  const fs::path sim = simulate("e2e-closure-compare-sim", "");
  const fs::path ran = run_forced(sim, 2);
  std::string output;
  const fs::path out = compare_forced(sim, "e2e-closure-compare-out", "", &output);
  EXPECT_NE(output.find("ATE corrected (m)"), std::string::npos) << output;
  const auto compare = nlohmann::json::parse(read_file(out / "compare.json"));
  const auto& method = compare["dird-seqslam"];
  ASSERT_TRUE(method.contains("loop_correction")) << method.dump();
  EXPECT_FALSE(method.contains("loops_verified"));  // the timed run itself did not verify
  const auto summary = nlohmann::json::parse(read_file(ran / "summary.json"));
  const auto& correction = method["loop_correction"];
  EXPECT_EQ(correction["loops_verified"], summary["loops_verified"]);
  EXPECT_EQ(correction["loops_rejected_geometry"], summary["loops_rejected_geometry"]);
  EXPECT_NEAR(correction["trajectory_accuracy_corrected"]["rmse_m"].get<double>(),
              summary["trajectory_accuracy_corrected"]["rmse_m"].get<double>(), 1e-9);
  EXPECT_EQ(edges_without_timing(out / "dird-seqslam"), edges_without_timing(ran));
  EXPECT_EQ(read_file(out / "dird-seqslam" / "trajectory_corrected.tum"),
            read_file(ran / "trajectory_corrected.tum"));
  EXPECT_EQ(read_file(out / "dird-seqslam" / "pose_graph.g2o"), read_file(ran / "pose_graph.g2o"));
  // The plots draw the trajectories before and after correction beside the ground truth.
  std::string plot_output;
  ASSERT_EQ(testing::run_command("/usr/bin/python3 " + std::string(LOOPGATE_SOURCE_DIR) +
                                     "/scripts/plot.py compare " + out.string(),
                                 &plot_output),
            0)
      << plot_output;
  EXPECT_TRUE(fs::is_regular_file(out / "plots" / "correction.png")) << plot_output;
}

// compare's correction submits every loop at once, so it verifies nearly all of them after its input ends,
// several at once on two threads (LoopCloser::verify_ahead, on a guess of the outcomes not known yet); a run
// on one thread verifies them one after the other. Without the skip windows most loops are verified: the
// same files.
TEST(E2eLoopClosure, LoopsVerifiedAtOnceAfterTheStreamGiveTheResultsOfOneAfterTheOther) {
  const fs::path sim = simulate("e2e-closure-ahead-sim", "");
  const std::string windows =
      "--set verify.skip_after_verified_frames=0 --set verify.skip_after_rejected_frames=0";
  const fs::path ran = run_forced(sim, 1, windows);
  std::string output;
  const fs::path out = compare_forced(sim, "e2e-closure-ahead-out", windows, &output);
  const auto compare = nlohmann::json::parse(read_file(out / "compare.json"));
  ASSERT_TRUE(compare["dird-seqslam"].contains("loop_correction")) << compare.dump();
  const auto& correction = compare["dird-seqslam"]["loop_correction"];
  const auto& drained = correction["loop_closure"]["end_of_stream"];
  EXPECT_GE(drained["loops_verified_in_parallel"].get<int>(), 4) << drained.dump();
  const auto summary = nlohmann::json::parse(read_file(ran / "summary.json"));
  // A loop not skipped is counted once, however many were verified on a guess and dropped. The worker starts
  // on the first loop submitted, before the correction's last submit ends the stream, so not every loop needs
  // to be counted as after the stream.
  EXPECT_LE(drained["loops_verified"].get<int>(),
            correction["loops_verified"].get<int>() + correction["loops_rejected_geometry"].get<int>())
      << drained.dump();
  EXPECT_LE(drained["loops_verified_in_parallel"].get<int>(), drained["loops_verified"].get<int>());
  EXPECT_EQ(summary["loop_closure"]["end_of_stream"]["loops_verified_in_parallel"].get<int>(), 0);
  EXPECT_EQ(correction["loops_verified"], summary["loops_verified"]);
  EXPECT_EQ(correction["loops_rejected_geometry"], summary["loops_rejected_geometry"]);
  EXPECT_EQ(edges_without_timing(out / "dird-seqslam"), edges_without_timing(ran));
  EXPECT_EQ(read_file(out / "dird-seqslam" / "trajectory_corrected.tum"),
            read_file(ran / "trajectory_corrected.tum"));
  EXPECT_EQ(read_file(out / "dird-seqslam" / "pose_graph.g2o"), read_file(ran / "pose_graph.g2o"));
}

TEST(E2eLoopClosure, ThumbnailImagesSkipVerificationWithAReason) {
  const fs::path sim = simulate("e2e-closure-thumbs",
                                "--set camera.width_px=64 --set camera.height_px=32 "
                                "--set camera.fx=37 --set camera.fy=37 "
                                "--set camera.cx=31.5 --set camera.cy=15.5");
  const fs::path out = run_forced(sim, 2);
  const auto summary = nlohmann::json::parse(read_file(out / "summary.json"));
  ASSERT_GT(summary["loops"].get<int>(), 0);
  EXPECT_EQ(summary["loops_verified"].get<int>(), 0);
  EXPECT_NE(summary["loop_closure"]["unusable_reason"].get<std::string>().find("image too small"),
            std::string::npos)
      << summary["loop_closure"].dump();
  for (const auto& row : read_csv(out / "loop_edges.csv")) {
    EXPECT_EQ(row[3], "n");
    EXPECT_NE(row[7].find("image too small for features (64x32"), std::string::npos) << row[7];
  }
  // Nothing verified: the corrected trajectory is the odometry's.
  EXPECT_NEAR(summary["trajectory_accuracy_corrected"]["rmse_m"].get<double>(),
              summary["trajectory_accuracy"]["rmse_m"].get<double>(), 1e-6);
}

// With the default verify.min_information_gain (0.1), the forced loops a few frames apart: the first is
// verified whatever its gain (no verified loop has checked the odometry between its frames yet), every loop
// skipped for small gain comes after a verified one, and the skips are counted under their key.
TEST(E2eLoopClosure, OnlyLoopsOverCheckedOdometryAreSkippedForGain) {
  const fs::path sim = simulate("e2e-closure-known", "");
  const fs::path out = run_forced(sim, 2, "--set verify.min_information_gain=0.1");
  const auto summary = nlohmann::json::parse(read_file(out / "summary.json"));
  ASSERT_GT(summary["loops"].get<int>(), 2);
  const auto rows = read_csv(out / "loop_edges.csv");
  ASSERT_FALSE(rows.empty());
  EXPECT_NE(rows.front()[3], "skipped") << rows.front()[7];
  bool verified_before = false;
  int gain_rows = 0;
  for (const auto& row : rows) {
    if (row[3] == "y") verified_before = true;
    if (row[7].find("skipped: information gain") == std::string::npos) continue;
    EXPECT_TRUE(verified_before) << row[7];
    ++gain_rows;
  }
  const auto& by_reason = summary["loop_closure"]["skipped_by_reason"];
  EXPECT_EQ(by_reason.contains("small_information_gain") ? by_reason["small_information_gain"].get<int>() : 0,
            gain_rows);
}

// A loop must be kept when the odometry's covariance claims to know T_j_i but nothing has checked that
// claim: the same drive's odometry read back from a file with a covariance that grows by 1e-12 m^2 per metre
// (over-confident, like an EKF's over a long drive) gives every forced loop a gain near 0. Trusting that
// covariance would skip them all; the loop closer verifies the first (and every one until a verified loop
// has checked the odometry between them).
TEST(E2eLoopClosure, ALoopOverUncheckedOdometryIsKeptWhateverItsGain) {
  const fs::path sim = simulate("e2e-closure-keep", "");
  const fs::path drift = run_forced(sim, 2);
  const fs::path out = run_forced(
      sim, 2,
      "--set verify.min_information_gain=0.1 --set odometry.source=file --set odometry.file=" +
          (drift / "trajectory.tum").string() +
          " --set odometry.file_format=tum --set odometry.file_sigma2_a_m2=1e-12 --set "
          "odometry.file_sigma2_b_m2_per_m=1e-12 --set odometry.file_rot_sigma2_a_rad2=1e-12 --set "
          "odometry.file_rot_sigma2_b_rad2_per_m=1e-12");
  const auto summary = nlohmann::json::parse(read_file(out / "summary.json"));
  const int loops = summary["loops"].get<int>();
  ASSERT_GT(loops, 2);
  EXPECT_GE(summary["loops_verified"].get<int>(), 1) << summary["loop_closure"].dump();
  const auto rows = read_csv(out / "loop_edges.csv");
  ASSERT_FALSE(rows.empty());
  EXPECT_NE(rows.front()[3], "skipped") << rows.front()[7];
  // The others were judged against that covariance: its gain is tiny, so they are skipped for it.
  EXPECT_GT(summary["loop_closure"]["skipped_by_reason"]["small_information_gain"].get<int>(), 0);
}

// A final pose-graph solve that fails (odometry covariances scaled to overflow) corrects nothing: the run
// fails with the reason in problems and a non-zero exit, trajectory_corrected.tum and pose_graph.g2o are not
// written and are listed as missing, nothing claims a correction, and the other outputs are all there.
TEST(E2eLoopClosure, AFailedSolveIsAFailedRun) {
  const fs::path sim = simulate("e2e-closure-failed-solve", "");
  const fs::path out = testing::make_temp_dir("e2e-closure-failed-solve-out");
  int status = -1;
  const std::string output =
      run("run --config " + std::string(LOOPGATE_SOURCE_DIR) + "/configs/demo.yaml --dataset " +
              sim.string() + " --out " + out.string() +
              " --mode full --threads 2 --set match.margin=4 --set dird_seqslam.min_score=0 --set "
              "output.progress=off --set verify.enabled=true --set verify.min_information_gain=0 --set "
              "posegraph.odometry_cov_scale=1e300",
          &status);
  EXPECT_NE(status, 0) << output;
  EXPECT_NE(output.find("the final solve failed"), std::string::npos) << output;
  const auto summary = nlohmann::json::parse(read_file(out / "summary.json"));
  EXPECT_TRUE(summary["failed"].get<bool>());
  ASSERT_GT(summary["loops_verified"].get<int>(), 0);  // there was something to correct
  ASSERT_EQ(summary["problems"].size(), 1u) << summary["problems"].dump();
  EXPECT_NE(summary["problems"][0].get<std::string>().find("pose graph: the final solve failed"),
            std::string::npos);
  EXPECT_FALSE(summary["trajectory_accuracy_corrected"]["available"].get<bool>());
  EXPECT_FALSE(summary["trajectory_accuracy_corrected"].contains("poses"));
  EXPECT_FALSE(fs::exists(out / "trajectory_corrected.tum"));
  EXPECT_FALSE(fs::exists(out / "pose_graph.g2o"));
  const std::string missing = summary["outputs_missing"].dump();
  EXPECT_NE(missing.find("trajectory_corrected.tum"), std::string::npos) << missing;
  EXPECT_NE(missing.find("pose_graph.g2o"), std::string::npos) << missing;
  for (const char* name : {"frames.csv", "loops.csv", "loop_edges.csv", "trajectory.tum", "timing.csv"})
    EXPECT_TRUE(fs::exists(out / name)) << name;
}

// posegraph.odometry_cov model: the fixed sigma model instead; another correction, as deterministic.
TEST(E2eLoopClosure, TheFixedOdometryModelStillCorrects) {
  const fs::path sim = simulate("e2e-closure-model-sim", "");
  // run_forced reuses its output folder per thread count: read each run's files before the next.
  const fs::path own = run_forced(sim, 2);
  const std::string own_loops = read_file(own / "loops.csv");
  const std::string own_corrected = read_file(own / "trajectory_corrected.tum");
  const fs::path model_one = run_forced(sim, 1, "--set posegraph.odometry_cov=model");
  const fs::path model = run_forced(sim, 2, "--set posegraph.odometry_cov=model");
  const auto summary = nlohmann::json::parse(read_file(model / "summary.json"));
  EXPECT_EQ(summary["loop_closure"]["odometry_cov"], "model");
  EXPECT_EQ(summary["loop_closure"]["odometry_cov_scale"].get<double>(), 1.0);
  EXPECT_GT(summary["loops_verified"].get<int>(), 0);
  EXPECT_EQ(own_loops, read_file(model / "loops.csv"));  // the same loops, verified alike
  EXPECT_NE(own_corrected, read_file(model / "trajectory_corrected.tum"));
  EXPECT_EQ(read_file(model / "trajectory_corrected.tum"), read_file(model_one / "trajectory_corrected.tum"));
}

// The aliasing preset's second street is a copy of the first, built and textured the same: ORB, triangulation
// and PnP verify loops between the copies. The odometry knows the streets are far apart, and the check
// against it (verify.odometry_chi2) rejects those loops, and only those.
TEST(E2eLoopClosure, TheAliasingPresetsCopiedStreetIsRejectedByTheOdometry) {
  const fs::path sim = testing::make_temp_dir("e2e-closure-aliasing-sim");
  int status = -1;
  std::string output = run("simulate --preset aliasing --force --out " + sim.string(), &status);
  ASSERT_EQ(status, 0) << output;
  // Ground-truth distance of the loop's frames, by frame number (frames.csv t_ns -> ground_truth.tum).
  const auto loops_by_truth = [](const fs::path& out, int* true_verified, int* false_verified,
                                 int* rejected_by_odometry) {
    std::map<Timestamp, Eigen::Vector3d> truth_at;
    for (const StampedPose& p : read_tum(out / "ground_truth.tum")) truth_at[p.t_ns] = p.T_w_b.translation();
    std::vector<std::string> h;
    std::map<std::string, Eigen::Vector3d> truth_of_frame;
    for (const auto& row : read_csv(out / "frames.csv", &h))
      truth_of_frame[row[0]] = truth_at.at(std::stoll(row[2]));
    *true_verified = *false_verified = *rejected_by_odometry = 0;
    for (const auto& row : read_csv(out / "loop_edges.csv")) {
      const double d_m = (truth_of_frame.at(row[0]) - truth_of_frame.at(row[1])).norm();
      if (row[3] == "y") ++(d_m <= 4.0 ? *true_verified : *false_verified);
      if (row[7].find(" m from the odometry's frame i, ") != std::string::npos) {
        ++*rejected_by_odometry;
        EXPECT_GT(d_m, 4.0) << row[0] << " " << row[1] << " " << row[7];
      }
    }
  };
  const std::string base = "run --config " + std::string(LOOPGATE_SOURCE_DIR) +
                           "/configs/aliasing.yaml --dataset " + sim.string() +
                           " --mode full --set output.progress=off --set verify.enabled=true --out ";
  int true_off = 0, false_off = 0, odometry_off = 0, true_on = 0, false_on = 0, odometry_on = 0;
  const fs::path off = testing::make_temp_dir("e2e-closure-aliasing-off");
  output = run(base + off.string() + " --set verify.odometry_chi2=0", &status);
  ASSERT_EQ(status, 0) << output;
  loops_by_truth(off, &true_off, &false_off, &odometry_off);
  const fs::path on = testing::make_temp_dir("e2e-closure-aliasing-on");
  output = run(base + on.string(), &status);
  ASSERT_EQ(status, 0) << output;
  loops_by_truth(on, &true_on, &false_on, &odometry_on);
  EXPECT_GT(false_off, 10);  // without the check the copies verify
  EXPECT_EQ(odometry_off, 0);
  EXPECT_EQ(false_on, 0);
  EXPECT_GE(odometry_on, false_off);
  EXPECT_GT(true_on, 10);
  EXPECT_EQ(true_on, true_off);

  // An odometry whose chain breaks between the streets (no pose for frames 200-210, so they are lost) cannot
  // say where frame i is relative to frame j: the check is left out and the copies verify again.
  const fs::path broken = testing::make_temp_dir("e2e-closure-aliasing-broken");
  std::vector<StampedPose> odometry;
  for (const StampedPose& p : read_tum(on / "ground_truth.tum"))
    if (p.t_ns < s_to_ns(19.95) || p.t_ns > s_to_ns(21.05)) odometry.push_back(p);
  write_tum(broken / "odometry.tum", odometry);
  const fs::path gap = broken / "run";
  output = run(base + gap.string() +
                   " --set odometry.source=file --set odometry.file=" + (broken / "odometry.tum").string(),
               &status);
  ASSERT_EQ(status, 0) << output;
  int true_gap = 0, false_gap = 0, odometry_gap = 0;
  loops_by_truth(gap, &true_gap, &false_gap, &odometry_gap);
  EXPECT_EQ(odometry_gap, 0);
  EXPECT_GT(false_gap, 10);
}

// The demo's only revisit is at night under street lamps, of a route driven by day. ORB does not match the
// night frames to the day's; the tracking fallback does. With 4x the demo's drift the corrected trajectory
// has at most half the odometry's error, and every loop verified at night was verified by
// tracking or by ORB with the reason saying which.
TEST(E2eLoopClosure, TheNightRevisitIsVerifiedByTrackingAndHalvesTheError) {
  const fs::path sim = testing::make_temp_dir("e2e-closure-night-sim");
  int status = -1;
  std::string output = run("simulate --preset demo --force --out " + sim.string(), &status);
  ASSERT_EQ(status, 0) << output;
  const fs::path out = testing::make_temp_dir("e2e-closure-night-out");
  output = run("run --config " + std::string(LOOPGATE_SOURCE_DIR) + "/configs/demo.yaml --dataset " +
                   sim.string() + " --out " + out.string() +
                   " --set verify.enabled=true --set odometry.drift_heading_sigma_rad_per_sqrt_m=0.0012"
                   " --set odometry.drift_position_sigma_m_per_sqrt_m=0.02 --set output.progress=off",
               &status);
  ASSERT_EQ(status, 0) << output;
  const auto summary = nlohmann::json::parse(read_file(out / "summary.json"));
  const double odometry_m = summary["trajectory_accuracy"]["rmse_m"].get<double>();
  const double corrected_m = summary["trajectory_accuracy_corrected"]["rmse_m"].get<double>();
  const int tracked = summary["loop_closure"]["verified_by_tracking"].get<int>();
  EXPECT_GE(tracked, 3) << summary["loop_closure"].dump();
  EXPECT_LE(corrected_m, 0.5 * odometry_m) << odometry_m << " -> " << corrected_m;
  std::vector<std::string> names;
  const auto loops = read_csv(out / "loops.csv", &names);
  const auto col = [&](const std::string& name) {
    return static_cast<std::size_t>(std::find(names.begin(), names.end(), name) - names.begin());
  };
  int by_tracking = 0;
  for (const auto& row : loops) {
    if (row[col("verified")] != "y") continue;
    const std::string& reason = row[col("geometry_reason")];
    EXPECT_TRUE(reason == "verified" || reason.rfind("verified by tracking (", 0) == 0) << reason;
    by_tracking += reason.rfind("verified by tracking", 0) == 0 ? 1 : 0;
  }
  EXPECT_EQ(by_tracking, tracked);
}

TEST(E2eLoopClosure, OffByDefault) {
  const fs::path sim = simulate("e2e-closure-off", "");
  const fs::path out = run_forced(sim, 2, "--set verify.enabled=false");
  const auto summary = nlohmann::json::parse(read_file(out / "summary.json"));
  EXPECT_FALSE(summary.contains("loops_verified"));
  EXPECT_FALSE(fs::exists(out / "loop_edges.csv"));
  EXPECT_FALSE(fs::exists(out / "trajectory_corrected.tum"));
  EXPECT_FALSE(fs::exists(out / "pose_graph.g2o"));
  EXPECT_NE(header(out / "frames.csv").back(), "geometry");
}

}  // namespace
}  // namespace loopgate
