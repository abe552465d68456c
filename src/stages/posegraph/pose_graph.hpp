// A 6-DoF pose graph on Ceres: nodes are body poses T_w_b (initialised from the odometry), edges relative
// poses T_a_b with a 6x6 covariance (position, rotation as a right perturbation). Odometry edges are plain
// least squares; loop edges go through a robust loss (Cauchy or Huber, on the whitened squared norm) so
// that one wrong loop cannot bend the map, and after a solve a loop edge whose whitened squared residual
// exceeds outlier_chi2 is switched off and the graph solved again. The first node is held fixed (gauge).
// Section "posegraph". No threads, no files.
//
// 6-DoF, not VINS-Mono's 4-DoF (x, y, z, yaw): it needs no gravity axis (KITTI camera worlds are -y up,
// EuRoC z up, image folders have none) and the odometry edges' rotation sigmas keep roll and pitch where the
// odometry put them.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <cstddef>
#include <span>
#include <string>
#include <vector>

#include "core/enum_names.hpp"

namespace loopgate {

// posegraph.odometry_cov: the odometry edges' covariance (PoseGraphConfig::odometry_cov).
enum class PoseGraphOdometryCov { kModel, kOdometry };
inline constexpr EnumName<PoseGraphOdometryCov> kPoseGraphOdometryCovNames[] = {
    {PoseGraphOdometryCov::kModel, "model"}, {PoseGraphOdometryCov::kOdometry, "odometry"}};
constexpr std::span<const EnumName<PoseGraphOdometryCov>> enum_names(PoseGraphOdometryCov) {
  return kPoseGraphOdometryCovNames;
}
// posegraph.loss: the loop edges' robust loss.
enum class PoseGraphLoss { kCauchy, kHuber, kNone };
inline constexpr EnumName<PoseGraphLoss> kPoseGraphLossNames[] = {
    {PoseGraphLoss::kCauchy, "cauchy"}, {PoseGraphLoss::kHuber, "huber"}, {PoseGraphLoss::kNone, "none"}};
constexpr std::span<const EnumName<PoseGraphLoss>> enum_names(PoseGraphLoss) {
  return kPoseGraphLossNames;
}
// posegraph.sparse_library: the sparse Cholesky of Ceres' SPARSE_NORMAL_CHOLESKY.
enum class PoseGraphSparseLibrary { kEigen, kSuiteSparse };
inline constexpr EnumName<PoseGraphSparseLibrary> kPoseGraphSparseLibraryNames[] = {
    {PoseGraphSparseLibrary::kEigen, "eigen"}, {PoseGraphSparseLibrary::kSuiteSparse, "suite_sparse"}};
constexpr std::span<const EnumName<PoseGraphSparseLibrary>> enum_names(PoseGraphSparseLibrary) {
  return kPoseGraphSparseLibraryNames;
}

struct PoseGraphConfig {
  bool enabled = true;
  int node_every_frames = 1;  // a node every N tracked frames (and one at every loop frame)
  // The odometry edges' covariance. "odometry": the odometry's own, its step covariances
  // (OdometryOutput::step_cov) composed from node to node, plus the floors below squared; an edge over a
  // frame whose source gave none (the first pose, after a loss) falls back to the model. "model": a fixed
  // model of edge length d metres, sigma = floor + per_sqrt_m * sqrt(d), position and rotation.
  PoseGraphOdometryCov odometry_cov = PoseGraphOdometryCov::kOdometry;
  // odometry_cov odometry: the odometry's covariances times this; 0: from the verified loops
  // (odometry_cov_scale_from_loops), 1 when fewer than 3 loops are verified.
  double odometry_cov_scale = 0.0;
  double odometry_sigma_position_m_per_sqrt_m = 0.02;
  double odometry_sigma_position_floor_m = 0.005;
  double odometry_sigma_rotation_rad_per_sqrt_m = 0.002;
  double odometry_sigma_rotation_floor_rad = 0.0005;
  PoseGraphLoss loss = PoseGraphLoss::kCauchy;  // cauchy | huber | none (loop edges only)
  double loss_scale = 1.0;       // in whitened units (sigma); a loop edge's own: loop_loss_scale()
  double outlier_chi2 = 22.46;   // chi-square, 6 dof, 0.999
  int max_iterations = 50;       // per solve
  double max_solve_s = 2.0;      // per solve while the stream runs (the final solve has no time bound)
  bool optimize_on_loop = true;  // solve whenever verified loops arrived (off the frame's critical path)
  // The sparse Cholesky of Ceres' SPARSE_NORMAL_CHOLESKY: "eigen" (Eigen's SimplicialLDLT; a pose graph is
  // a chain with a few loops, whose factor has little fill-in) or "suite_sparse" (CHOLMOD, supernodal).
  PoseGraphSparseLibrary sparse_library = PoseGraphSparseLibrary::kEigen;

  template <class Self, class V>
  static void fields(Self& self, V&& v) {
    v("enabled", self.enabled);
    v("node_every_frames", self.node_every_frames);
    v("odometry_cov", self.odometry_cov);
    v("odometry_cov_scale", self.odometry_cov_scale);
    v("odometry_sigma_position_m_per_sqrt_m", self.odometry_sigma_position_m_per_sqrt_m);
    v("odometry_sigma_position_floor_m", self.odometry_sigma_position_floor_m);
    v("odometry_sigma_rotation_rad_per_sqrt_m", self.odometry_sigma_rotation_rad_per_sqrt_m);
    v("odometry_sigma_rotation_floor_rad", self.odometry_sigma_rotation_floor_rad);
    v("loss", self.loss);
    v("loss_scale", self.loss_scale);
    v("outlier_chi2", self.outlier_chi2);
    v("max_iterations", self.max_iterations);
    v("max_solve_s", self.max_solve_s);
    v("optimize_on_loop", self.optimize_on_loop);
    v("sparse_library", self.sparse_library);
  }
  void validate() const;  // throws ConfigError naming posegraph.KEY and its bound

  // The covariance of an odometry edge T_a_b under this model.
  Eigen::Matrix<double, 6, 6> model_cov(const Eigen::Isometry3d& T_a_b) const;
  // An odometry edge's covariance from the odometry's own: `cov` plus the floors squared on the diagonal.
  Eigen::Matrix<double, 6, 6> with_floors(const Eigen::Matrix<double, 6, 6>& cov) const;
};

// One verified loop (i, j) seen from the odometry: the error of the loop's T_j_i against the odometry's
// (core/pose_covariance.hpp's convention) and the covariances of the two.
struct LoopInnovation {
  Eigen::Matrix<double, 6, 1> error = Eigen::Matrix<double, 6, 1>::Zero();
  Eigen::Matrix<double, 6, 6> odometry_cov = Eigen::Matrix<double, 6, 6>::Zero();
  Eigen::Matrix<double, 6, 6> loop_cov = Eigen::Matrix<double, 6, 6>::Identity();
  // How much less certain the odometry itself says T_j_i is than odometry_cov (0: it does not say): its
  // absolute position variance's growth from j to i (sigma_i^2 - sigma_j^2, sigma the square root of the
  // position covariance's trace: the variance the verifier's odometry check judged the loop with) over the
  // trace of odometry_cov's position block (odometry_check_scale()). A loop that passed that check is
  // consistent with an odometry this much less certain, no more.
  double check_scale = 0.0;
};

// The factor k >= 1 for the odometry's covariances such that the median over the loops of
// e^T (k C_odometry + C_loop)^-1 e is the chi-square median of 6 dof (5.348): an odometry that claims to
// know the relative pose of a loop's two frames better than the verified loops show (a filter's
// overconfidence) gets its covariance scaled up by what the loops show. Never scaled down (1 when the loops
// agree at least as well as predicted), at most max_scale; the median lets up to half the loops be wrong.
// With fewer than min_loops loops (one or two) the median cannot outvote a wrong loop, so the scale they
// show is taken only as far as the odometry's own sigmas allow it: at most the smallest check_scale among
// them (1 when one of them has none), the uncertainty the odometry check already granted each loop.
// 1 without loops.
// min_scale < 1 (in (0, 1]) also lets the loops scale the covariance down, to the k at which the median is
// the chi-square median, when they agree better than the odometry predicts: an odometry more certain than it
// claims (a conservative drift model). Scaled down only from min_loops loops on.
double odometry_cov_scale_from_loops(const std::vector<LoopInnovation>& loops, std::size_t min_loops,
                                     double max_scale, double min_scale = 1.0);

// LoopInnovation::check_scale: (sigma_i_m^2 - sigma_j_m^2) / trace of the position block of odometry_cov,
// 0 when it is not a finite number > 0 (no sigmas, or the odometry learnt where it is between j and i).
double odometry_check_scale(const Eigen::Matrix<double, 6, 6>& odometry_cov, double sigma_i_m,
                            double sigma_j_m);

// What a loop edge between frames j and i would add to what the odometry knows of their relative pose: the
// fraction by which it shrinks the largest position variance of T_j_i, 1 - lambda_max(P_fused) /
// lambda_max(P_odometry), where P is the position block (first three rows and columns) of the covariance
// (position, rotation) and the fused covariance is that of the two independent estimates combined,
// (C_odometry^-1 + C_loop^-1)^-1. 0 when the odometry knows the relative pose exactly, near 1 when the loop
// edge is far more certain. With both isotropic it is s_odo^2 / (s_odo^2 + s_loop^2): 0.5 when the two are
// equally certain. C_loop must be positive definite; C_odometry positive semi-definite.
double loop_information_gain(const Eigen::Matrix<double, 6, 6>& odometry_cov,
                             const Eigen::Matrix<double, 6, 6>& loop_cov);

// The robust loss's scale for a loop edge (in the edge's whitened units): loss_scale times
// sqrt(1 + tr(C_loop^-1 C_odometry) / 6). Before the solve a true loop's whitened squared residual is spread
// as chi-square with 6 + tr(C_loop^-1 C_odometry) mean, C_odometry the odometry's true covariance of T_j_i:
// the odometry's drift seen through the edge's sigma. A loop that corrects a drift far larger than its own
// sigma would otherwise start deep in the loss's flat tail, barely pull the graph and be switched off as an
// outlier although the odometry check found it consistent. Equal to loss_scale when the odometry knows T_j_i
// exactly. The loop closer passes the graph's covariance of T_j_i times the fraction of it the loops confirm
// (odometry_cov_scale_from_loops() with min_scale): a claim the loops do not confirm is no drift to make room
// for.
double loop_loss_scale(const PoseGraphConfig& config, const Eigen::Matrix<double, 6, 6>& odometry_cov,
                       const Eigen::Matrix<double, 6, 6>& loop_cov);

enum class EdgeKind { kOdometry, kLoop };

struct PoseGraphEdge {
  std::size_t a = 0, b = 0;
  EdgeKind kind = EdgeKind::kOdometry;
  Eigen::Isometry3d T_a_b = Eigen::Isometry3d::Identity();
  Eigen::Matrix<double, 6, 6> sqrt_information = Eigen::Matrix<double, 6, 6>::Identity();
  double loss_scale = 0.0;  // loop edges: the robust loss's scale (0: posegraph.loss_scale)
  bool outlier = false;     // loop edges switched off by the last solve
  double chi2 = 0.0;        // whitened squared residual after the last solve
};

struct SolveReport {
  int iterations = 0;
  double initial_cost = 0.0;
  double final_cost = 0.0;
  double seconds = 0.0;
  std::size_t loop_edges = 0;
  std::size_t outliers = 0;
  bool converged = false;
};

class PoseGraph {
 public:
  explicit PoseGraph(const PoseGraphConfig& config);

  // A node with its initial pose; returns its id (0, 1, ...).
  std::size_t add_node(const Eigen::Isometry3d& T_w_b);
  // Throws std::invalid_argument for an unknown node or a covariance that is not positive definite.
  // `loss_scale`: a loop edge's robust loss scale (loop_loss_scale()); 0: posegraph.loss_scale.
  void add_edge(std::size_t a, std::size_t b, EdgeKind kind, const Eigen::Isometry3d& T_a_b,
                const Eigen::Matrix<double, 6, 6>& cov, double loss_scale = 0.0);

  // Solves from the current estimate (from_initial: from the initial poses, so the result depends only on
  // the graph, not on earlier solves). max_seconds <= 0: no time bound. Loop edges found outliers are
  // switched off and the graph solved once more.
  SolveReport optimize(bool from_initial, double max_seconds);

  std::size_t node_count() const { return initial_.size(); }
  Eigen::Isometry3d pose(std::size_t id) const;
  const Eigen::Isometry3d& initial_pose(std::size_t id) const { return initial_.at(id); }
  const std::vector<PoseGraphEdge>& edges() const { return edges_; }

 private:
  SolveReport solve_once(double max_seconds);

  PoseGraphConfig config_;
  std::vector<Eigen::Isometry3d> initial_;
  std::vector<std::array<double, 7>> state_;  // tx ty tz qx qy qz qw
  std::vector<PoseGraphEdge> edges_;
};

}  // namespace loopgate
