// End-to-end tests of scripts/plot.py: a synthetic run directory and compare directory (the files
// `loopgate run` / `compare` write) are plotted; the PNGs must exist and be real pictures, missing
// optional inputs are skipped, and bad input exits 2 naming the file and line.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <numbers>
#include <sstream>
#include <string>
#include <vector>

#include "test_support.hpp"

namespace loopgate {
namespace {

namespace fs = std::filesystem;

constexpr int kFrames = 300;
constexpr int kLap = 200;  // frames per lap: frames kLap.. revisit frames 0..
constexpr double kRadiusM = 20.0;

const char* const kPython = "/usr/bin/python3";

fs::path plot_script() {
  return fs::path(LOOPGATE_SOURCE_DIR) / "scripts" / "plot.py";
}

bool have_matplotlib() {
  return testing::run_command(std::string(kPython) + " -c \"import matplotlib\"") == 0;
}

struct Result {
  int status = -1;
  std::string output;  // stdout + stderr
};

Result plot(const std::string& what, const fs::path& dir, const fs::path& out) {
  Result r;
  r.status = testing::run_command(std::string(kPython) + " " + plot_script().string() + " " + what + " " +
                                      dir.string() + " --out " + out.string(),
                                  &r.output);
  return r;
}

// Ground-truth position of frame k: a circle driven 1.5 times.
void gt_position(int k, double* x, double* y) {
  const double angle = 2.0 * std::numbers::pi * k / kLap;
  *x = kRadiusM * std::cos(angle);
  *y = kRadiusM * std::sin(angle);
}

std::string pr_json(double ap, double r100) {
  std::ostringstream s;
  s << R"({"curve": [{"threshold": 0.9, "precision": 1.0, "recall": )" << r100
    << R"(}, {"threshold": 0.5, "precision": 0.8, "recall": 0.7}, {"threshold": 0.1, "precision": 0.5, "recall": 0.9}],
     "average_precision": )"
    << ap << R"(, "recall_at_100": )" << r100
    << R"(, "recall_at_99": 0.3, "recall_at_95": 0.4, "positives": 100})";
  return s.str();
}

// A run directory as `loopgate run` writes it; `full` makes the matcher compare every earlier frame.
void write_run(const fs::path& dir, const std::string& mode, const std::string& method) {
  fs::create_directories(dir);
  std::ofstream frames(dir / "frames.csv");
  frames << "seq,frame,t_ns,t_s,x_m,y_m,z_m,qx,qy,qz,qw,sigma_m,odom_status,status,reason,nearest_frame,"
            "gate_d_m,gate_threshold_m,gated,area_id,descriptor,detection,match_frame,match_score,"
            "detection_reason\n";
  std::ofstream tum(dir / "ground_truth.tum");
  std::ofstream timing(dir / "timing.csv");
  timing
      << "seq,frame,sync_ms,decode_ms,odometry_ms,gate_ms,describe_ms,match_ms,sink_ms,latency_ms,total_ms\n";
  for (int k = 0; k < kFrames; ++k) {
    double x = 0.0, y = 0.0;
    gt_position(k, &x, &y);
    const double t_s = 0.1 * k;
    const bool gated = k >= kLap - 5;
    const bool revisit = k >= kLap;
    char line[512];
    std::snprintf(line, sizeof(line), "%d,%d,%lld,%.9f,%.6f,%.6f,%.6f,0,0,0,1,%.4f,tracking,ok,,", k, k,
                  static_cast<long long>(k) * 100000000LL, t_s, x + 0.004 * k, y - 0.002 * k, 1.5, 0.01 * k);
    frames << line;
    if (revisit) {
      frames << (k - kLap) << ",1.2,3.0,y,0,y,loop," << (k - kLap) << ",0.8,\"ok, above tau\"\n";
    } else if (gated) {
      frames << ",,3.0,y,0,y,no candidate,,,\"no reference yet, waiting\"\n";  // empty cells
    } else {
      frames << k / 2 << ",40.0,3.0,n,-1," << (mode == "full" ? "y" : "n") << ",no candidate,,,\n";
    }
    std::snprintf(line, sizeof(line), "%.9f %.6f %.6f 1.5 0 0 0 1\n", t_s, x, y);
    tum << line;
    const double describe_ms = (mode == "full" || gated) ? 0.4 : 0.0;
    const double match_ms = mode == "full" ? 0.002 * k : (revisit ? 0.05 : 0.0);
    std::snprintf(line, sizeof(line), "0,%d,0.01,1.1,0.02,0.01,%.4f,%.4f,0.01,%.4f,%.4f\n", k, describe_ms,
                  match_ms, 2.0 + describe_ms + match_ms, 1.15 + describe_ms + match_ms);
    timing << line;
  }
  std::ofstream loops(dir / "loops.csv");
  loops << "i,j,t_i,t_j,score\n";
  for (int i = kLap + 10; i < kFrames; i += 3) {
    const int j = (i % 4 == 0) ? i - 150 : i - kLap;  // every 4th a false loop (half a lap away)
    loops << i << "," << j << "," << 0.1 * i << "," << 0.1 * j << "," << (i % 4 == 0 ? 0.3 : 0.8) << "\n";
  }
  std::ofstream truth(dir / "truth_loops.csv");
  truth << "i,j\n";
  for (int i = kLap; i < kFrames; ++i) truth << i << "," << i - kLap << "\n";
  std::ofstream areas(dir / "candidate_areas.csv");
  areas << "id,row_begin,row_end,col_begin,col_end,i_first,i_last,j_min,j_max,gated_frames\n"
        << "0,175,299,0,119,195,299,0,99,105\n";
  std::ofstream descriptor(dir / "descriptor.csv");
  descriptor << "frame";
  for (int v = 0; v < 3456; ++v) descriptor << ",v" << v;
  descriptor << "\n5";
  for (int v = 0; v < 3456; ++v) descriptor << "," << (v * 37 + (v / 64) * 11) % 256;
  descriptor << "\n";
  std::ofstream(dir / "summary.json")
      << R"({"mode": ")" << mode << R"(", "method": ")" << method << R"(", "score_order": "higher_is_better",
      "config": {"eval": {"accept_radius_m": 2.0}}, "precision_recall": )"
      << pr_json(0.7, 0.25) << "}\n";
}

// A real picture: PNG signature, an IHDR of plausible size, and more bytes than a blank canvas takes.
void expect_png(const fs::path& file) {
  ASSERT_TRUE(fs::is_regular_file(file)) << file;
  const std::string bytes = testing::read_file(file);
  ASSERT_GT(bytes.size(), 24u) << file;
  EXPECT_EQ(bytes.substr(0, 8), std::string("\x89PNG\r\n\x1a\n", 8)) << file;
  EXPECT_EQ(bytes.substr(12, 4), "IHDR") << file;
  const auto be32 = [&](std::size_t at) {
    std::uint32_t v = 0;
    for (std::size_t k = 0; k < 4; ++k) v = (v << 8) | static_cast<unsigned char>(bytes[at + k]);
    return v;
  };
  EXPECT_GE(be32(16), 400u) << file << ": width";
  EXPECT_GE(be32(20), 400u) << file << ": height";
  EXPECT_GT(bytes.size(), 10000u) << file << ": too small to be a real plot";
}

class E2ePlot : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!have_matplotlib()) GTEST_SKIP() << kPython << " has no matplotlib";
    ASSERT_TRUE(fs::is_regular_file(plot_script())) << plot_script();
  }
};

TEST_F(E2ePlot, RunWritesEveryPicture) {
  const fs::path run = testing::make_temp_dir("plot-run");
  write_run(run, "gated", "dird");
  const fs::path out = run / "pictures";
  const Result r = plot("run", run, out);
  ASSERT_EQ(r.status, 0) << r.output;
  for (const char* name : {"trajectory.png", "plane.png", "timing.png", "pr.png", "descriptor.png"}) {
    EXPECT_NE(r.output.find((out / name).string() + "\n"), std::string::npos) << name << "\n" << r.output;
    expect_png(out / name);
  }
}

TEST_F(E2ePlot, RunDefaultsToPlotsFolderAndSkipsMissingOptionalInputs) {
  const fs::path run = testing::make_temp_dir("plot-run-minimal");
  write_run(run, "full", "dird");
  for (const char* name :
       {"ground_truth.tum", "truth_loops.csv", "candidate_areas.csv", "loops.csv", "descriptor.csv"})
    fs::remove(run / name);
  std::string output;
  const int status = testing::run_command(
      std::string(kPython) + " " + plot_script().string() + " run " + run.string(), &output);
  ASSERT_EQ(status, 0) << output;
  for (const char* name : {"trajectory.png", "plane.png", "timing.png"}) expect_png(run / "plots" / name);
  EXPECT_FALSE(fs::exists(run / "plots" / "descriptor.png"));
  EXPECT_NE(output.find("descriptor.csv"), std::string::npos) << output;  // the note says what is skipped
}

TEST_F(E2ePlot, CompareWritesPrTimePlaneAndTrajectory) {
  const fs::path dir = testing::make_temp_dir("plot-compare");
  write_run(dir / "full", "full", "dird");
  write_run(dir / "gated", "gated", "dird");
  write_run(dir / "seqslam", "full", "seqslam");
  std::ofstream(dir / "compare.json")
      << R"({"full": {"mode": "full", "precision_recall": )" << pr_json(0.6, 0.2)
      << R"(}, "gated": {"mode": "gated", "precision_recall": )" << pr_json(0.8, 0.4)
      << R"(}, "seqslam": {"mode": "full", "precision_recall": )" << pr_json(0.5, 0.1) << "}}\n";
  const Result r = plot("compare", dir, dir / "plots");
  ASSERT_EQ(r.status, 0) << r.output;
  for (const char* name : {"pr.png", "time_per_frame.png", "plane.png", "trajectory.png"}) {
    EXPECT_NE(r.output.find((dir / "plots" / name).string() + "\n"), std::string::npos) << name << r.output;
    expect_png(dir / "plots" / name);
  }
}

// Without a gated DIRD run, trajectory.png and plane.png show the recommended method; a method without
// detections stays in the PR legend, and a range without a true loop gives AP n/a, not 0.
TEST_F(E2ePlot, CompareDrawsRecommendedMethodAndListsEveryMethod) {
  const fs::path dir = testing::make_temp_dir("plot-compare-recommended");
  write_run(dir / "full", "full", "dird");
  write_run(dir / "dird-seqslam-gated", "gated", "dird-seqslam");
  std::ofstream(dir / "compare.json")
      << R"({"full": {"mode": "full", "precision_recall": )" << pr_json(0.6, 0.2)
      << R"(}, "dird-seqslam-gated": {"mode": "gated", "precision_recall": )" << pr_json(0.9, 0.8)
      << R"(}, "seqslam": {"mode": "full", "precision_recall": {"average_precision": 0, "recall_at_100": 0,)"
      << R"( "positives": 0}}, "recommended": "dird-seqslam-gated"})"
      << "\n";
  const Result r = plot("compare", dir, dir / "plots");
  ASSERT_EQ(r.status, 0) << r.output;
  for (const char* name : {"pr.png", "plane.png", "trajectory.png"}) expect_png(dir / "plots" / name);
  EXPECT_NE(r.output.find("plane.png, trajectory.png: dird-seqslam-gated (recommended)"), std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("pr.png: SeqSLAM: no detection (AP n/a)"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("pr.png: gated DIRD-SeqSLAM (AP 0.900, R@P100 0.800)"), std::string::npos)
      << r.output;
  EXPECT_EQ(r.output.find("0.000"), std::string::npos) << r.output;
}

TEST_F(E2ePlot, MissingFileExits2NamingIt) {
  const fs::path run = testing::make_temp_dir("plot-missing");
  write_run(run, "gated", "dird");
  fs::remove(run / "frames.csv");
  const Result r = plot("run", run, run / "plots");
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_NE(r.output.find((run / "frames.csv").string() + ": file not found"), std::string::npos) << r.output;

  const fs::path compare = testing::make_temp_dir("plot-missing-compare");
  const Result c = plot("compare", compare, compare / "plots");
  EXPECT_EQ(c.status, 2) << c.output;
  EXPECT_NE(c.output.find("compare.json: file not found"), std::string::npos) << c.output;
}

// Replaces line `line_no` (1-based) of `file` with `text`.
void replace_line(const fs::path& file, int line_no, const std::string& text) {
  std::istringstream in(testing::read_file(file));
  std::string content, line;
  for (int n = 1; std::getline(in, line); ++n) content += (n == line_no ? text : line) + "\n";
  std::ofstream(file) << content;
}

TEST_F(E2ePlot, MalformedLinesExit2NamingFileAndLine) {
  struct Case {
    const char* file;
    int line;
    const char* text;
    const char* expected;  // after "<file>:<line>: "
  };
  const std::vector<Case> cases = {
      {"frames.csv", 5, "3,3,300000000,0.3,1.0", "expected 25 fields"},
      {"frames.csv", 7,
       "5,5,500000000,0.5,abc,0,1.5,0,0,0,1,0.05,tracking,ok,,2,40.0,3.0,n,-1,n,no candidate,,,",
       "column 'x_m': expected a number, got 'abc'"},
      {"loops.csv", 3, "213,x7,21.3,1.3,0.8", "column 'j': expected an integer, got 'x7'"},
      {"truth_loops.csv", 4, "202,-2", "column 'j': expected a frame index >= 0"},
      {"ground_truth.tum", 6, "0.5 1 2", "expected 8 numbers"},
      {"descriptor.csv", 2, "5,1,2,3", "expected 3457 fields"},
      {"summary.json", 2, "  \"mode\" \"gated\",", "invalid JSON"},
  };
  for (const Case& c : cases) {
    const fs::path run = testing::make_temp_dir("plot-bad");
    write_run(run, "gated", "dird");
    replace_line(run / c.file, c.line, c.text);
    const Result r = plot("run", run, run / "plots");
    EXPECT_EQ(r.status, 2) << c.file << "\n" << r.output;
    const std::string expected = (run / c.file).string() + ":" + std::to_string(c.line) + ": ";
    EXPECT_NE(r.output.find(expected), std::string::npos) << expected << "\n" << r.output;
    EXPECT_NE(r.output.find(c.expected), std::string::npos) << c.expected << "\n" << r.output;
  }
}

// `loopgate aggregate`'s table (aggregate.csv): the AP and time figure; an empty cell (no ground truth) is
// drawn as "n/a", a missing column or a bad number is exit 2 naming file and line.
TEST_F(E2ePlot, AggregateDrawsApAndTimePerRunAndMethod) {
  const fs::path dir = testing::make_temp_dir("plot-aggregate");
  const std::string header =
      "run,method,average_precision,wall_s,describe_match_ms,describe_match_decode_ms\n";
  std::ofstream(dir / "aggregate.csv") << header << "demo,full,0.1,2.0,900,1200\n"
                                       << "demo,gated,0.95,0.8,300,310\n"
                                       << "aliasing,gated,,0.5,100,110\n";
  const Result r = plot("aggregate", dir, dir);
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find((dir / "aggregate.png").string() + "\n"), std::string::npos) << r.output;
  expect_png(dir / "aggregate.png");

  std::ofstream(dir / "aggregate.csv") << "run,method,wall_s\ndemo,full,2.0\n";
  Result bad = plot("aggregate", dir, dir);
  EXPECT_EQ(bad.status, 2) << bad.output;
  EXPECT_NE(bad.output.find((dir / "aggregate.csv").string() + ":1: missing column(s) average_precision"),
            std::string::npos)
      << bad.output;
  std::ofstream(dir / "aggregate.csv")
      << header << "demo,full,0.1,2.0,900,1200\ndemo,gated,high,0.8,300,310\n";
  bad = plot("aggregate", dir, dir);
  EXPECT_EQ(bad.status, 2) << bad.output;
  EXPECT_NE(bad.output.find((dir / "aggregate.csv").string() +
                            ":3: column 'average_precision': expected a number, got 'high'"),
            std::string::npos)
      << bad.output;
}

}  // namespace
}  // namespace loopgate
