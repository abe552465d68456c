// End-to-end tests of scripts/loop_edges_truth.py: a run directory holding loop_edges.csv, frames.csv and
// ground_truth.tum (as `loopgate run` writes them) gives, per outcome of the geometric verification, how far
// apart the two views of its loops are by the ground truth; skipped loops are left out, and bad input exits
// non-zero naming the file (and line).
#include <gtest/gtest.h>

#include <fstream>
#include <string>

#include "test_support.hpp"

namespace loopgate {
namespace {

namespace fs = std::filesystem;

std::string script() {
  return "/usr/bin/python3 " + (fs::path(LOOPGATE_SOURCE_DIR) / "scripts" / "loop_edges_truth.py").string();
}

void write(const fs::path& file, const std::string& text) {
  std::ofstream out(file);
  out << text;
}

// Frames 0..3 at t = 1..4 s. Frame 0 at the origin looking along x; frame 1 1 m away, the same orientation;
// frame 2 3 m away, turned 90 degrees about z; frame 3 at the origin, turned 30 degrees.
fs::path make_run(const std::string& name) {
  const fs::path dir = testing::make_temp_dir(name);
  write(dir / "frames.csv",
        "seq,frame,t_ns,t_s\n0,0,1000000000,1.000000000\n1,1,2000000000,2.000000000\n"
        "2,2,3000000000,3.000000000\n3,3,4000000000,4.000000000\n");
  write(dir / "ground_truth.tum",
        "# t x y z qx qy qz qw\n"
        "1.000000000 0 0 0 0 0 0 1\n"
        "2.000000000 1 0 0 0 0 0 1\n"
        "3.000000000 3 0 0 0 0 0.7071067811865476 0.7071067811865476\n"
        "4.000000000 0 0 0 0 0 0.25881904510252074 0.9659258022531567\n");
  write(dir / "loop_edges.csv",
        "i,j,verified,reason\n"
        "1,0,y,verified\n"
        "2,0,n,geometry: 0 inliers < 15; tracked: 0 of 30 points, 0 inliers\n"
        "3,0,n,geometry: 6 inliers < 15\n"
        "3,1,skipped,skipped: near (3; 0) rejected\n");
  return dir;
}

TEST(E2eLoopEdgesTruth, RangesPerOutcomeWithoutTheSkippedLoops) {
  const fs::path run = make_run("e2e-loop-edges-truth");
  std::string output;
  ASSERT_EQ(testing::run_command(script() + " " + run.string() + " --per-loop --angle-deg 45", &output), 0)
      << output;
  EXPECT_NE(output.find("verified: 1 loops, 1.00-1.00 m and 0.0-0.0 deg apart; 0 at least 45 deg apart, the "
                        "other 1 1.00-1.00 m apart"),
            std::string::npos)
      << output;
  EXPECT_NE(
      output.find("rejected, tracking fallback tried: 1 loops, 3.00-3.00 m and 90.0-90.0 deg apart; 1 at "
                  "least 45 deg apart"),
      std::string::npos)
      << output;
  EXPECT_NE(output.find("rejected: 1 loops, 0.00-0.00 m and 30.0-30.0 deg apart"), std::string::npos)
      << output;
  EXPECT_EQ(output.find("     3      1"), std::string::npos) << output;  // the skipped loop
}

TEST(E2eLoopEdgesTruth, BadInputNamesTheFile) {
  const fs::path run = make_run("e2e-loop-edges-truth-bad");
  fs::remove(run / "ground_truth.tum");
  std::string output;
  EXPECT_NE(testing::run_command(script() + " " + run.string(), &output), 0);
  EXPECT_NE(output.find("ground_truth.tum"), std::string::npos) << output;
  EXPECT_NE(output.find("only when its dataset has ground truth"), std::string::npos) << output;

  write(run / "ground_truth.tum", "1.0 0 0 0\n");
  EXPECT_NE(testing::run_command(script() + " " + run.string(), &output), 0);
  EXPECT_NE(output.find("ground_truth.tum:1: expected 8 values"), std::string::npos) << output;

  write(run / "ground_truth.tum", "1.000000000 0 0 0 0 0 0 1\n");  // frames 1-3 have no pose
  EXPECT_NE(testing::run_command(script() + " " + run.string(), &output), 0);
  EXPECT_NE(output.find("loop (1, 0): frame 1 has no ground-truth pose"), std::string::npos) << output;
}

}  // namespace
}  // namespace loopgate
