#include "stages/posegraph/pose_graph.hpp"

#include <ceres/ceres.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <memory>
#include <stdexcept>

#include "core/error.hpp"
#include "stages/posegraph/relative_pose_cost.hpp"

namespace loopgate {

namespace {

using Matrix6d = Eigen::Matrix<double, 6, 6>;

ceres::SparseLinearAlgebraLibraryType ceres_library(PoseGraphSparseLibrary library) {
  return library == PoseGraphSparseLibrary::kEigen ? ceres::EIGEN_SPARSE : ceres::SUITE_SPARSE;
}

Eigen::Isometry3d to_isometry(const std::array<double, 7>& s) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation() = Eigen::Vector3d(s[0], s[1], s[2]);
  T.linear() = Eigen::Quaterniond(s[6], s[3], s[4], s[5]).normalized().toRotationMatrix();
  return T;
}

std::array<double, 7> to_state(const Eigen::Isometry3d& T) {
  const Eigen::Quaterniond q(T.rotation());
  const Eigen::Vector3d& t = T.translation();
  return {t.x(), t.y(), t.z(), q.x(), q.y(), q.z(), q.w()};
}

}  // namespace

double loop_information_gain(const Matrix6d& odometry_cov, const Matrix6d& loop_cov) {
  const Matrix6d odo = 0.5 * (odometry_cov + odometry_cov.transpose());
  // (C_o^-1 + C_l^-1)^-1 = C_o - C_o (C_o + C_l)^-1 C_o: needs only C_o + C_l invertible (C_l is).
  const Matrix6d fused = odo - odo * (odo + loop_cov).ldlt().solve(odo);
  const Eigen::Matrix3d p_odo = odo.topLeftCorner<3, 3>();
  const Eigen::Matrix3d p_fused =
      0.5 * (fused.topLeftCorner<3, 3>() + fused.topLeftCorner<3, 3>().transpose());
  const double before = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(p_odo).eigenvalues().maxCoeff();
  if (!(std::isfinite(before) && before > 0.0)) return 0.0;
  const double after = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(p_fused).eigenvalues().maxCoeff();
  if (!std::isfinite(after)) return 0.0;
  return std::clamp(1.0 - std::max(0.0, after) / before, 0.0, 1.0);
}

void PoseGraphConfig::validate() const {
  const auto positive = [](double v) { return std::isfinite(v) && v > 0.0; };
  const auto non_negative = [](double v) { return std::isfinite(v) && v >= 0.0; };
  if (node_every_frames < 1) throw ConfigError("posegraph.node_every_frames: must be >= 1");
  if (!non_negative(odometry_sigma_position_m_per_sqrt_m))
    throw ConfigError("posegraph.odometry_sigma_position_m_per_sqrt_m: must be a finite number >= 0");
  if (!positive(odometry_sigma_position_floor_m))
    throw ConfigError("posegraph.odometry_sigma_position_floor_m: must be a finite number > 0");
  if (!non_negative(odometry_sigma_rotation_rad_per_sqrt_m))
    throw ConfigError("posegraph.odometry_sigma_rotation_rad_per_sqrt_m: must be a finite number >= 0");
  if (!positive(odometry_sigma_rotation_floor_rad))
    throw ConfigError("posegraph.odometry_sigma_rotation_floor_rad: must be a finite number > 0");
  if (!non_negative(odometry_cov_scale))
    throw ConfigError("posegraph.odometry_cov_scale: must be a finite number >= 0 (0: from the loops)");
  if (!positive(loss_scale)) throw ConfigError("posegraph.loss_scale: must be a finite number > 0");
  if (!positive(outlier_chi2)) throw ConfigError("posegraph.outlier_chi2: must be a finite number > 0");
  if (max_iterations < 1) throw ConfigError("posegraph.max_iterations: must be >= 1");
  if (!ceres::IsSparseLinearAlgebraLibraryTypeAvailable(ceres_library(sparse_library)))
    throw ConfigError("posegraph.sparse_library: this build of Ceres has no " +
                      std::string(enum_name(sparse_library)) + " sparse Cholesky; use the other one");
  if (!non_negative(max_solve_s)) throw ConfigError("posegraph.max_solve_s: must be a finite number >= 0");
}

Eigen::Matrix<double, 6, 6> PoseGraphConfig::model_cov(const Eigen::Isometry3d& T_a_b) const {
  const double root_d = std::sqrt(T_a_b.translation().norm());
  const double sigma_p = odometry_sigma_position_floor_m + odometry_sigma_position_m_per_sqrt_m * root_d;
  const double sigma_r = odometry_sigma_rotation_floor_rad + odometry_sigma_rotation_rad_per_sqrt_m * root_d;
  Matrix6d cov = Matrix6d::Zero();
  cov.topLeftCorner<3, 3>().diagonal().setConstant(sigma_p * sigma_p);
  cov.bottomRightCorner<3, 3>().diagonal().setConstant(sigma_r * sigma_r);
  return cov;
}

Eigen::Matrix<double, 6, 6> PoseGraphConfig::with_floors(const Eigen::Matrix<double, 6, 6>& cov) const {
  Matrix6d out = cov;
  out.topLeftCorner<3, 3>().diagonal().array() +=
      odometry_sigma_position_floor_m * odometry_sigma_position_floor_m;
  out.bottomRightCorner<3, 3>().diagonal().array() +=
      odometry_sigma_rotation_floor_rad * odometry_sigma_rotation_floor_rad;
  return out;
}

double odometry_cov_scale_from_loops(const std::vector<LoopInnovation>& loops, std::size_t min_loops,
                                     double max_scale, double min_scale) {
  constexpr double kChi2MedianDof6 = 5.348120627447;
  if (loops.empty()) return 1.0;
  if (!(std::isfinite(min_scale) && min_scale > 0.0 && min_scale < 1.0)) min_scale = 1.0;
  if (loops.size() < min_loops) {
    min_scale = 1.0;
    double check = max_scale;
    for (const LoopInnovation& loop : loops)
      check = std::min(check, std::isfinite(loop.check_scale) ? loop.check_scale : 0.0);
    if (!(check > 1.0)) return 1.0;
    max_scale = check;
  }
  std::vector<double> nis(loops.size());
  const auto median_nis = [&](double k) {
    for (std::size_t n = 0; n < loops.size(); ++n) {
      const Matrix6d S = k * loops[n].odometry_cov + loops[n].loop_cov;
      nis[n] = loops[n].error.dot(S.ldlt().solve(loops[n].error));
    }
    const auto mid = nis.begin() + static_cast<std::ptrdiff_t>(nis.size() / 2);
    std::nth_element(nis.begin(), mid, nis.end());
    if (nis.size() % 2 == 1) return *mid;
    return 0.5 * (*mid + *std::max_element(nis.begin(), mid));
  };
  double lo = 0.0, hi = std::log(max_scale);
  if (median_nis(1.0) <= kChi2MedianDof6) {
    if (min_scale >= 1.0) return 1.0;
    if (median_nis(min_scale) <= kChi2MedianDof6) return min_scale;
    lo = std::log(min_scale);
    hi = 0.0;
  } else if (median_nis(max_scale) > kChi2MedianDof6) {
    return max_scale;
  }
  // The median NIS falls as k grows: bisection on log k.
  for (int it = 0; it < 60; ++it) {
    const double mid = 0.5 * (lo + hi);
    (median_nis(std::exp(mid)) > kChi2MedianDof6 ? lo : hi) = mid;
  }
  return std::exp(hi);
}

double odometry_check_scale(const Matrix6d& odometry_cov, double sigma_i_m, double sigma_j_m) {
  const double growth_m2 = sigma_i_m * sigma_i_m - sigma_j_m * sigma_j_m;
  const double trace_m2 = odometry_cov.topLeftCorner<3, 3>().trace();
  if (!(std::isfinite(growth_m2) && growth_m2 > 0.0 && std::isfinite(trace_m2) && trace_m2 > 0.0)) return 0.0;
  const double scale = growth_m2 / trace_m2;
  return std::isfinite(scale) ? scale : 0.0;
}

PoseGraph::PoseGraph(const PoseGraphConfig& config) : config_(config) {}

std::size_t PoseGraph::add_node(const Eigen::Isometry3d& T_w_b) {
  initial_.push_back(T_w_b);
  state_.push_back(to_state(T_w_b));
  return initial_.size() - 1;
}

double loop_loss_scale(const PoseGraphConfig& config, const Matrix6d& odometry_cov,
                       const Matrix6d& loop_cov) {
  const Eigen::LDLT<Matrix6d> ldlt(loop_cov);
  const double spread = ldlt.solve(0.5 * (odometry_cov + odometry_cov.transpose())).trace();
  if (!(std::isfinite(spread) && spread > 0.0)) return config.loss_scale;
  return config.loss_scale * std::sqrt(1.0 + spread / 6.0);
}

void PoseGraph::add_edge(std::size_t a, std::size_t b, EdgeKind kind, const Eigen::Isometry3d& T_a_b,
                         const Eigen::Matrix<double, 6, 6>& cov, double loss_scale) {
  if (a >= node_count() || b >= node_count() || a == b)
    throw std::invalid_argument("pose graph edge between unknown or equal nodes");
  const Eigen::LLT<Matrix6d> cov_llt(cov);
  if (!cov.allFinite() || cov_llt.info() != Eigen::Success)
    throw std::invalid_argument("pose graph edge covariance is not positive definite");
  const Eigen::LLT<Matrix6d> llt(cov.inverse());
  if (llt.info() != Eigen::Success || !llt.matrixU().toDenseMatrix().allFinite())
    throw std::invalid_argument("pose graph edge covariance is not positive definite");
  PoseGraphEdge edge;
  edge.a = a;
  edge.b = b;
  edge.kind = kind;
  edge.T_a_b = T_a_b;
  edge.sqrt_information = llt.matrixU();  // U^T U = information, so |U r|^2 = r^T information r
  edge.loss_scale = std::isfinite(loss_scale) && loss_scale > 0.0 ? loss_scale : 0.0;
  edges_.push_back(edge);
}

Eigen::Isometry3d PoseGraph::pose(std::size_t id) const {
  return to_isometry(state_.at(id));
}

SolveReport PoseGraph::optimize(bool from_initial, double max_seconds) {
  if (from_initial) {
    for (std::size_t k = 0; k < initial_.size(); ++k) state_[k] = to_state(initial_[k]);
  }
  for (PoseGraphEdge& e : edges_) e.outlier = false;
  SolveReport report = solve_once(max_seconds);
  std::size_t outliers = 0;
  for (PoseGraphEdge& e : edges_) {
    if (e.kind == EdgeKind::kLoop && e.chi2 > config_.outlier_chi2) {
      e.outlier = true;
      ++outliers;
    }
  }
  if (outliers > 0) {
    const SolveReport second = solve_once(max_seconds);
    report.iterations += second.iterations;
    report.final_cost = second.final_cost;
    report.seconds += second.seconds;
    report.converged = second.converged;
  }
  report.outliers = outliers;
  return report;
}

SolveReport PoseGraph::solve_once(double max_seconds) {
  SolveReport report;
  ceres::Problem::Options problem_options;
  problem_options.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  problem_options.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem problem(problem_options);
  ceres::EigenQuaternionManifold quaternion;
  const auto make_loss = [&](double scale) -> std::unique_ptr<ceres::LossFunction> {
    if (config_.loss == PoseGraphLoss::kCauchy) return std::make_unique<ceres::CauchyLoss>(scale);
    if (config_.loss == PoseGraphLoss::kHuber) return std::make_unique<ceres::HuberLoss>(scale);
    return nullptr;
  };
  const std::unique_ptr<ceres::LossFunction> loss = make_loss(config_.loss_scale);
  std::vector<std::unique_ptr<ceres::LossFunction>> edge_losses;  // loop edges with their own scale
  for (const PoseGraphEdge& e : edges_) {
    if (e.outlier) continue;
    ceres::LossFunction* edge_loss = nullptr;
    if (e.kind == EdgeKind::kLoop) {
      ++report.loop_edges;
      edge_loss = loss.get();
      if (e.loss_scale > 0.0 && loss) {
        edge_losses.push_back(make_loss(e.loss_scale));
        edge_loss = edge_losses.back().get();
      }
    }
    auto* cost = new RelativePoseCost(e.T_a_b, e.sqrt_information);
    problem.AddResidualBlock(cost, edge_loss, state_[e.a].data(), state_[e.a].data() + 3, state_[e.b].data(),
                             state_[e.b].data() + 3);
  }
  for (std::size_t k = 0; k < state_.size(); ++k) {
    if (!problem.HasParameterBlock(state_[k].data())) continue;
    problem.SetManifold(state_[k].data() + 3, &quaternion);
  }
  if (!state_.empty() && problem.HasParameterBlock(state_[0].data())) {
    problem.SetParameterBlockConstant(state_[0].data());
    problem.SetParameterBlockConstant(state_[0].data() + 3);
  }
  ceres::Solver::Options options;
  options.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  options.sparse_linear_algebra_library_type = ceres_library(config_.sparse_library);
  options.max_num_iterations = config_.max_iterations;
  if (max_seconds > 0) options.max_solver_time_in_seconds = max_seconds;
  options.num_threads = 1;  // deterministic
  options.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  if (problem.NumResidualBlocks() > 0) ceres::Solve(options, &problem, &summary);
  report.iterations = static_cast<int>(summary.iterations.size());
  report.initial_cost = summary.initial_cost;
  report.final_cost = summary.final_cost;
  report.seconds = summary.total_time_in_seconds;
  report.converged = summary.termination_type == ceres::CONVERGENCE;
  for (PoseGraphEdge& e : edges_) {
    const RelativePoseResidual cost(e.T_a_b, e.sqrt_information);
    Eigen::Matrix<double, 6, 1> r;
    cost(state_[e.a].data(), state_[e.a].data() + 3, state_[e.b].data(), state_[e.b].data() + 3, r.data());
    e.chi2 = r.squaredNorm();
  }
  return report;
}

}  // namespace loopgate
