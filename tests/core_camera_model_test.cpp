#include <gtest/gtest.h>

#include "core/camera_model.hpp"
#include "core/error.hpp"

namespace loopgate {
namespace {

CameraCalibration euroc_cam0() {
  CameraCalibration c;
  c.width_px = 752;
  c.height_px = 480;
  c.fx = 458.654;
  c.fy = 457.296;
  c.cx = 367.215;
  c.cy = 248.375;
  c.distortion_model = DistortionModel::kRadTan;
  c.distortion = {-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05};
  return c;
}

CameraCalibration equidistant_cam() {
  CameraCalibration c = euroc_cam0();
  c.distortion_model = DistortionModel::kEquidistant;
  c.distortion = {-0.0137, 0.0207, -0.0176, 0.0055};
  return c;
}

CameraCalibration pinhole_cam() {
  CameraCalibration c;
  c.width_px = 1241;
  c.height_px = 376;
  c.fx = c.fy = 718.856;
  c.cx = 607.19;
  c.cy = 185.22;
  return c;
}

// Every pixel of a grid over the image -> ray -> back to the same pixel.
void expect_pixel_round_trip(const CameraModel& model, double tolerance_px) {
  const CameraCalibration& c = model.calibration();
  double worst = 0.0;
  for (double v = 0.0; v < c.height_px; v += 17.0) {
    for (double u = 0.0; u < c.width_px; u += 23.0) {
      const Eigen::Vector3d ray = model.unproject_ray(Eigen::Vector2d(u, v));
      EXPECT_NEAR(ray.norm(), 1.0, 1e-12);
      EXPECT_GT(ray.z(), 0.0);
      Eigen::Vector2d uv;
      ASSERT_TRUE(model.project(ray * 3.7, &uv));
      worst = std::max(worst, (uv - Eigen::Vector2d(u, v)).norm());
    }
  }
  EXPECT_LT(worst, tolerance_px);
}

// Points in front of the camera -> pixel -> ray parallel to the point.
void expect_point_round_trip(const CameraModel& model) {
  for (double x = -0.6; x <= 0.6; x += 0.15) {
    for (double y = -0.45; y <= 0.45; y += 0.15) {
      const Eigen::Vector3d p(x * 4.0, y * 4.0, 4.0);
      Eigen::Vector2d uv;
      ASSERT_TRUE(model.project(p, &uv));
      const Eigen::Vector3d ray = model.unproject_ray(uv);
      EXPECT_LT((ray - p.normalized()).norm(), 1e-9) << x << " " << y;
      const Eigen::Vector2d xy = model.undistort_normalized(uv);
      EXPECT_LT((xy - Eigen::Vector2d(x, y)).norm(), 1e-9);
      const Eigen::Vector2d xd = model.distort_normalized(xy);
      EXPECT_NEAR(xd.x(), (uv.x() - model.calibration().cx) / model.calibration().fx, 1e-12);
    }
  }
}

TEST(CameraModel, RadTanEurocCam0RoundTrips) {
  const CameraModel model(euroc_cam0());
  expect_pixel_round_trip(model, 1e-6);
  expect_point_round_trip(model);
}

TEST(CameraModel, RadTanDistortsTowardsTheCentre) {
  // Negative k1 (barrel): a point near the corner lands closer to the principal point than pinhole.
  const CameraModel model(euroc_cam0());
  const Eigen::Vector2d xy(0.6, 0.4);
  const Eigen::Vector2d xd = model.distort_normalized(xy);
  EXPECT_LT(xd.norm(), xy.norm());
  const double r2 = xy.squaredNorm();
  const double radial = 1.0 - 0.28340811 * r2 + 0.07395907 * r2 * r2;
  EXPECT_NEAR(xd.x(), 0.6 * radial + 2.0 * 0.00019359 * 0.6 * 0.4 + 1.76187114e-05 * (r2 + 2.0 * 0.36),
              1e-12);
}

TEST(CameraModel, EquidistantRoundTrips) {
  const CameraModel model(equidistant_cam());
  expect_pixel_round_trip(model, 1e-6);
  expect_point_round_trip(model);
  // theta_d = theta (1 + k1 theta^2 + ...): check one value by hand.
  const Eigen::Vector2d xd = model.distort_normalized(Eigen::Vector2d(0.5, 0.0));
  const double theta = std::atan(0.5);
  const double t2 = theta * theta;
  const double theta_d =
      theta * (1 - 0.0137 * t2 + 0.0207 * t2 * t2 - 0.0176 * t2 * t2 * t2 + 0.0055 * t2 * t2 * t2 * t2);
  EXPECT_NEAR(xd.x(), theta_d, 1e-12);
}

TEST(CameraModel, PinholeProjectsAndRoundTrips) {
  const CameraModel model(pinhole_cam());
  Eigen::Vector2d uv;
  ASSERT_TRUE(model.project(Eigen::Vector3d(1.0, -0.5, 10.0), &uv));
  EXPECT_NEAR(uv.x(), 718.856 * 0.1 + 607.19, 1e-9);
  EXPECT_NEAR(uv.y(), 718.856 * -0.05 + 185.22, 1e-9);
  EXPECT_FALSE(model.project(Eigen::Vector3d(1.0, 0.0, 0.0), &uv));
  EXPECT_FALSE(model.project(Eigen::Vector3d(1.0, 0.0, -2.0), &uv));
  expect_pixel_round_trip(model, 1e-9);
  expect_point_round_trip(model);
}

TEST(CameraModel, RejectsBadCalibration) {
  CameraCalibration c = euroc_cam0();
  c.distortion.pop_back();
  EXPECT_THROW(CameraModel{c}, ConfigError);
  c = pinhole_cam();
  c.fx = 0.0;
  EXPECT_THROW(CameraModel{c}, ConfigError);
  c = pinhole_cam();
  c.distortion = {0.1, 0.0, 0.0, 0.0};
  EXPECT_THROW(CameraModel{c}, ConfigError);
}

}  // namespace
}  // namespace loopgate
