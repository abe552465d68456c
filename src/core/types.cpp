#include "core/types.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>

namespace loopgate {

Timestamp s_to_ns(double t_s) {
  return static_cast<Timestamp>(std::llround(t_s * kNsPerS));
}

double PoseEstimate::position_sigma_m() const {
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(position_cov_m2(), Eigen::EigenvaluesOnly);
  return std::sqrt(std::max(0.0, solver.eigenvalues().maxCoeff()));
}

const char* to_string(OdometryStatus status) {
  switch (status) {
    case OdometryStatus::kInitialising: return "initialising";
    case OdometryStatus::kTracking: return "tracking";
    case OdometryStatus::kLost: return "lost";
  }
  return "unknown";
}

const char* to_string(FrameOutcome outcome) {
  switch (outcome) {
    case FrameOutcome::kNoCandidate: return "no candidate";
    case FrameOutcome::kBelowThreshold: return "below threshold";
    case FrameOutcome::kSuppressed: return "suppressed";
    case FrameOutcome::kLoop: return "loop";
  }
  return "unknown";
}

const char* to_string(DistortionModel model) {
  switch (model) {
    case DistortionModel::kNone: return "none";
    case DistortionModel::kRadTan: return "radial-tangential";
    case DistortionModel::kEquidistant: return "equidistant";
  }
  return "unknown";
}

}  // namespace loopgate
