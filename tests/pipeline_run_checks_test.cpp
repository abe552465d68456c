// The run's checks: a run that got nothing usable says what is missing, naming what it expected.
#include <gtest/gtest.h>

#include <string>

#include "pipeline/graph/run_checks.hpp"

namespace loopgate {
namespace {

// A healthy run: every frame with a pose and its image, far more frames than the margin.
RunCheckInput healthy() {
  RunCheckInput in;
  in.frames_processed = 300;
  in.odometry_source = "file";
  in.odometry_expected = "poses in traj.tum within odometry.file_max_gap_s = 0.5 s of the frame times";
  in.frames_with_pose = 300;
  in.frames_needing_image = 300;
  in.frames_decoded = 300;
  in.dataset_root = "/data/seq";
  in.detects = true;
  in.method = "dird";
  in.margin_key = "match.margin";
  in.margin_frames = 200;
  return in;
}

TEST(PipelineRunChecks, AHealthyRunHasNoProblem) {
  EXPECT_TRUE(run_problems(healthy()).empty());
  RunCheckInput some_lost = healthy();
  some_lost.frames_with_pose = 1;  // one pose is enough: frames without are reported frame by frame
  some_lost.frames_decoded = 1;
  EXPECT_TRUE(run_problems(some_lost).empty());
  RunCheckInput empty = healthy();
  empty.frames_processed = 0;  // nothing went through (interrupted at once): nothing to judge
  empty.frames_with_pose = 0;
  EXPECT_TRUE(run_problems(empty).empty());
}

TEST(PipelineRunChecks, NoOdometryNamesTheSourceAndWhatItExpected) {
  RunCheckInput in = healthy();
  in.frames_with_pose = 0;
  in.first_odometry_problem = "frame 0: odometry lost: trajectory file has no pose within file_max_gap_s";
  const auto problems = run_problems(in);
  ASSERT_EQ(problems.size(), 1u);
  EXPECT_EQ(
      problems[0],
      "no odometry: none of the 300 frames got a pose from odometry.source file; expected poses in "
      "traj.tum within odometry.file_max_gap_s = 0.5 s of the frame times (first frame: frame 0: odometry "
      "lost: trajectory file has no pose within file_max_gap_s)");
  // Appearance only: no pose is what was asked for.
  in.odometry_source = "none";
  EXPECT_TRUE(run_problems(in).empty());
}

// A source that starts from the data (the ekf): started within ekf.max_init_s and tracking at least
// ekf.min_tracked_share of the frames since, or a problem with the numbers.
RunCheckInput ekf_run() {
  RunCheckInput in = healthy();
  in.odometry_source = "ekf";
  in.max_init_s = 10.0;
  in.min_tracked_share = 0.8;
  OdometryStart start;
  start.started = true;
  start.method = "static";
  start.frame = 20;
  start.after_first_s = 1.0;
  start.frames_seen = 300;
  start.frames_since_start = 280;
  start.frames_tracking = 280;
  start.starts = 1;
  start.data_s = 15.0;
  in.start = start;
  in.frames_with_pose = 280;
  return in;
}

TEST(PipelineRunChecks, OdometryThatStartsFromTheDataMustStartInTimeAndTrack) {
  EXPECT_TRUE(run_problems(ekf_run()).empty());

  RunCheckInput never = ekf_run();
  never.start->started = false;
  never.start->status = "static: not still (accelerometer moving): low-passed accelerometer spread 0.3 m/s2";
  never.frames_with_pose = 0;
  auto problems = run_problems(never);
  ASSERT_EQ(problems.size(), 1u);
  EXPECT_EQ(problems[0],
            "no odometry: odometry.source ekf never started: still initialising after 15.00 s of data from "
            "the first frame (300 frames; ekf.max_init_s = 10 s): static: not still (accelerometer moving): "
            "low-passed accelerometer spread 0.3 m/s2");

  RunCheckInput late = ekf_run();
  late.start->after_first_s = 12.5;
  problems = run_problems(late);
  ASSERT_EQ(problems.size(), 1u);
  EXPECT_EQ(problems[0].rfind("odometry started late: ", 0), 0u) << problems[0];
  EXPECT_NE(problems[0].find("12.50 s"), std::string::npos) << problems[0];

  RunCheckInput few = ekf_run();
  few.start->frames_tracking = 200;  // 71.4% < 80%
  problems = run_problems(few);
  ASSERT_EQ(problems.size(), 1u);
  EXPECT_EQ(problems[0],
            "odometry tracked too few frames: odometry.source ekf tracked 200 of the 280 frames from its "
            "start on (71.4%; 1 start(s)); expected at least ekf.min_tracked_share = 80.0%");
}

TEST(PipelineRunChecks, NoImageNamesTheDatasetAndTheFirstError) {
  RunCheckInput in = healthy();
  in.frames_decoded = 0;
  in.first_image_error = "frame 0: image: /data/seq/image_0/000000.png: cannot decode image";
  const auto problems = run_problems(in);
  ASSERT_EQ(problems.size(), 1u);
  EXPECT_EQ(
      problems[0].rfind("no image: none of the 300 frames whose pixels the run needed could be read from "
                        "/data/seq",
                        0),
      0u)
      << problems[0];
  EXPECT_NE(problems[0].find("(first: frame 0: image: /data/seq/image_0/000000.png: cannot decode image)"),
            std::string::npos);
  // No frame needed its pixels (odometry from a file, gated frames read in describe): nothing to say.
  in.frames_needing_image = 0;
  EXPECT_TRUE(run_problems(in).empty());
}

TEST(PipelineRunChecks, NoDetectionPossibleWhenTheRunIsNotLongerThanTheMargin) {
  RunCheckInput in = healthy();
  in.frames_processed = 200;
  in.frames_with_pose = in.frames_decoded = in.frames_needing_image = 200;
  const auto problems = run_problems(in);
  ASSERT_EQ(problems.size(), 1u);
  EXPECT_EQ(problems[0].rfind("no detection possible: the run has 200 frames, and run.method dird compares a "
                              "frame only with frames at least match.margin = 200 frames before it",
                              0),
            0u)
      << problems[0];
  in.frames_processed = 201;
  EXPECT_TRUE(run_problems(in).empty());
  in.frames_processed = 20;
  in.detects = false;  // run.mode odometry
  EXPECT_TRUE(run_problems(in).empty());
}

TEST(PipelineRunChecks, EveryProblemIsSaid) {
  RunCheckInput in = healthy();
  in.frames_processed = 10;
  in.frames_with_pose = 0;
  in.frames_decoded = 0;
  in.frames_needing_image = 10;
  const auto problems = run_problems(in);
  ASSERT_EQ(problems.size(), 3u);
  EXPECT_EQ(problems[0].rfind("no odometry: ", 0), 0u);
  EXPECT_EQ(problems[1].rfind("no image: ", 0), 0u);
  EXPECT_EQ(problems[2].rfind("no detection possible: ", 0), 0u);
}

}  // namespace
}  // namespace loopgate
