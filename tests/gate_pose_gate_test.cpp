// The KD-tree search of PoseGate equals a brute-force scan over all j <= i - gap travelled from by at least
// min_travel_m, on random trajectories with random (also degenerate, huge and zero) covariances, duplicate
// positions, both sigma norms, several gaps and travels; delayed insertion; standing still; bad input.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdint>
#include <ostream>
#include <random>
#include <string>
#include <vector>

#include "core/error.hpp"
#include "stages/gate/combined_distance.hpp"
#include "stages/gate/pose_gate.hpp"

namespace loopgate {
namespace {

struct Sample {
  std::int64_t frame = 0;
  Eigen::Vector3d p_m;
  Eigen::Matrix3d P_m2;
};

enum class CovKind { kRealistic, kWild };

Eigen::Matrix3d random_covariance(std::mt19937_64& rng, CovKind kind, double growth_m2) {
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::normal_distribution<double> gauss(0.0, 1.0);
  const Eigen::Quaterniond q =
      Eigen::Quaterniond(gauss(rng), gauss(rng), gauss(rng), gauss(rng)).normalized();
  Eigen::Vector3d s;
  if (kind == CovKind::kRealistic) {
    for (int a = 0; a < 3; ++a) s(a) = growth_m2 * (0.2 + unit(rng));
  } else {
    const double u = unit(rng);
    for (int a = 0; a < 3; ++a) s(a) = std::pow(10.0, -6.0 + 8.0 * unit(rng));
    if (u < 0.1)
      s.setZero();  // exactly zero
    else if (u < 0.2)
      s(0) = s(1) = 0.0;  // rank 1
    else if (u < 0.3)
      s(2) = 1e8 * (1.0 + unit(rng));  // huge along one axis
    else if (u < 0.35)
      s.setConstant(1e6);  // huge everywhere
  }
  const Eigen::Matrix3d R = q.toRotationMatrix();
  Eigen::Matrix3d P = R * s.asDiagonal() * R.transpose();
  P = (0.5 * (P + P.transpose())).eval();  // exactly symmetric
  return P;
}

// Random walk with revisits (jumps back to an earlier position) and exact duplicates.
std::vector<Sample> make_samples(std::uint64_t seed, int n, CovKind kind, bool skip_frames) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> step(0.0, 1.0);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::vector<Sample> out;
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
  std::int64_t frame = 0;
  for (int k = 0; k < n; ++k) {
    const double u = unit(rng);
    if (k > 10 && u < 0.05) {
      p = out[static_cast<std::size_t>(rng() % out.size())].p_m;  // exact duplicate position
    } else if (k > 10 && u < 0.10) {
      p = out[static_cast<std::size_t>(rng() % out.size())].p_m +
          Eigen::Vector3d(step(rng), step(rng), 0.1 * step(rng));
    } else {
      p += Eigen::Vector3d(2.0 * step(rng), 2.0 * step(rng), 0.2 * step(rng));
    }
    Sample s;
    s.frame = frame;
    s.p_m = p;
    s.P_m2 = random_covariance(rng, kind, 0.01 * static_cast<double>(k));
    out.push_back(s);
    frame += skip_frames ? 1 + static_cast<std::int64_t>(rng() % 3) : 1;
  }
  return out;
}

// Reference: scan j in increasing order, strict improvement (ties keep the smallest j).
void expect_matches_brute_force(const GateConfig& config, const std::vector<Sample>& samples) {
  PoseGate gate(config);
  std::size_t gated = 0;
  std::vector<double> travel_m(samples.size(), 0.0);  // path length from the first sample
  for (std::size_t k = 1; k < samples.size(); ++k)
    travel_m[k] = travel_m[k - 1] + (samples[k].p_m - samples[k - 1].p_m).norm();
  for (std::size_t k = 0; k < samples.size(); ++k) {
    const Sample& s = samples[k];
    const GateDecision got = gate.process(s.frame, s.p_m, s.P_m2);
    bool has = false;
    std::int64_t best_j = -1;
    double best_d = 0.0;
    for (std::size_t m = 0; m < k; ++m) {
      if (samples[m].frame > s.frame - config.gap_frames) break;
      if (travel_m[m] > travel_m[k] - config.revisit.min_travel_m) break;
      const double d = combined_distance(s.p_m, s.P_m2, samples[m].p_m, samples[m].P_m2);
      if (!has || d < best_d) {
        has = true;
        best_d = d;
        best_j = samples[m].frame;
      }
    }
    const double sigma = position_sigma_m(s.P_m2, config.sigma_norm);
    const double threshold = config.confidence_scale * sigma + config.beta_m;
    ASSERT_EQ(got.frame, s.frame);
    ASSERT_EQ(got.has_nearest, has) << "frame " << s.frame;
    ASSERT_EQ(got.nearest_frame, best_j) << "frame " << s.frame;
    if (has) {
      ASSERT_EQ(got.distance_m, best_d) << "frame " << s.frame;
    }
    ASSERT_EQ(got.sigma_m, sigma);
    ASSERT_EQ(got.threshold_m, threshold);
    ASSERT_EQ(got.gated, has && best_d < threshold);
    gated += got.gated ? 1 : 0;
  }
  EXPECT_GT(gated, 0u);  // the data exercises both decisions
  EXPECT_LT(gated, samples.size());
}

struct BruteForceCase {
  SigmaNorm sigma_norm;
  int gap;
  CovKind kind;
  bool skip_frames;
  int seed_neighbours;
  double min_travel_m = 2.0;
};

void PrintTo(const BruteForceCase& c, std::ostream* os) {
  *os << enum_name(c.sigma_norm) << "/gap" << c.gap << (c.kind == CovKind::kWild ? "/wild" : "/realistic")
      << (c.skip_frames ? "/skips" : "") << "/seeds" << c.seed_neighbours << "/travel"
      << static_cast<int>(c.min_travel_m);
}

class PoseGateBruteForce : public ::testing::TestWithParam<BruteForceCase> {};

TEST_P(PoseGateBruteForce, KdTreeSearchEqualsBruteForce) {
  const BruteForceCase& c = GetParam();
  GateConfig config;
  config.sigma_norm = c.sigma_norm;
  config.gap_frames = c.gap;
  config.beta_m = 2.0;
  config.kdtree_seed_neighbours = c.seed_neighbours;
  config.kdtree_leaf_size = 4;
  config.revisit.min_travel_m = c.min_travel_m;
  const auto samples =
      make_samples(1000 + static_cast<std::uint64_t>(c.gap) * 7 + (c.kind == CovKind::kWild ? 1 : 0), 2000,
                   c.kind, c.skip_frames);
  expect_matches_brute_force(config, samples);
}

INSTANTIATE_TEST_SUITE_P(
    Cases, PoseGateBruteForce,
    ::testing::Values(BruteForceCase{SigmaNorm::kMaxEigen, 30, CovKind::kRealistic, false, 4},
                      BruteForceCase{SigmaNorm::kTrace, 30, CovKind::kRealistic, false, 1},
                      BruteForceCase{SigmaNorm::kMaxEigen, 1, CovKind::kWild, false, 1},
                      BruteForceCase{SigmaNorm::kTrace, 7, CovKind::kWild, true, 3},
                      BruteForceCase{SigmaNorm::kMaxEigen, 200, CovKind::kWild, true, 8},
                      BruteForceCase{SigmaNorm::kTrace, 2, CovKind::kRealistic, true, 2},
                      BruteForceCase{SigmaNorm::kMaxEigen, 30, CovKind::kWild, false, 32},
                      BruteForceCase{SigmaNorm::kTrace, 1, CovKind::kRealistic, true, 4, 0.0},
                      BruteForceCase{SigmaNorm::kMaxEigen, 1, CovKind::kWild, false, 4, 40.0},
                      BruteForceCase{SigmaNorm::kTrace, 30, CovKind::kRealistic, false, 2, 150.0}),
    [](const ::testing::TestParamInfo<BruteForceCase>& param_info) {
      const BruteForceCase& c = param_info.param;
      return std::string(enum_name(c.sigma_norm)) + "_gap" + std::to_string(c.gap) +
             (c.kind == CovKind::kWild ? "_wild" : "_realistic") + (c.skip_frames ? "_skips" : "") +
             "_seeds" + std::to_string(c.seed_neighbours) + "_travel" +
             std::to_string(static_cast<int>(c.min_travel_m));
    });

TEST(PoseGate, AllPositionsEqualTiesGoToSmallestFrame) {
  GateConfig config;
  config.gap_frames = 3;
  config.revisit.min_travel_m = 0.0;  // the paper's gate: the frame gap only
  PoseGate gate(config);
  const Eigen::Vector3d p(1.0, 2.0, 3.0);
  for (std::int64_t i = 0; i < 50; ++i) {
    const GateDecision d = gate.process(i, p, Eigen::Matrix3d::Identity() * 0.5);
    if (i < 3) {
      EXPECT_FALSE(d.has_nearest);
      EXPECT_FALSE(d.gated);
      EXPECT_EQ(d.nearest_frame, -1);
    } else {
      EXPECT_EQ(d.nearest_frame, 0);
      EXPECT_EQ(d.distance_m, 0.0);
      EXPECT_TRUE(d.gated);
    }
  }
}

TEST(PoseGate, DelayedInsertionRespectsGap) {
  GateConfig config;
  config.gap_frames = 5;
  config.beta_m = 0.5;
  PoseGate gate(config);
  // Frames on a line 10 m apart; frame 12 comes back to x = 0 and x = 100 (frame 10) is too recent.
  for (std::int64_t i = 0; i < 12; ++i)
    gate.process(i, Eigen::Vector3d(10.0 * static_cast<double>(i), 0, 0), Eigen::Matrix3d::Zero());
  EXPECT_EQ(gate.frames_in_tree(), 7u);  // frames 0..6 (11 - 5 = 6)
  const GateDecision d = gate.process(12, Eigen::Vector3d(99.0, 0, 0), Eigen::Matrix3d::Zero());
  EXPECT_EQ(gate.frames_in_tree(), 8u);  // frame 7 inserted on arrival of frame 12
  EXPECT_EQ(d.nearest_frame, 7);         // 70 m at x = 70; frames 8..11 are within the gap
  EXPECT_DOUBLE_EQ(d.distance_m, 29.0);
  EXPECT_FALSE(d.gated);
  EXPECT_DOUBLE_EQ(d.threshold_m, 0.5);
}

TEST(PoseGate, GapsInFrameNumbering) {
  GateConfig config;
  config.gap_frames = 10;
  config.revisit.min_travel_m = 0.0;
  PoseGate gate(config);
  gate.process(0, Eigen::Vector3d::Zero(), Eigen::Matrix3d::Zero());
  gate.process(5, Eigen::Vector3d(1, 0, 0), Eigen::Matrix3d::Zero());
  EXPECT_FALSE(gate.process(9, Eigen::Vector3d(1, 0, 0), Eigen::Matrix3d::Zero()).has_nearest);
  const GateDecision d = gate.process(15, Eigen::Vector3d(1, 0, 0), Eigen::Matrix3d::Zero());
  EXPECT_EQ(d.nearest_frame, 5);  // 0 and 5 are <= 15 - 10; 9 is not
  EXPECT_EQ(d.distance_m, 0.0);
  EXPECT_EQ(gate.frames_in_tree(), 2u);
}

TEST(PoseGate, UsesPoseEstimatePositionAndCovariance) {
  GateConfig config;
  config.gap_frames = 1;
  config.beta_m = 0.0;
  PoseGate gate(config);
  PoseEstimate a;
  a.T_w_b.translation() = Eigen::Vector3d(0, 0, 0);
  a.cov.topLeftCorner<3, 3>() = Eigen::Matrix3d::Identity();
  PoseEstimate b = a;
  b.T_w_b.translation() = Eigen::Vector3d(3, 0, 0);
  b.cov.topLeftCorner<3, 3>() = 2.0 * Eigen::Matrix3d::Identity();
  b.cov.bottomRightCorner<3, 3>() = 1e6 * Eigen::Matrix3d::Identity();  // rotation part is ignored
  gate.process(0, a);
  const GateDecision d = gate.process(1, b);
  EXPECT_DOUBLE_EQ(d.distance_m, 3.0 / 2.0);  // A = (1 + 1 + 2) I
  EXPECT_DOUBLE_EQ(d.sigma_m, std::sqrt(2.0));
  EXPECT_DOUBLE_EQ(d.threshold_m, 1.96 * std::sqrt(2.0));
  EXPECT_TRUE(d.gated);  // 1.5 < 2.77
}

TEST(PoseGate, RunningMaxEigenvalueOfTree) {
  GateConfig config;
  config.gap_frames = 2;
  config.revisit.min_travel_m = 0.0;
  PoseGate gate(config);
  gate.process(0, Eigen::Vector3d::Zero(), Eigen::Vector3d(1, 4, 2).asDiagonal().toDenseMatrix());
  gate.process(1, Eigen::Vector3d::Zero(), Eigen::Matrix3d::Identity() * 9);
  EXPECT_EQ(gate.max_tree_eigenvalue_m2(), 0.0);
  gate.process(2, Eigen::Vector3d::Zero(), Eigen::Matrix3d::Zero());
  EXPECT_NEAR(gate.max_tree_eigenvalue_m2(), 4.0, 1e-12);
  gate.process(3, Eigen::Vector3d::Zero(), Eigen::Matrix3d::Zero());
  EXPECT_NEAR(gate.max_tree_eigenvalue_m2(), 9.0, 1e-12);
}

// Standing still (or hovering), the camera sees the place it has not left: no past frame is a candidate until
// the odometry has travelled min_travel_m from it, however many frames pass.
TEST(PoseGate, StandingStillGivesNoCandidateUntilTheOdometryTravelled) {
  GateConfig config;
  config.gap_frames = 3;
  config.revisit.min_travel_m = 2.0;
  PoseGate gate(config);
  std::int64_t frame = 0;
  // 100 frames at the origin with 1 mm of jitter: 2 mm of path per frame at most, 0.2 m in all.
  for (; frame < 100; ++frame) {
    const double jitter = (frame % 2 == 0 ? 1e-3 : -1e-3);
    const GateDecision d = gate.process(frame, Eigen::Vector3d(jitter, 0, 0), Eigen::Matrix3d::Zero());
    EXPECT_FALSE(d.has_nearest) << "frame " << frame;
  }
  EXPECT_EQ(gate.frames_in_tree(), 0u);
  // Drive away along x at 0.6 m per frame (path 0.199 m at frame 100, then 0.799, 1.399, ...): nothing
  // enters before frame 104, 2.6 m of path from the stationary frames, which then enter all at once.
  for (; frame < 104; ++frame) {
    gate.process(frame, Eigen::Vector3d(0.6 * static_cast<double>(frame - 100), 0, 0),
                 Eigen::Matrix3d::Zero());
    EXPECT_EQ(gate.frames_in_tree(), 0u) << "frame " << frame;
  }
  gate.process(frame++, Eigen::Vector3d(2.4, 0, 0), Eigen::Matrix3d::Zero());
  EXPECT_EQ(gate.frames_in_tree(), 101u);  // frames 0..100
  for (; frame < 110; ++frame)
    gate.process(frame, Eigen::Vector3d(0.6 * static_cast<double>(frame - 100), 0, 0),
                 Eigen::Matrix3d::Zero());
  EXPECT_EQ(gate.frames_in_tree(), 106u);  // then one per frame: 101..105 (frame 109 at 5.599 m of path)
  // Back at the origin: the nearest past frame is one of the stationary ones (or frame 100, at x = 0).
  const GateDecision back = gate.process(frame, Eigen::Vector3d::Zero(), Eigen::Matrix3d::Zero());
  EXPECT_TRUE(back.gated);
  EXPECT_LE(back.nearest_frame, 100);
  // With min_travel_m 0 the gate searches every frame older than the gap, stationary ones too.
  config.revisit.min_travel_m = 0.0;
  PoseGate paper(config);
  for (std::int64_t f = 0; f < 10; ++f) paper.process(f, Eigen::Vector3d::Zero(), Eigen::Matrix3d::Zero());
  EXPECT_EQ(paper.frames_in_tree(), 10u - 3u);
}

TEST(PoseGate, BadInputIsDataError) {
  GateConfig config;
  PoseGate gate(config, "vio.csv");
  gate.process(3, Eigen::Vector3d::Zero(), Eigen::Matrix3d::Zero());
  EXPECT_THROW(gate.process(3, Eigen::Vector3d::Zero(), Eigen::Matrix3d::Zero()), DataError);
  EXPECT_THROW(gate.process(4, Eigen::Vector3d(NAN, 0, 0), Eigen::Matrix3d::Zero()), DataError);
  Eigen::Matrix3d inf_cov = Eigen::Matrix3d::Zero();
  inf_cov(1, 1) = INFINITY;
  EXPECT_THROW(gate.process(5, Eigen::Vector3d::Zero(), inf_cov), DataError);
  try {
    gate.process(6, Eigen::Vector3d::Zero(), -Eigen::Matrix3d::Identity());
    FAIL() << "expected DataError";
  } catch (const DataError& e) {
    EXPECT_EQ(e.file().string(), "vio.csv");
    EXPECT_NE(std::string(e.what()).find("frame 6"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("positive semi-definite"), std::string::npos) << e.what();
  }
  // Rejected frames are not stored: the gate continues.
  EXPECT_EQ(gate.frames_seen(), 1u);
  EXPECT_NO_THROW(gate.process(7, Eigen::Vector3d::Zero(), Eigen::Matrix3d::Identity() * -1e-12));
}

TEST(PoseGate, InvalidConfigIsRejected) {
  GateConfig config;
  config.gap_frames = 0;
  EXPECT_THROW(PoseGate{config}, ConfigError);
}

// On a realistic trajectory the search rescoring stays far below the number of stored frames.
TEST(PoseGate, SearchIsSelectiveOnRealisticTrajectory) {
  GateConfig config;
  PoseGate gate(config);
  std::mt19937_64 rng(5);
  std::normal_distribution<double> noise(0.0, 0.05);
  double heading = 0.0;
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
  std::size_t rescored = 0;
  const int n = 20000;
  for (int i = 0; i < n; ++i) {
    heading += noise(rng);
    p += Eigen::Vector3d(std::cos(heading), std::sin(heading), 0.0);
    const double var_m2 = 0.0025 + 0.002 * static_cast<double>(i % 2000);  // resets like loop corrections
    rescored += gate.process(i, p, Eigen::Matrix3d::Identity() * var_m2).candidates_rescored;
  }
  EXPECT_LT(static_cast<double>(rescored) / n, 200.0);
}

}  // namespace
}  // namespace loopgate

namespace loopgate {
namespace {

TEST(PoseGate, QueryEqualsProcessWithoutChangingState) {
  GateConfig config;
  config.gap_frames = 10;
  const auto samples = make_samples(77, 400, CovKind::kRealistic, false);
  PoseGate gate(config);
  for (const Sample& s : samples) {
    const std::size_t in_tree = gate.frames_in_tree();
    const GateDecision peek = gate.query(s.frame, s.p_m, s.P_m2);
    EXPECT_EQ(gate.frames_in_tree(), in_tree);
    const GateDecision got = gate.process(s.frame, s.p_m, s.P_m2);
    if (s.frame >= 11) {  // exactly one frame enters the tree per frame
      EXPECT_EQ(gate.frames_in_tree(), in_tree + 1);
    }
    const GateDecision again = gate.query(s.frame + 1000000, s.p_m, s.P_m2);
    EXPECT_EQ(again.nearest_frame, got.nearest_frame);
    EXPECT_EQ(again.distance_m, got.distance_m);
    EXPECT_EQ(peek.threshold_m, got.threshold_m);
  }
  EXPECT_EQ(gate.frames_seen(), samples.size());
  EXPECT_EQ(gate.frames_in_tree(), samples.size() - 10);
  EXPECT_THROW(gate.query(0, Eigen::Vector3d(INFINITY, 0, 0), Eigen::Matrix3d::Zero()), DataError);
}

}  // namespace
}  // namespace loopgate
