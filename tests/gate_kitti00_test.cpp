// The gate and the candidate areas on the real KITTI 00 geometry (shared data): ground-truth positions with
// a seeded heading drift (a random walk of the yaw about the camera's vertical y axis) and a covariance
// growing with the distance travelled. The loop pairs of loops-gt/botw_pairs.csv (with i - j >= the pair
// margin) must lie inside candidate areas, while the areas hold a small part of the full triangle.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "stages/gate/candidate_areas.hpp"
#include "stages/gate/pose_gate.hpp"
#include "test_support.hpp"

namespace loopgate {
namespace {

std::vector<Eigen::Vector3d> read_kitti_positions(const std::filesystem::path& file) {
  std::ifstream in(file);
  std::vector<Eigen::Vector3d> out;
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream row(line);
    double v[12];
    for (double& x : v) row >> x;
    if (!row) break;
    out.emplace_back(v[3], v[7], v[11]);
  }
  return out;
}

TEST(GateKitti00, TrueLoopsStayInsideCandidateAreas) {
  LOOPGATE_REQUIRE_SHARED_DATA("kitti/00/poses.txt");
  LOOPGATE_REQUIRE_SHARED_DATA("kitti/00/loops-gt/botw_pairs.csv");
  const auto dir = ::loopgate::testing::shared_data_dir() / "kitti/00";
  const std::vector<Eigen::Vector3d> gt = read_kitti_positions(dir / "poses.txt");
  ASSERT_EQ(gt.size(), 4541u);

  // Drifted estimate: increments rotated by a yaw random walk (0.0003 rad / sqrt(m)).
  std::mt19937_64 rng(1);
  std::normal_distribution<double> unit(0.0, 1.0);
  double yaw_rad = 0.0;
  double travelled_m = 0.0;
  GateConfig config;
  config.gap_frames = 30;
  config.beta_m = 5.0;
  config.area_margin_query_frames = 20;
  config.area_margin_reference_frames = 20;
  const int sequence_length = 20;
  const int pair_margin = 200;
  PoseGate gate(config, "kitti/00/poses.txt");
  CandidateAreaTracker tracker(config, sequence_length, pair_margin);
  Eigen::Vector3d p_est = gt[0];
  std::size_t gated = 0;
  std::size_t cells = 0;
  for (std::size_t k = 0; k < gt.size(); ++k) {
    if (k > 0) {
      const Eigen::Vector3d step = gt[k] - gt[k - 1];
      const double len_m = step.norm();
      travelled_m += len_m;
      yaw_rad += 0.0003 * std::sqrt(len_m) * unit(rng);
      p_est += Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitY()) * step;
    }
    const double var_m2 = 0.0025 + 0.002 * travelled_m;
    const GateDecision d =
        gate.process(static_cast<std::int64_t>(k), p_est, Eigen::Matrix3d::Identity() * var_m2);
    gated += d.gated ? 1 : 0;
    const AreaUpdate u = tracker.update(d);
    for (const CellSpan& s : u.new_cells) cells += static_cast<std::size_t>(s.j1 - s.j0 + 1);
  }
  tracker.finish();

  std::ifstream pairs(dir / "loops-gt/botw_pairs.csv");
  std::string line;
  std::size_t loops = 0;
  std::size_t covered = 0;
  while (std::getline(pairs, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::int64_t i = 0, j = 0;
    char comma = 0;
    std::istringstream row(line);
    row >> i >> comma >> j;
    if (!row || i - j < pair_margin) continue;
    ++loops;
    covered += tracker.covers(i, j) ? 1 : 0;
  }
  const double n = static_cast<double>(gt.size());
  const double full_cells = (n - pair_margin) * (n - pair_margin + 1) / 2.0;
  const double coverage = static_cast<double>(covered) / static_cast<double>(loops);
  const double cell_fraction = static_cast<double>(cells) / full_cells;
  const double descriptor_fraction = static_cast<double>(tracker.descriptor_requests().count()) / n;
  std::printf(
      "KITTI 00: gated %zu / %zu frames, %zu areas, loop pairs covered %zu / %zu (%.4f), cells %.4f of "
      "the full triangle, descriptors %.4f of the frames\n",
      gated, gt.size(), tracker.areas().size(), covered, loops, coverage, cell_fraction, descriptor_fraction);
  EXPECT_GT(loops, 1000u);
  EXPECT_GE(coverage, 0.95);
  EXPECT_LT(cell_fraction, 0.15);
  EXPECT_GT(tracker.areas().size(), 2u);
}

}  // namespace
}  // namespace loopgate
