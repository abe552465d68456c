// The combined distance (eq. 8-9), the sigma norms and the threshold (eq. 10), and GateConfig validation.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <cmath>
#include <random>
#include <string>

#include "core/error.hpp"
#include "stages/gate/combined_distance.hpp"
#include "stages/gate/gate_config.hpp"

namespace loopgate {
namespace {

TEST(CombinedDistance, ZeroCovarianceIsEuclidean) {
  const Eigen::Vector3d a(1.0, 2.0, 3.0);
  const Eigen::Vector3d b(4.0, 6.0, 3.0);
  EXPECT_DOUBLE_EQ(combined_distance(a, Eigen::Matrix3d::Zero(), b, Eigen::Matrix3d::Zero()), 5.0);
  EXPECT_EQ(combined_distance(a, Eigen::Matrix3d::Zero(), a, Eigen::Matrix3d::Zero()), 0.0);
}

TEST(CombinedDistance, IsotropicCovarianceShrinks) {
  const Eigen::Vector3d a(0.0, 0.0, 0.0);
  const Eigen::Vector3d b(6.0, 0.0, 0.0);
  // A = (1 + 3 + 5) I = 9 I -> d = 6 / 3.
  EXPECT_DOUBLE_EQ(
      combined_distance(a, 3.0 * Eigen::Matrix3d::Identity(), b, 5.0 * Eigen::Matrix3d::Identity()), 2.0);
}

TEST(CombinedDistance, AnisotropicByHand) {
  // P_i = diag(3, 0, 0), P_j = diag(0, 8, 0): A = diag(4, 9, 1); dp = (2, 3, 1) -> d^2 = 1 + 1 + 1.
  const Eigen::Matrix3d P_i = Eigen::Vector3d(3, 0, 0).asDiagonal();
  const Eigen::Matrix3d P_j = Eigen::Vector3d(0, 8, 0).asDiagonal();
  EXPECT_NEAR(combined_distance(Eigen::Vector3d(2, 3, 1), P_i, Eigen::Vector3d::Zero(), P_j), std::sqrt(3.0),
              1e-15);
}

TEST(CombinedDistance, MatchesExplicitInverseAndBounds) {
  std::mt19937_64 rng(3);
  std::normal_distribution<double> g(0.0, 1.0);
  for (int t = 0; t < 1000; ++t) {
    Eigen::Matrix3d M_i, M_j;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) M_i(r, c) = g(rng), M_j(r, c) = g(rng);
    const Eigen::Matrix3d P_i = M_i * M_i.transpose();
    const Eigen::Matrix3d P_j = 0.1 * M_j * M_j.transpose();
    const Eigen::Vector3d p_i(g(rng), g(rng), g(rng));
    const Eigen::Vector3d p_j(g(rng), g(rng), g(rng));
    const Eigen::Vector3d dp = p_i - p_j;
    const Eigen::Matrix3d A = Eigen::Matrix3d::Identity() + P_i + P_j;
    const double expected = std::sqrt(dp.dot(A.inverse() * dp));
    const double d = combined_distance(p_i, P_i, p_j, P_j);
    EXPECT_NEAR(d, expected, 1e-12 * (1.0 + expected));
    EXPECT_LE(d, dp.norm() * (1 + 1e-12));  // I + P_i + P_j >= I
    const double K = std::sqrt(1.0 + max_eigenvalue_m2(P_i) + max_eigenvalue_m2(P_j));
    EXPECT_GE(d * (1 + 1e-12), dp.norm() / K);
  }
}

TEST(CombinedDistance, SymmetricInTheTwoFrames) {
  const Eigen::Matrix3d P_i = Eigen::Vector3d(0.5, 2.0, 0.1).asDiagonal();
  const Eigen::Matrix3d P_j = Eigen::Vector3d(1.5, 0.0, 0.3).asDiagonal();
  const Eigen::Vector3d a(1, -2, 0.5), b(-3, 4, 2);
  EXPECT_DOUBLE_EQ(combined_distance(a, P_i, b, P_j), combined_distance(b, P_j, a, P_i));
}

TEST(Sigma, MaxEigenAndTrace) {
  // Rotated diag(9, 4, 1): lambda_max = 9, trace = 14.
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  const Eigen::Matrix3d P = R * Eigen::Vector3d(9, 4, 1).asDiagonal() * R.transpose();
  EXPECT_NEAR(max_eigenvalue_m2(P), 9.0, 1e-12);
  EXPECT_NEAR(position_sigma_m(P, SigmaNorm::kMaxEigen), 3.0, 1e-12);
  EXPECT_NEAR(position_sigma_m(P, SigmaNorm::kTrace), std::sqrt(14.0), 1e-12);
  EXPECT_EQ(position_sigma_m(Eigen::Matrix3d::Zero(), SigmaNorm::kMaxEigen), 0.0);
  EXPECT_EQ(position_sigma_m(-1e-15 * Eigen::Matrix3d::Identity(), SigmaNorm::kTrace), 0.0);
  EXPECT_THROW(position_sigma_m(P, static_cast<SigmaNorm>(7)), ConfigError);  // not in the table
}

TEST(Threshold, Equation10) {
  EXPECT_DOUBLE_EQ(gate_threshold_m(3.0, 1.96, 10.0), 15.88);
  EXPECT_DOUBLE_EQ(gate_threshold_m(0.0, 1.96, 2.5), 2.5);
}

TEST(GateConfig, DefaultsAreValidAndVisitListsEveryKey) {
  GateConfig config;
  EXPECT_NO_THROW(config.validate());
  int keys = 0;
  GateConfig::fields(config, [&](const char*, auto&) { ++keys; });
  EXPECT_EQ(keys, 14);
  EXPECT_EQ(config.gap_frames, 30);
  EXPECT_DOUBLE_EQ(config.revisit.min_travel_m, 2.0);  // eval.min_travel_m's definition of a revisit
  EXPECT_FALSE(config.feedback);                       // gate.feedback is off by default
  EXPECT_EQ(config.sigma_norm, SigmaNorm::kMaxEigen);
  EXPECT_DOUBLE_EQ(config.confidence_scale, 1.96);
}

TEST(GateConfig, ErrorsNameTheKey) {
  auto expect_error = [](auto mutate, const std::string& key) {
    GateConfig config;
    mutate(config);
    try {
      config.validate();
      ADD_FAILURE() << "expected ConfigError for " << key;
    } catch (const ConfigError& e) {
      EXPECT_NE(std::string(e.what()).find(key), std::string::npos) << e.what();
    }
  };
  expect_error([](GateConfig& c) { c.gap_frames = 0; }, "gate.gap_frames");
  expect_error([](GateConfig& c) { c.revisit.min_travel_m = -1; }, "gate.min_travel_m");
  expect_error([](GateConfig& c) { c.revisit.min_travel_m = NAN; }, "gate.min_travel_m");
  expect_error([](GateConfig& c) { c.beta_m = -1; }, "gate.beta_m");
  expect_error([](GateConfig& c) { c.beta_m = NAN; }, "gate.beta_m");
  expect_error([](GateConfig& c) { c.confidence_scale = -1; }, "gate.confidence_scale");
  expect_error([](GateConfig& c) { c.covariance_tolerance_m2 = 1.0; }, "gate.covariance_tolerance_m2");
  expect_error([](GateConfig& c) { c.kdtree_leaf_size = 0; }, "gate.kdtree_leaf_size");
  expect_error([](GateConfig& c) { c.kdtree_seed_neighbours = 0; }, "gate.kdtree_seed_neighbours");
  expect_error([](GateConfig& c) { c.area_max_hole_frames = -1; }, "gate.area_max_hole_frames");
  expect_error([](GateConfig& c) { c.area_j_tolerance_frames = -1; }, "gate.area_j_tolerance_frames");
  expect_error([](GateConfig& c) { c.area_margin_query_frames = -1; }, "gate.area_margin_query_frames");
  expect_error([](GateConfig& c) { c.area_margin_reference_frames = -1; },
               "gate.area_margin_reference_frames");
  GateConfig config;
  config.area_margin_query_frames = 19;
  EXPECT_THROW(config.validate_for_sequence_length(20), ConfigError);
  EXPECT_NO_THROW(config.validate_for_sequence_length(19));
}

}  // namespace
}  // namespace loopgate
