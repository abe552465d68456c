// Trajectory files in every format odometry.file takes (io/trajectory_file.hpp): TUM, KITTI with 12 columns
// (timed by the dataset's frames) or 13 (a time first), EuRoC csv; the format told from the first data line,
// or given; and the errors, naming the file and line.
#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>

#include "core/error.hpp"
#include "io/trajectory_file.hpp"
#include "io/trajectory_io.hpp"
#include "test_support.hpp"

namespace loopgate {
namespace {

namespace fs = std::filesystem;

constexpr Timestamp kT0 = 1'403'636'580'013'555'456;
constexpr Timestamp kPeriod = 100'000'000;
constexpr int kPoses = 6;

fs::path write_file(const fs::path& file, const std::string& text) {
  fs::create_directories(file.parent_path());
  std::ofstream(file, std::ios::binary) << text;
  return file;
}

Eigen::Isometry3d pose(int i) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::AngleAxisd(0.1 * i, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(1.0 * i, -0.5 * i, 2.0);
  return T;
}

std::vector<StampedPose> poses() {
  std::vector<StampedPose> out;
  for (int i = 0; i < kPoses; ++i) out.push_back(StampedPose{kT0 + i * kPeriod, pose(i)});
  return out;
}

// One file per format holding poses(), in `dir`.
struct Files {
  fs::path tum, kitti12, kitti13, euroc;
};

Files write_formats(const fs::path& dir) {
  Files f{dir / "traj.tum", dir / "poses12.txt", dir / "poses13.txt", dir / "data.csv"};
  write_tum(f.tum, poses());
  std::vector<Eigen::Isometry3d> matrices;
  for (const StampedPose& p : poses()) matrices.push_back(p.T_w_b);
  write_kitti_poses(f.kitti12, matrices);
  std::string text = "# timestamp, then the row-major 3x4 pose\n";
  for (const StampedPose& p : poses()) {
    char time[40];
    std::snprintf(time, sizeof(time), "%lld.%09lld", static_cast<long long>(p.t_ns / 1'000'000'000),
                  static_cast<long long>(p.t_ns % 1'000'000'000));
    text += time;
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 4; ++c) text += " " + std::to_string(p.T_w_b.matrix()(r, c));
    }
    text += "\n";
  }
  write_file(f.kitti13, text);
  std::vector<GroundTruthState> states;
  for (const StampedPose& p : poses()) {
    GroundTruthState s;
    s.t_ns = p.t_ns;
    s.T_w_b = p.T_w_b;
    states.push_back(s);
  }
  write_euroc_groundtruth(f.euroc, states);
  return f;
}

std::vector<std::optional<Timestamp>> frame_times(int n) {
  std::vector<std::optional<Timestamp>> times;
  for (int i = 0; i < n; ++i) times.push_back(kT0 + i * kPeriod);
  return times;
}

using testing::catch_data_error;

TEST(IoTrajectoryFile, EveryFormatDetectedAndReadAlike) {
  const Files f = write_formats(testing::make_temp_dir("trajectory-file"));
  EXPECT_EQ(detect_trajectory_format(f.tum), TrajectoryFormat::kTum);
  EXPECT_EQ(detect_trajectory_format(f.kitti12), TrajectoryFormat::kKitti);
  EXPECT_EQ(detect_trajectory_format(f.kitti13), TrajectoryFormat::kKitti);
  EXPECT_EQ(detect_trajectory_format(f.euroc), TrajectoryFormat::kEuroc);
  const auto times = frame_times(kPoses);
  for (const fs::path& file : {f.tum, f.kitti12, f.kitti13, f.euroc}) {
    for (const TrajectoryFormat format : {TrajectoryFormat::kAuto, detect_trajectory_format(file)}) {
      const TrajectoryFile read = read_trajectory_file(file, format, times);
      EXPECT_EQ(read.format, detect_trajectory_format(file)) << file;
      ASSERT_EQ(read.poses.size(), static_cast<std::size_t>(kPoses)) << file;
      for (int i = 0; i < kPoses; ++i) {
        EXPECT_EQ(read.poses[i].t_ns, kT0 + i * kPeriod) << file << " " << i;
        EXPECT_TRUE(read.poses[i].T_w_b.matrix().isApprox(pose(i).matrix(), 1e-5)) << file << " " << i;
      }
      EXPECT_EQ(read.description.find("(detected)") != std::string::npos, format == TrajectoryFormat::kAuto);
    }
  }
  EXPECT_EQ(read_trajectory_file(f.kitti12, TrajectoryFormat::kAuto, times).description,
            "kitti, 12 columns timed by the dataset's frame times (detected)");
}

// A 12-column file is one pose per frame of the sequence: line k takes frame k's time; a frame without a time
// (a row of times.txt rejected in lenient mode) drops its pose; more lines than frames is an error.
TEST(IoTrajectoryFile, TwelveColumnsAreTimedByTheDatasetFrames) {
  const Files f = write_formats(testing::make_temp_dir("trajectory-file-kitti"));
  auto times = frame_times(kPoses + 4);  // a trajectory that ends before the sequence does
  times[2].reset();
  const TrajectoryFile read = read_trajectory_file(f.kitti12, TrajectoryFormat::kKitti, times);
  ASSERT_EQ(read.poses.size(), static_cast<std::size_t>(kPoses - 1));
  EXPECT_EQ(read.poses[2].t_ns, kT0 + 3 * kPeriod);
  EXPECT_NE(read.description.find("1 lines of frames without a time skipped"), std::string::npos);

  const DataError e = catch_data_error(
      [&] { read_trajectory_file(f.kitti12, TrajectoryFormat::kAuto, frame_times(kPoses - 2)); });
  EXPECT_EQ(e.file(), f.kitti12);
  EXPECT_NE(e.message().find("6 poses of 12 columns (no times): one per frame of the sequence, timed by the "
                             "dataset, and it has 4 frame times"),
            std::string::npos)
      << e.what();
  // 13 columns need no frame times at all.
  EXPECT_EQ(read_trajectory_file(f.kitti13, TrajectoryFormat::kAuto, {}).poses.size(),
            static_cast<std::size_t>(kPoses));
}

TEST(IoTrajectoryFile, ErrorsNameFileAndLine) {
  const fs::path dir = testing::make_temp_dir("trajectory-file-bad");
  const fs::path five = write_file(dir / "five.txt", "# header\n\n1.0 2 3 4 5\n");
  const DataError e1 = catch_data_error([&] { detect_trajectory_format(five); });
  EXPECT_EQ(e1.file(), five);
  EXPECT_EQ(e1.line(), 3u);
  EXPECT_NE(e1.message().find("cannot tell the trajectory format from 5 fields: expected 8 (TUM"),
            std::string::npos)
      << e1.what();
  EXPECT_NE(e1.message().find("or set odometry.file_format"), std::string::npos);

  const fs::path empty = write_file(dir / "empty.txt", "# nothing\n");
  EXPECT_NE(catch_data_error([&] { read_trajectory_file(empty, TrajectoryFormat::kAuto, {}); })
                .message()
                .find("no poses"),
            std::string::npos);

  // An explicit format that does not fit the file: that reader's error, with the line.
  const Files f = write_formats(dir);
  const DataError e2 =
      catch_data_error([&] { read_trajectory_file(f.kitti12, TrajectoryFormat::kTum, frame_times(kPoses)); });
  EXPECT_EQ(e2.line(), 1u);
  EXPECT_NE(e2.message().find("expected 8 columns"), std::string::npos) << e2.what();

  // A 14-column row in a KITTI file.
  std::string text = "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1 0 5 6\n";
  const fs::path fourteen = write_file(dir / "fourteen.txt", text);
  const DataError e3 =
      catch_data_error([&] { read_trajectory_file(fourteen, TrajectoryFormat::kAuto, frame_times(kPoses)); });
  EXPECT_EQ(e3.file(), fourteen);
  EXPECT_EQ(e3.line(), 2u);
  EXPECT_NE(e3.message().find("expected 12 columns like the first data row (no time), got 14"),
            std::string::npos)
      << e3.what();
}

}  // namespace
}  // namespace loopgate
