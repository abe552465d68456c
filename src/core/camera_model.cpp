#include "core/camera_model.hpp"

#include <Eigen/LU>
#include <cmath>
#include <string>

#include "core/error.hpp"

namespace loopgate {
namespace {

constexpr double kMinDepth = 1e-9;
constexpr int kUndistortIterations = 30;
constexpr double kUndistortTolerance = 1e-14;

std::size_t expected_coefficients(DistortionModel model) {
  switch (model) {
    case DistortionModel::kNone: return 0;
    case DistortionModel::kRadTan: return 4;
    case DistortionModel::kEquidistant: return 4;
  }
  return 0;
}

}  // namespace

CameraModel::CameraModel(const CameraCalibration& calibration) : calibration_(calibration) {
  if (!(calibration_.fx > 0.0) || !(calibration_.fy > 0.0)) {
    throw ConfigError("camera: fx and fy must be positive (got fx=" + std::to_string(calibration_.fx) +
                      ", fy=" + std::to_string(calibration_.fy) + ")");
  }
  const std::size_t expected = expected_coefficients(calibration_.distortion_model);
  if (calibration_.distortion_model == DistortionModel::kNone && !calibration_.distortion.empty()) {
    bool all_zero = true;
    for (double k : calibration_.distortion) all_zero = all_zero && k == 0.0;
    if (!all_zero) throw ConfigError("camera.distortion: model 'none' takes no coefficients");
    calibration_.distortion.clear();
  } else if (calibration_.distortion.size() != expected) {
    throw ConfigError(std::string("camera.distortion: model '") + to_string(calibration_.distortion_model) +
                      "' needs " + std::to_string(expected) + " coefficients, got " +
                      std::to_string(calibration_.distortion.size()));
  }
}

Eigen::Vector2d CameraModel::distort_normalized(const Eigen::Vector2d& xy) const {
  const auto& k = calibration_.distortion;
  const double x = xy.x();
  const double y = xy.y();
  switch (calibration_.distortion_model) {
    case DistortionModel::kNone: return xy;
    case DistortionModel::kRadTan: {
      const double r2 = x * x + y * y;
      const double radial = 1.0 + k[0] * r2 + k[1] * r2 * r2;
      return {x * radial + 2.0 * k[2] * x * y + k[3] * (r2 + 2.0 * x * x),
              y * radial + k[2] * (r2 + 2.0 * y * y) + 2.0 * k[3] * x * y};
    }
    case DistortionModel::kEquidistant: {
      const double r = std::sqrt(x * x + y * y);
      if (r < 1e-12) return xy;
      const double theta = std::atan(r);
      const double t2 = theta * theta;
      const double theta_d = theta * (1.0 + t2 * (k[0] + t2 * (k[1] + t2 * (k[2] + t2 * k[3]))));
      const double scale = theta_d / r;
      return {x * scale, y * scale};
    }
  }
  return xy;
}

bool CameraModel::project(const Eigen::Vector3d& p_c, Eigen::Vector2d* uv_px) const {
  if (p_c.z() <= kMinDepth) return false;
  const Eigen::Vector2d d = distort_normalized(Eigen::Vector2d(p_c.x() / p_c.z(), p_c.y() / p_c.z()));
  *uv_px =
      Eigen::Vector2d(calibration_.fx * d.x() + calibration_.cx, calibration_.fy * d.y() + calibration_.cy);
  return true;
}

Eigen::Vector2d CameraModel::undistort_normalized(const Eigen::Vector2d& uv_px) const {
  const Eigen::Vector2d xd((uv_px.x() - calibration_.cx) / calibration_.fx,
                           (uv_px.y() - calibration_.cy) / calibration_.fy);
  const auto& k = calibration_.distortion;
  switch (calibration_.distortion_model) {
    case DistortionModel::kNone: return xd;
    case DistortionModel::kRadTan: {
      // Gauss-Newton on distort(xy) = xd, starting from xd, with the analytic Jacobian.
      Eigen::Vector2d xy = xd;
      for (int it = 0; it < kUndistortIterations; ++it) {
        const double x = xy.x();
        const double y = xy.y();
        const double r2 = x * x + y * y;
        const double radial = 1.0 + k[0] * r2 + k[1] * r2 * r2;
        const double dradial_dr2 = k[0] + 2.0 * k[1] * r2;
        Eigen::Matrix2d jac;
        jac(0, 0) = radial + x * dradial_dr2 * 2.0 * x + 2.0 * k[2] * y + k[3] * 6.0 * x;
        jac(0, 1) = x * dradial_dr2 * 2.0 * y + 2.0 * k[2] * x + k[3] * 2.0 * y;
        jac(1, 0) = y * dradial_dr2 * 2.0 * x + k[2] * 2.0 * x + 2.0 * k[3] * y;
        jac(1, 1) = radial + y * dradial_dr2 * 2.0 * y + k[2] * 6.0 * y + 2.0 * k[3] * x;
        const Eigen::Vector2d residual = distort_normalized(xy) - xd;
        const Eigen::Vector2d step = jac.partialPivLu().solve(residual);
        xy -= step;
        if (step.squaredNorm() < kUndistortTolerance * kUndistortTolerance) break;
      }
      return xy;
    }
    case DistortionModel::kEquidistant: {
      const double theta_d = xd.norm();
      if (theta_d < 1e-12) return xd;
      // Newton on theta * (1 + k1 t^2 + k2 t^4 + k3 t^6 + k4 t^8) = theta_d.
      double theta = theta_d;
      for (int it = 0; it < kUndistortIterations; ++it) {
        const double t2 = theta * theta;
        const double f = theta * (1.0 + t2 * (k[0] + t2 * (k[1] + t2 * (k[2] + t2 * k[3])))) - theta_d;
        const double df = 1.0 + t2 * (3.0 * k[0] + t2 * (5.0 * k[1] + t2 * (7.0 * k[2] + t2 * 9.0 * k[3])));
        const double step = f / df;
        theta -= step;
        if (std::abs(step) < kUndistortTolerance) break;
      }
      const double r = std::tan(theta);
      return xd * (r / theta_d);
    }
  }
  return xd;
}

Eigen::Vector3d CameraModel::unproject_ray(const Eigen::Vector2d& uv_px) const {
  const Eigen::Vector2d xy = undistort_normalized(uv_px);
  return Eigen::Vector3d(xy.x(), xy.y(), 1.0).normalized();
}

}  // namespace loopgate
