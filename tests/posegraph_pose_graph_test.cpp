// The pose graph on toy graphs with known solutions, and the robust loss against a wrong loop.
#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <algorithm>
#include <array>
#include <cmath>
#include <random>
#include <vector>

#include "core/error.hpp"
#include "core/geometry.hpp"
#include "core/pose_covariance.hpp"
#include "stages/posegraph/pose_graph.hpp"
#include "stages/posegraph/relative_pose_cost.hpp"

namespace loopgate {
namespace {

constexpr double kPi = 3.14159265358979323846;

Eigen::Isometry3d pose(double x, double y, double z, double yaw) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation() = Eigen::Vector3d(x, y, z);
  T.linear() = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  return T;
}

Eigen::Matrix<double, 6, 6> cov(double sigma_p, double sigma_r) {
  Eigen::Matrix<double, 6, 6> c = Eigen::Matrix<double, 6, 6>::Zero();
  c.topLeftCorner<3, 3>().diagonal().setConstant(sigma_p * sigma_p);
  c.bottomRightCorner<3, 3>().diagonal().setConstant(sigma_r * sigma_r);
  return c;
}

// A circle of n poses (radius 50 m) driven twice; odometry with a heading bias (drift).
struct Drive {
  std::vector<Eigen::Isometry3d> truth;
  std::vector<Eigen::Isometry3d> odometry;
};

Drive circle_drive(std::size_t per_lap, double heading_bias_rad) {
  Drive d;
  const std::size_t n = 2 * per_lap;
  for (std::size_t k = 0; k < n; ++k) {
    const double a = 2 * kPi * static_cast<double>(k) / static_cast<double>(per_lap);
    d.truth.push_back(pose(50 * std::sin(a), 50 - 50 * std::cos(a), 0, a));
  }
  d.odometry.push_back(d.truth[0]);
  const Eigen::Isometry3d bias = pose(0, 0, 0, heading_bias_rad);
  for (std::size_t k = 1; k < n; ++k)
    d.odometry.push_back(d.odometry.back() * (d.truth[k - 1].inverse() * d.truth[k]) * bias);
  return d;
}

double rmse(const PoseGraph& graph, const std::vector<Eigen::Isometry3d>& truth) {
  double sum = 0;
  for (std::size_t k = 0; k < truth.size(); ++k)
    sum += (graph.pose(k).translation() - truth[k].translation()).squaredNorm();
  return std::sqrt(sum / static_cast<double>(truth.size()));
}

PoseGraph graph_of(const Drive& d, const PoseGraphConfig& config, std::size_t per_lap, std::size_t loops) {
  PoseGraph graph(config);
  for (const auto& T : d.odometry) graph.add_node(T);
  for (std::size_t k = 1; k < d.odometry.size(); ++k) {
    const Eigen::Isometry3d T_a_b = d.odometry[k - 1].inverse() * d.odometry[k];
    graph.add_edge(k - 1, k, EdgeKind::kOdometry, T_a_b, config.model_cov(T_a_b));
  }
  // True loops of the second lap onto the first.
  for (std::size_t l = 0; l < loops; ++l) {
    const std::size_t j = 5 + l * (per_lap / loops);
    const std::size_t i = j + per_lap;
    graph.add_edge(j, i, EdgeKind::kLoop, d.truth[j].inverse() * d.truth[i], cov(0.1, 0.01));
  }
  return graph;
}

Eigen::Matrix<double, 6, 6> diagonal_cov(double sigma_position_m, double sigma_rotation_rad) {
  Eigen::Matrix<double, 6, 6> cov = Eigen::Matrix<double, 6, 6>::Zero();
  cov.diagonal() << Eigen::Vector3d::Constant(sigma_position_m * sigma_position_m),
      Eigen::Vector3d::Constant(sigma_rotation_rad * sigma_rotation_rad);
  return cov;
}

// The skip rule's measure (verify.min_information_gain): a loop after a long drive, whose odometry is
// uncertain in one direction (1 m along track, 0.05 m across) against an edge of 0.3 m, shrinks the largest
// position variance by 1 - (1 * 0.09 / 1.09) / 1 = 0.917: kept at the default 0.5. After hovering, the
// odometry knows the relative pose to 0.05 m: the edge adds 1 - (0.0025 * 0.09 / 0.0925) / 0.0025 = 0.027:
// skipped. Equal certainty gives exactly 0.5, the default's boundary.
TEST(PoseGraph, LoopInformationGainKeepsALoopAfterDriftAndSkipsOneAfterHovering) {
  const Eigen::Matrix<double, 6, 6> edge = diagonal_cov(0.3, 0.02);
  Eigen::Matrix<double, 6, 6> drive = diagonal_cov(0.05, 0.01);
  drive(0, 0) = 1.0;
  EXPECT_NEAR(loop_information_gain(drive, edge), 1.0 - 0.09 / 1.09, 1e-9);
  EXPECT_GE(loop_information_gain(drive, edge), 0.1);
  const Eigen::Matrix<double, 6, 6> hover = diagonal_cov(0.05, 0.001);
  EXPECT_NEAR(loop_information_gain(hover, edge), 1.0 - 0.09 / 0.0925, 1e-9);
  EXPECT_LT(loop_information_gain(hover, edge), 0.1);
  EXPECT_NEAR(loop_information_gain(edge, edge), 0.5, 1e-9);
  // A loop the old rule (the growth of the scalar sigma against the edge's, 0.3 m) skipped: the odometry's
  // relative pose over the loop is 0.2 m uncertain (composed steps): the edge still removes 31% of it.
  EXPECT_NEAR(loop_information_gain(diagonal_cov(0.2, 0.01), edge), 1.0 - 0.09 / 0.13, 1e-9);
  EXPECT_GT(loop_information_gain(diagonal_cov(0.2, 0.01), edge), 0.1);
  // Nothing known better than exactly: no gain, and no NaN for a zero covariance.
  EXPECT_EQ(loop_information_gain(Eigen::Matrix<double, 6, 6>::Zero(), edge), 0.0);
}

TEST(PoseGraph, ConsistentSquareReachesTheTruth) {
  // Four poses on a 10 m square; exact odometry and loop edges, drifted initial poses: the optimum is the
  // truth.
  const std::vector<Eigen::Isometry3d> truth = {pose(0, 0, 0, 0), pose(10, 0, 0, kPi / 2),
                                                pose(10, 10, 0, kPi), pose(0, 10, 0, -kPi / 2)};
  PoseGraphConfig config;
  PoseGraph graph(config);
  graph.add_node(truth[0]);
  for (std::size_t k = 1; k < 4; ++k) graph.add_node(truth[k] * pose(0.5, -0.3, 0.2, 0.1 * k));
  for (std::size_t k = 1; k < 4; ++k)
    graph.add_edge(k - 1, k, EdgeKind::kOdometry, truth[k - 1].inverse() * truth[k], cov(0.1, 0.01));
  graph.add_edge(0, 3, EdgeKind::kLoop, truth[0].inverse() * truth[3], cov(0.1, 0.01));
  const SolveReport report = graph.optimize(false, 0);
  EXPECT_EQ(report.outliers, 0u);
  for (std::size_t k = 0; k < 4; ++k) {
    EXPECT_LT((graph.pose(k).translation() - truth[k].translation()).norm(), 1e-6) << k;
    EXPECT_LT(Eigen::AngleAxisd(graph.pose(k).rotation().transpose() * truth[k].rotation()).angle(), 1e-6)
        << k;
  }
}

TEST(PoseGraph, TrueLoopsRemoveTheDrift) {
  const std::size_t per_lap = 100;
  const Drive d = circle_drive(per_lap, 0.002);
  PoseGraphConfig config;
  PoseGraph graph = graph_of(d, config, per_lap, 10);
  PoseGraph odometry_only = graph_of(d, config, per_lap, 0);
  const double before = rmse(odometry_only, d.truth);
  graph.optimize(true, 0);
  const double after = rmse(graph, d.truth);
  EXPECT_GT(before, 5.0);
  EXPECT_LT(after, 0.25 * before);
}

TEST(PoseGraph, AWrongLoopDoesNotBendTheMap) {
  const std::size_t per_lap = 100;
  const Drive d = circle_drive(per_lap, 0.002);
  PoseGraphConfig config;
  PoseGraph clean = graph_of(d, config, per_lap, 10);
  PoseGraph wrong = graph_of(d, config, per_lap, 10);
  // Frame 150 claims to be where frame 20 was (they are 100 m apart on the circle).
  wrong.add_edge(20, 150, EdgeKind::kLoop, pose(1, 0, 0, 0), cov(0.1, 0.01));
  clean.optimize(true, 0);
  const SolveReport report = wrong.optimize(true, 0);
  EXPECT_GE(report.outliers, 1u);
  EXPECT_TRUE(wrong.edges().back().outlier);
  EXPECT_LE(rmse(wrong, d.truth), 1.1 * rmse(clean, d.truth));
}

TEST(PoseGraph, AnalyticJacobiansEqualAutomaticDifferentiation) {
  // The edge's closed-form Jacobians against Ceres' automatic differentiation of the same residual, on random
  // poses, measurements and (upper-triangular) square-root informations; the quaternions slightly off unit
  // length, as a solver's steps leave them before the manifold renormalises.
  std::mt19937 rng(7);
  std::normal_distribution<double> normal(0.0, 1.0);
  const auto random_quaternion = [&] {
    Eigen::Quaterniond q(normal(rng), normal(rng), normal(rng), normal(rng));
    q.normalize();
    return q;
  };
  for (int trial = 0; trial < 200; ++trial) {
    Eigen::Isometry3d T_a_b = Eigen::Isometry3d::Identity();
    T_a_b.linear() = random_quaternion().toRotationMatrix();
    T_a_b.translation() = Eigen::Vector3d(normal(rng), normal(rng), normal(rng)) * 5.0;
    Eigen::Matrix<double, 6, 6> sqrt_information = Eigen::Matrix<double, 6, 6>::Zero();
    for (int r = 0; r < 6; ++r) {
      sqrt_information(r, r) = 1.0 + std::abs(normal(rng)) * 10.0;
      for (int c = r + 1; c < 6; ++c) sqrt_information(r, c) = normal(rng);
    }
    const RelativePoseCost analytic(T_a_b, sqrt_information);
    const ceres::AutoDiffCostFunction<RelativePoseResidual, 6, 3, 4, 3, 4> automatic(
        new RelativePoseResidual(T_a_b, sqrt_information));
    std::array<double, 3> p_a{}, p_b{};
    std::array<double, 4> q_a{}, q_b{};
    for (double& x : p_a) x = normal(rng) * 20.0;
    for (double& x : p_b) x = normal(rng) * 20.0;
    const double scale_a = 1.0 + 0.01 * normal(rng), scale_b = 1.0 + 0.01 * normal(rng);
    Eigen::Map<Eigen::Vector4d>(q_a.data()) = random_quaternion().coeffs() * scale_a;
    Eigen::Map<Eigen::Vector4d>(q_b.data()) = random_quaternion().coeffs() * scale_b;
    const double* parameters[] = {p_a.data(), q_a.data(), p_b.data(), q_b.data()};
    std::array<double, 6> r_analytic{}, r_automatic{};
    std::array<std::array<double, 24>, 4> J_analytic{}, J_automatic{};
    double* jac_analytic[] = {J_analytic[0].data(), J_analytic[1].data(), J_analytic[2].data(),
                              J_analytic[3].data()};
    double* jac_automatic[] = {J_automatic[0].data(), J_automatic[1].data(), J_automatic[2].data(),
                               J_automatic[3].data()};
    ASSERT_TRUE(analytic.Evaluate(parameters, r_analytic.data(), jac_analytic));
    ASSERT_TRUE(automatic.Evaluate(parameters, r_automatic.data(), jac_automatic));
    // The same expression in doubles and in Jets: equal to rounding.
    for (int k = 0; k < 6; ++k)
      EXPECT_NEAR(r_analytic[k], r_automatic[k], 1e-12 * std::max(1.0, std::abs(r_automatic[k])))
          << "trial " << trial;
    const int sizes[] = {3, 4, 3, 4};
    for (int block = 0; block < 4; ++block) {
      double largest = 0.0;
      for (int k = 0; k < 6 * sizes[block]; ++k) largest = std::max(largest, std::abs(J_automatic[block][k]));
      for (int k = 0; k < 6 * sizes[block]; ++k)
        EXPECT_NEAR(J_analytic[block][k], J_automatic[block][k], 1e-12 * std::max(1.0, largest))
            << "trial " << trial << " block " << block << " entry " << k;
    }
    // Residual only (no Jacobians asked for), and some blocks only (a constant block has none).
    std::array<double, 6> r_only{};
    ASSERT_TRUE(analytic.Evaluate(parameters, r_only.data(), nullptr));
    EXPECT_EQ(r_only, r_analytic);
    double* some[] = {nullptr, J_analytic[1].data(), nullptr, nullptr};
    ASSERT_TRUE(analytic.Evaluate(parameters, r_only.data(), some));
  }
}

TEST(PoseGraph, BothSparseCholeskyLibrariesGiveTheSameOptimum) {
  // posegraph.sparse_library: Eigen's SimplicialLDLT (the default) and CHOLMOD solve the same normal
  // equations; the optima agree to far below what the outputs print (6 decimals), with a wrong loop switched
  // off by both.
  const std::size_t per_lap = 100;
  const Drive d = circle_drive(per_lap, 0.002);
  PoseGraphConfig eigen_config;
  PoseGraphConfig cholmod_config;
  cholmod_config.sparse_library = PoseGraphSparseLibrary::kSuiteSparse;
  ASSERT_EQ(eigen_config.sparse_library, PoseGraphSparseLibrary::kEigen);
  PoseGraph eigen = graph_of(d, eigen_config, per_lap, 10);
  PoseGraph cholmod = graph_of(d, cholmod_config, per_lap, 10);
  for (PoseGraph* graph : {&eigen, &cholmod})
    graph->add_edge(20, 150, EdgeKind::kLoop, pose(1, 0, 0, 0), cov(0.1, 0.01));
  const SolveReport a = eigen.optimize(true, 0);
  const SolveReport b = cholmod.optimize(true, 0);
  EXPECT_EQ(a.outliers, 1u);
  EXPECT_EQ(b.outliers, 1u);
  EXPECT_NEAR(a.final_cost, b.final_cost, 1e-9 * std::max(1.0, b.final_cost));
  for (std::size_t k = 0; k < eigen.node_count(); ++k) {
    EXPECT_LT((eigen.pose(k).translation() - cholmod.pose(k).translation()).norm(), 1e-8) << k;
    EXPECT_LT(Eigen::AngleAxisd(eigen.pose(k).rotation().transpose() * cholmod.pose(k).rotation()).angle(),
              1e-9)
        << k;
  }
}

TEST(PoseGraph, SameResultFromTheInitialPosesWhateverSolvedBefore) {
  const std::size_t per_lap = 60;
  const Drive d = circle_drive(per_lap, 0.003);
  PoseGraphConfig config;
  PoseGraph a = graph_of(d, config, per_lap, 6);
  PoseGraph b = graph_of(d, config, per_lap, 6);
  b.optimize(false, 0);  // an intermediate solve
  a.optimize(true, 0);
  b.optimize(true, 0);
  for (std::size_t k = 0; k < a.node_count(); ++k)
    EXPECT_EQ(a.pose(k).translation(), b.pose(k).translation()) << k;
}

// Loops whose errors come from an odometry k_true times less certain than it claims.
std::vector<LoopInnovation> innovations(double k_true, int count, int wrong, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> n01(0.0, 1.0);
  std::uniform_real_distribution<double> length(0.5, 3.0);
  std::vector<LoopInnovation> out;
  for (int n = 0; n < count; ++n) {
    LoopInnovation loop;
    const double l =
        length(rng);  // odometry covariances of different sizes, as loops over short and long stretches
    loop.odometry_cov = cov(0.05 * l, 0.004 * l);
    loop.loop_cov = cov(0.1, 0.005);
    const Eigen::Matrix<double, 6, 6> S = k_true * loop.odometry_cov + loop.loop_cov;
    const Eigen::Matrix<double, 6, 6> L = S.llt().matrixL();
    Eigen::Matrix<double, 6, 1> z;
    for (int i = 0; i < 6; ++i) z(i) = n01(rng);
    loop.error = L * z;
    if (n < wrong) loop.error *= 30.0;  // a wrong loop that verification let through
    out.push_back(loop);
  }
  return out;
}

TEST(PoseGraph, OdometryCovarianceScaleFromTheLoops) {
  // An odometry 9 times overconfident (3 times in sigma): the loops show it.
  const double k = odometry_cov_scale_from_loops(innovations(9.0, 400, 0, 1), 3, 1e6);
  EXPECT_GT(k, 9.0 / 1.3);
  EXPECT_LT(k, 9.0 * 1.3);
  // A fifth of the loops wrong moves the median, not by much.
  const double k_wrong = odometry_cov_scale_from_loops(innovations(9.0, 400, 80, 2), 3, 1e6);
  EXPECT_GT(k_wrong, 9.0 / 1.3);
  EXPECT_LT(k_wrong, 9.0 * 2.0);
  // An odometry as certain as it claims, or more: never scaled down.
  EXPECT_NEAR(odometry_cov_scale_from_loops(innovations(1.0, 400, 0, 3), 3, 1e6), 1.0, 0.3);
  EXPECT_EQ(odometry_cov_scale_from_loops(innovations(0.1, 400, 0, 4), 3, 1e6), 1.0);
  // Too few loops to tell, or loops beyond any scale.
  EXPECT_EQ(odometry_cov_scale_from_loops(innovations(9.0, 2, 0, 5), 3, 1e6), 1.0);
  EXPECT_EQ(odometry_cov_scale_from_loops({}, 3, 1e6), 1.0);
  EXPECT_EQ(odometry_cov_scale_from_loops(innovations(9.0, 5, 5, 6), 3, 4.0), 4.0);
}

// One or two loops: the median cannot outvote a wrong one, so the scale they show is taken only as far as
// the odometry's own position sigmas allow (check_scale), never beyond; without that figure, 1.
TEST(PoseGraph, OdometryCovarianceScaleFromOneOrTwoLoopsStaysWithinTheOdometrysOwnSigma) {
  const std::vector<LoopInnovation> two = innovations(9.0, 2, 0, 7);
  EXPECT_EQ(odometry_cov_scale_from_loops(two, 3, 1e6), 1.0);  // check_scale unknown: as before
  std::vector<LoopInnovation> checked = two;
  for (LoopInnovation& loop : checked) loop.check_scale = 50.0;
  const double k = odometry_cov_scale_from_loops(checked, 3, 1e6);
  EXPECT_GT(k, 1.5);  // the two loops show an overconfident odometry
  EXPECT_LE(k, 50.0);
  // A wrong loop 30 times its sigma off: at most what the odometry's sigma granted it.
  std::vector<LoopInnovation> wrong = innovations(1.0, 1, 1, 8);
  wrong[0].check_scale = 4.0;
  EXPECT_EQ(odometry_cov_scale_from_loops(wrong, 3, 1e6), 4.0);
  // The smallest check among the loops bounds it; one without a check leaves the odometry unscaled.
  checked[1].check_scale = 2.0;
  EXPECT_LE(odometry_cov_scale_from_loops(checked, 3, 1e6), 2.0);
  checked[1].check_scale = 0.0;
  EXPECT_EQ(odometry_cov_scale_from_loops(checked, 3, 1e6), 1.0);
  // The check scale: the growth of the absolute position variance over the relative covariance's trace.
  EXPECT_NEAR(odometry_check_scale(cov(0.1, 0.01), 0.5, 0.3), (0.25 - 0.09) / 0.03, 1e-9);
  EXPECT_EQ(odometry_check_scale(cov(0.1, 0.01), 0.3, 0.5), 0.0);  // it learnt where it is in between
  EXPECT_EQ(odometry_check_scale(cov(0.1, 0.01), std::nan(""), 0.1), 0.0);
}

// A filter whose step covariances claim 10 times too small a sigma, while its absolute position sigma grows
// honestly: a single true loop after a drifted lap is an outlier to the graph at the claimed covariance and
// is switched off; with the scale one loop shows within the odometry's own sigma, and the robust loss as
// wide as that odometry's uncertainty seen through the edge (loop_loss_scale()), it is kept and removes most
// of the drift.
TEST(PoseGraph, OneTrueLoopIsKeptWhenTheOdometrysStepCovarianceIsOverconfident) {
  const std::size_t per_lap = 100;
  const Drive d = circle_drive(per_lap, 0.004);
  PoseGraphConfig config;
  const std::size_t j = 5, i = j + per_lap;
  // The odometry's covariance of T_j_i, composed from its (overconfident) steps, and the honest one.
  PoseCov claimed = PoseCov::Zero(), honest = PoseCov::Zero();
  Eigen::Isometry3d T_j_f = Eigen::Isometry3d::Identity();
  for (std::size_t f = j + 1; f <= i; ++f) {
    const Eigen::Isometry3d step = d.odometry[f - 1].inverse() * d.odometry[f];
    const PoseCov step_cov = config.model_cov(step);
    claimed = compose_pose_cov(T_j_f, claimed, step, 0.01 * step_cov);
    honest = compose_pose_cov(T_j_f, honest, step, step_cov);
    T_j_f = T_j_f * step;
  }
  LoopInnovation loop;
  const Eigen::Isometry3d T_j_i_truth = d.truth[j].inverse() * d.truth[i];
  const Eigen::Isometry3d T_j_i_odometry = d.odometry[j].inverse() * d.odometry[i];
  loop.error.head<3>() = T_j_i_truth.translation() - T_j_i_odometry.translation();
  loop.error.tail<3>() = so3_log(T_j_i_odometry.rotation().transpose() * T_j_i_truth.rotation());
  loop.odometry_cov = claimed;
  loop.loop_cov = cov(0.1, 0.01);
  const double sigma_j = 0.2;
  const double sigma_i = std::sqrt(sigma_j * sigma_j + honest.topLeftCorner<3, 3>().trace());
  loop.check_scale = odometry_check_scale(claimed, sigma_i, sigma_j);
  EXPECT_NEAR(loop.check_scale, 100.0, 1.0);
  const double k = odometry_cov_scale_from_loops({loop}, 3, 1e6);
  EXPECT_GT(k, 1.0);
  EXPECT_LE(k, loop.check_scale);
  const auto solve = [&](double scale, bool with_loop, bool with_loss_scale) {
    PoseGraph graph(config);
    for (const auto& T : d.odometry) graph.add_node(T);
    for (std::size_t f = 1; f < d.odometry.size(); ++f) {
      const Eigen::Isometry3d step = d.odometry[f - 1].inverse() * d.odometry[f];
      graph.add_edge(f - 1, f, EdgeKind::kOdometry, step, scale * 0.01 * config.model_cov(step));
    }
    if (with_loop)
      graph.add_edge(j, i, EdgeKind::kLoop, T_j_i_truth, loop.loop_cov,
                     with_loss_scale ? loop_loss_scale(config, scale * claimed, loop.loop_cov) : 0.0);
    graph.optimize(true, 0);
    return graph;
  };
  const double odometry_m = rmse(solve(1.0, false, false), d.truth);
  const PoseGraph unscaled = solve(1.0, true, false);
  ASSERT_TRUE(unscaled.edges().back().outlier)
      << "the premise: at the claimed covariance the loop is an outlier";
  // The scaled odometry alone leaves the loop deep in the robust loss's flat tail: switched off too.
  EXPECT_TRUE(solve(k, true, false).edges().back().outlier);
  const PoseGraph scaled = solve(k, true, true);
  EXPECT_FALSE(scaled.edges().back().outlier) << "chi2 " << scaled.edges().back().chi2;
  EXPECT_LT(rmse(scaled, d.truth), 0.5 * odometry_m);
}

// Loops that agree with the odometry better than its covariance predicts show an odometry more certain than
// it claims: allowed below 1 (min_scale), the scale falls to about the true fraction; by default, with
// fewer than min_loops loops, or when the loops show an overconfident odometry, it does not.
TEST(PoseGraph, OdometryCovarianceScaleBelowOneOnlyFromEnoughLoopsAndWhenAsked) {
  const double k = odometry_cov_scale_from_loops(innovations(0.1, 400, 0, 4), 3, 1.0, 1e-6);
  EXPECT_GT(k, 0.1 / 1.3);
  EXPECT_LT(k, 0.1 * 1.3);
  // Innovations that are the edges' noise alone: down to the floor's order, where the odometry no longer
  // counts.
  EXPECT_LT(odometry_cov_scale_from_loops(innovations(0.0, 400, 0, 4), 3, 1.0, 1e-6), 0.05);
  EXPECT_EQ(odometry_cov_scale_from_loops(innovations(0.1, 400, 0, 4), 3, 1.0), 1.0);
  EXPECT_EQ(odometry_cov_scale_from_loops(innovations(0.1, 2, 0, 4), 3, 1.0, 1e-6), 1.0);
  EXPECT_EQ(odometry_cov_scale_from_loops(innovations(9.0, 400, 0, 4), 3, 1.0, 1e-6), 1.0);
}

// A good odometry that claims to be uncertain (a conservative drift model, or the odometry edges' floors
// summed over a long loop), nine loop edges within their sigma of the truth and a wrong one 0.6 m off (12
// sigma): with the robust loss widened by the odometry's whole claimed covariance of T_j_i
// (loop_loss_scale()), the soft odometry bends to the wrong edge until it looks like a true one, and it is
// kept; widened by the fraction of that covariance the loops confirm (odometry_cov_scale_from_loops() below
// 1, as the loop closer does), it is switched off and the trajectory stays near the truth.
TEST(PoseGraph, AWrongEdgeDoesNotBendAGoodOdometryThatClaimsToBeUncertain) {
  const std::size_t per_lap = 100, loops = 10, wrong = 3;
  const Drive d = circle_drive(per_lap, 0.0);
  PoseGraphConfig config;
  config.odometry_sigma_rotation_rad_per_sqrt_m = 0.0;
  config.odometry_sigma_rotation_floor_rad = 1e-4;
  std::mt19937_64 rng(11);
  std::normal_distribution<double> n01(0.0, 1.0);
  const double edge_sigma_m = 0.05;
  const PoseCov edge_cov = cov(edge_sigma_m, 0.003);
  struct Loop {
    std::size_t j, i;
    Eigen::Isometry3d T_j_i;
    PoseCov odometry_cov;
  };
  std::vector<Loop> edges;
  std::vector<LoopInnovation> innovations_of_loops;
  for (std::size_t l = 0; l < loops; ++l) {
    const std::size_t j = 5 + l * (per_lap / loops), i = j + per_lap;
    PoseCov claimed = PoseCov::Zero();
    Eigen::Isometry3d T_j_f = Eigen::Isometry3d::Identity();
    for (std::size_t f = j + 1; f <= i; ++f) {
      const Eigen::Isometry3d step = d.odometry[f - 1].inverse() * d.odometry[f];
      claimed = compose_pose_cov(T_j_f, claimed, step, config.model_cov(step));
      T_j_f = T_j_f * step;
    }
    Eigen::Isometry3d T_j_i = d.truth[j].inverse() * d.truth[i];
    const Eigen::Vector3d off = l == wrong ? Eigen::Vector3d(0.6, 0.0, 0.0)
                                           : Eigen::Vector3d(n01(rng), n01(rng), n01(rng)) * edge_sigma_m;
    T_j_i.translation() += off;
    edges.push_back({j, i, T_j_i, claimed});
    LoopInnovation innovation;
    innovation.error.head<3>() = T_j_i.translation() - T_j_f.translation();
    innovation.odometry_cov = claimed;
    innovation.loop_cov = edge_cov;
    innovations_of_loops.push_back(innovation);
  }
  const double fraction = odometry_cov_scale_from_loops(innovations_of_loops, 3, 1.0, 1e-6);
  EXPECT_LT(fraction, 0.1) << "the premise: the loops show a far more certain odometry than it claims";
  const auto solve = [&](double loss_fraction) {
    PoseGraph graph(config);
    for (const auto& T : d.odometry) graph.add_node(T);
    for (std::size_t f = 1; f < d.odometry.size(); ++f) {
      const Eigen::Isometry3d step = d.odometry[f - 1].inverse() * d.odometry[f];
      graph.add_edge(f - 1, f, EdgeKind::kOdometry, step, config.model_cov(step));
    }
    for (const Loop& e : edges)
      graph.add_edge(e.j, e.i, EdgeKind::kLoop, e.T_j_i, edge_cov,
                     loop_loss_scale(config, loss_fraction * e.odometry_cov, edge_cov));
    graph.optimize(true, 0);
    return graph;
  };
  const PoseGraph whole = solve(1.0), confirmed = solve(fraction);
  const std::size_t wrong_edge = d.odometry.size() - 1 + wrong;
  ASSERT_EQ(whole.edges().at(wrong_edge).kind, EdgeKind::kLoop);
  EXPECT_FALSE(whole.edges().at(wrong_edge).outlier) << "the premise: the wide loss keeps the wrong edge";
  EXPECT_TRUE(confirmed.edges().at(wrong_edge).outlier) << "chi2 " << confirmed.edges().at(wrong_edge).chi2;
  EXPECT_LT(rmse(confirmed, d.truth), 0.8 * rmse(whole, d.truth))
      << "whole claimed covariance " << rmse(whole, d.truth) << " m, confirmed " << rmse(confirmed, d.truth);
}

// The loop's robust loss scale: the configured one when the odometry knows T_j_i exactly, growing with the
// odometry's uncertainty in units of the edge's.
TEST(PoseGraph, LoopLossScaleGrowsWithTheOdometrysUncertaintyOfTheLoop) {
  PoseGraphConfig config;
  config.loss_scale = 2.0;
  EXPECT_DOUBLE_EQ(loop_loss_scale(config, PoseCov::Zero(), cov(0.1, 0.01)), 2.0);
  // The odometry 3 times the edge's sigma on every axis: tr(C_loop^-1 C_odo) = 6 x 9.
  EXPECT_NEAR(loop_loss_scale(config, cov(0.3, 0.03), cov(0.1, 0.01)), 2.0 * std::sqrt(10.0), 1e-9);
}

TEST(PoseGraph, BadEdgesAndConfigAreRejected) {
  PoseGraphConfig config;
  PoseGraph graph(config);
  graph.add_node(Eigen::Isometry3d::Identity());
  graph.add_node(Eigen::Isometry3d::Identity());
  EXPECT_THROW(graph.add_edge(0, 2, EdgeKind::kOdometry, Eigen::Isometry3d::Identity(), cov(1, 1)),
               std::invalid_argument);
  EXPECT_THROW(graph.add_edge(0, 1, EdgeKind::kOdometry, Eigen::Isometry3d::Identity(),
                              Eigen::Matrix<double, 6, 6>::Zero()),
               std::invalid_argument);
  // The closed choices (odometry_cov, loss, sparse_library) are enums: a bad word is refused when the config
  // is loaded (tests/pipeline_config_choices_test.cpp).
  config.odometry_cov_scale = -1;
  try {
    config.validate();
    FAIL();
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("posegraph.odometry_cov_scale"), std::string::npos) << e.what();
  }
  config.odometry_cov_scale = std::nan("");
  EXPECT_THROW(config.validate(), ConfigError);
  config = PoseGraphConfig{};
  config.node_every_frames = 0;
  try {
    config.validate();
    FAIL();
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("posegraph.node_every_frames"), std::string::npos);
  }
}

}  // namespace
}  // namespace loopgate
