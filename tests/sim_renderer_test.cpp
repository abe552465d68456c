#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

#include "core/error.hpp"
#include "sim/illumination.hpp"
#include "sim/renderer.hpp"
#include "sim/world.hpp"

namespace loopgate::sim {
namespace {

const Eigen::Vector3d kKittiUp(0.0, -1.0, 0.0);
const Eigen::Vector3d kEurocUp(0.0, 0.0, 1.0);

CameraCalibration kitti_cam(int width_px = 1241, int height_px = 376) {
  CameraCalibration c;
  const double scale = static_cast<double>(width_px) / 1241.0;
  c.width_px = width_px;
  c.height_px = height_px;
  c.fx = c.fy = 718.856 * scale;
  c.cx = 607.19 * scale;
  c.cy = 185.22 * static_cast<double>(height_px) / 376.0;
  return c;
}

CameraCalibration euroc_cam() {
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

Illumination no_noise_light() {
  Illumination light;
  light.noise_sigma = 0.0;
  light.vignetting = 0.0;
  return light;
}

// Camera looking along `forward` (horizontal) with image "down" = -up.
Eigen::Isometry3d look(const Eigen::Vector3d& position, const Eigen::Vector3d& forward,
                       const Eigen::Vector3d& up) {
  const Eigen::Vector3d z = forward.normalized();
  const Eigen::Vector3d y = -up.normalized();
  const Eigen::Vector3d x = y.cross(z);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear().col(0) = x;
  T.linear().col(1) = y;
  T.linear().col(2) = z;
  T.translation() = position;
  return T;
}

// A straight street with a side street (x forward... here z forward), KITTI-like world.
std::vector<Eigen::Vector3d> street_path() {
  std::vector<Eigen::Vector3d> path;
  for (int k = 0; k <= 200; ++k) path.emplace_back(0.0, 0.0, k * 1.0);
  return path;
}

std::vector<Eigen::Vector3d> hall_path() {
  std::vector<Eigen::Vector3d> path;
  for (int k = 0; k < 300; ++k) {
    const double s = k * 0.05;
    path.emplace_back(7.0 * std::sin(0.3 * s), 4.0 * std::sin(0.5 * s), 1.2 + 0.4 * std::sin(0.7 * s));
  }
  return path;
}

// A 4 m x 3 m checkerboard of 0.5 m squares in the plane z = 6, centred on the optical axis.
World checkerboard_world() {
  World world;
  world.up_w = kKittiUp;
  const int tpm = 64, w = 4 * tpm, h = 3 * tpm;
  std::vector<std::uint8_t> texels(static_cast<std::size_t>(w * h));
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u)
      texels[static_cast<std::size_t>(v * w + u)] = ((u / 32 + v / 32) % 2) ? 220 : 30;
  }
  world.textures.emplace_back(w, h, texels, false);
  Structure s;
  s.kind = StructureKind::kWall;
  world.structures.push_back(s);
  Quad q;
  q.origin_w = Eigen::Vector3f(-2.0f, -1.5f, 6.0f);
  q.axis_u_w = q.dual_u_w = Eigen::Vector3f::UnitX();
  q.axis_v_w = q.dual_v_w = Eigen::Vector3f::UnitY();
  q.normal_w = Eigen::Vector3f::UnitZ();
  q.width_m = 4.0f;
  q.height_m = 3.0f;
  q.texels_per_m = static_cast<float>(tpm);
  q.texture = 0;
  q.structure = 0;
  world.quads.push_back(q);
  rebuild_acceleration(&world);
  return world;
}

void expect_corners_where_the_model_says(const CameraCalibration& camera, const Eigen::Isometry3d& T_w_c) {
  const World world = checkerboard_world();
  const Renderer renderer(world, camera);
  const cv::Mat image = renderer.render(T_w_c, no_noise_light(), 1);
  std::vector<cv::Point2f> expected, refined;
  for (int i = 1; i < 8; ++i) {
    for (int j = 1; j < 6; ++j) {
      const Eigen::Vector3d p_w(-2.0 + 0.5 * i, -1.5 + 0.5 * j, 6.0);
      Eigen::Vector2d uv;
      ASSERT_TRUE(renderer.camera().project(T_w_c.inverse() * p_w, &uv));
      if (uv.x() < 10 || uv.y() < 10 || uv.x() > camera.width_px - 10 || uv.y() > camera.height_px - 10)
        continue;
      expected.emplace_back(static_cast<float>(uv.x()), static_cast<float>(uv.y()));
      refined.emplace_back(static_cast<float>(uv.x() + 1.5), static_cast<float>(uv.y() - 1.0));
    }
  }
  ASSERT_GE(expected.size(), 15u);
  cv::cornerSubPix(image, refined, cv::Size(5, 5), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 50, 1e-3));
  double worst = 0.0;
  for (std::size_t k = 0; k < expected.size(); ++k) {
    worst = std::max(worst, static_cast<double>(cv::norm(refined[k] - expected[k])));
  }
  EXPECT_LT(worst, 0.3) << "corners of the rendered checkerboard vs CameraModel::project";
}

TEST(Renderer, CheckerboardCornersLandWhereTheCameraModelSays) {
  expect_corners_where_the_model_says(kitti_cam(), Eigen::Isometry3d::Identity());
  Eigen::Isometry3d T_w_c = Eigen::Isometry3d::Identity();
  T_w_c.linear() =
      (Eigen::AngleAxisd(0.12, Eigen::Vector3d::UnitY()) * Eigen::AngleAxisd(-0.05, Eigen::Vector3d::UnitX()))
          .toRotationMatrix();
  T_w_c.translation() = Eigen::Vector3d(0.4, 0.2, 1.0);
  expect_corners_where_the_model_says(kitti_cam(), T_w_c);
  expect_corners_where_the_model_says(euroc_cam(), T_w_c);  // through radtan distortion
}

TEST(Renderer, IsDeterministicPerNoiseSeed) {
  const World world = build_world(WorldConfig{}, street_path(), kKittiUp);
  const Renderer renderer(world, kitti_cam(640, 200));
  const Eigen::Isometry3d T_w_c = look(Eigen::Vector3d(0, 0, 40), Eigen::Vector3d::UnitZ(), kKittiUp);
  const Illumination light;
  const cv::Mat a = renderer.render(T_w_c, light, 7);
  const cv::Mat b = renderer.render(T_w_c, light, 7);
  const cv::Mat c = renderer.render(T_w_c, light, 8);
  ASSERT_EQ(a.type(), CV_8UC1);
  ASSERT_EQ(a.cols, 640);
  ASSERT_EQ(a.rows, 200);
  EXPECT_EQ(cv::norm(a, b, cv::NORM_L1), 0.0);
  EXPECT_GT(cv::norm(a, c, cv::NORM_L1), 0.0);
  // A second world built from the same inputs renders the same bytes.
  const World world2 = build_world(WorldConfig{}, street_path(), kKittiUp);
  const Renderer renderer2(world2, kitti_cam(640, 200));
  EXPECT_EQ(cv::norm(a, renderer2.render(T_w_c, light, 7), cv::NORM_L1), 0.0);
}

cv::Mat gradient_magnitude(const cv::Mat& image) {
  cv::Mat f, gx, gy, mag;
  image.convertTo(f, CV_32F);
  cv::GaussianBlur(f, f, cv::Size(0, 0), 2.0);
  cv::Sobel(f, gx, CV_32F, 1, 0);
  cv::Sobel(f, gy, CV_32F, 0, 1);
  cv::magnitude(gx, gy, mag);
  return mag;
}

double ncc(const cv::Mat& a, const cv::Mat& b) {
  cv::Scalar ma, sa, mb, sb;
  cv::meanStdDev(a, ma, sa);
  cv::meanStdDev(b, mb, sb);
  cv::Mat da = a - ma[0], db = b - mb[0];
  return da.dot(db) / (static_cast<double>(a.total()) * sa[0] * sb[0]);
}

TEST(Renderer, NightIsDarkerNoisierButTheSamePlace) {
  const World world = build_world(WorldConfig{}, street_path(), kKittiUp);
  const Renderer renderer(world, kitti_cam());
  const Eigen::Isometry3d T_w_c = look(Eigen::Vector3d(0, 0, 60), Eigen::Vector3d::UnitZ(), kKittiUp);
  const IlluminationSchedule schedule;
  const Illumination day = schedule.at(0.0), night = schedule.at(1.0);
  const cv::Mat day_a = renderer.render(T_w_c, day, 1), day_b = renderer.render(T_w_c, day, 2);
  const cv::Mat night_a = renderer.render(T_w_c, night, 1), night_b = renderer.render(T_w_c, night, 2);
  EXPECT_LT(cv::mean(night_a)[0], 0.6 * cv::mean(day_a)[0]);
  cv::Mat diff_day, diff_night;
  cv::subtract(day_a, day_b, diff_day, cv::noArray(), CV_32F);
  cv::subtract(night_a, night_b, diff_night, cv::noArray(), CV_32F);
  cv::Scalar m, sd_day, sd_night;
  cv::meanStdDev(diff_day, m, sd_day);
  cv::meanStdDev(diff_night, m, sd_night);
  EXPECT_GT(sd_night[0], 3.0 * sd_day[0]);
  const double structure = ncc(gradient_magnitude(day_a), gradient_magnitude(night_a));
  EXPECT_GT(structure, 0.6) << "night gradients must still match the day's";
  // A different place is not that similar.
  const cv::Mat elsewhere =
      renderer.render(look(Eigen::Vector3d(0, 0, 130), Eigen::Vector3d::UnitZ(), kKittiUp), day, 1);
  EXPECT_LT(ncc(gradient_magnitude(day_a), gradient_magnitude(elsewhere)), structure - 0.2);
}

// KLT tracks >= 100 corners between views 0.1 m apart.
int tracked_corners(const Renderer& renderer, const Eigen::Isometry3d& T_w_c0,
                    const Eigen::Vector3d& step_w) {
  Eigen::Isometry3d T_w_c1 = T_w_c0;
  T_w_c1.translation() += step_w;
  const Illumination light;
  const cv::Mat a = renderer.render(T_w_c0, light, 11);
  const cv::Mat b = renderer.render(T_w_c1, light, 12);
  std::vector<cv::Point2f> corners, forward, back;
  cv::goodFeaturesToTrack(a, corners, 600, 0.01, 8.0);
  if (corners.empty()) return 0;
  std::vector<unsigned char> status_f, status_b;
  std::vector<float> err;
  cv::calcOpticalFlowPyrLK(a, b, corners, forward, status_f, err, cv::Size(21, 21), 3);
  cv::calcOpticalFlowPyrLK(b, a, forward, back, status_b, err, cv::Size(21, 21), 3);
  int good = 0;
  for (std::size_t k = 0; k < corners.size(); ++k) {
    if (status_f[k] && status_b[k] && cv::norm(back[k] - corners[k]) < 0.5) ++good;
  }
  return good;
}

TEST(Renderer, KltTracksEnoughCornersInStreetAndHall) {
  const World street = build_world(WorldConfig{}, street_path(), kKittiUp);
  const Eigen::Isometry3d T_street = look(Eigen::Vector3d(0, 0, 50), Eigen::Vector3d::UnitZ(), kKittiUp);
  const Eigen::Vector3d step_street(0.0, 0.0, 0.1);
  WorldConfig hall_config;
  hall_config.kind = sim::WorldKind::kHall;
  const World hall = build_world(hall_config, hall_path(), kEurocUp);
  const Eigen::Isometry3d T_hall =
      look(Eigen::Vector3d(0.5, 0.5, 1.3), Eigen::Vector3d(1.0, 0.3, 0.0), kEurocUp);
  const Eigen::Vector3d step_hall = T_hall.linear() * Eigen::Vector3d(0.0, 0.0, 0.1);
  for (const CameraCalibration& base : {kitti_cam(752, 480), kitti_cam(1241, 376), kitti_cam(640, 200)}) {
    CameraCalibration cam = base;
    if (cam.width_px == 752) cam = euroc_cam();
    const Renderer street_renderer(street, cam);
    const Renderer hall_renderer(hall, cam);
    EXPECT_GE(tracked_corners(street_renderer, T_street, step_street), 100) << "street " << cam.width_px;
    EXPECT_GE(tracked_corners(hall_renderer, T_hall, step_hall), 100) << "hall " << cam.width_px;
  }
}

TEST(Illumination, ScheduleGoesFromDayToNight) {
  IlluminationSchedule schedule;
  schedule.validate();
  const Illumination day = schedule.at(0.0), dusk = schedule.at(0.55), night = schedule.at(1.0);
  EXPECT_DOUBLE_EQ(schedule.night_factor(0.0), 0.0);
  EXPECT_DOUBLE_EQ(schedule.night_factor(1.0), 1.0);
  EXPECT_GT(day.ambient, dusk.ambient);
  EXPECT_GT(dusk.ambient, night.ambient);
  EXPECT_GT(night.noise_sigma, day.noise_sigma);
  EXPECT_GT(day.sky_brightness, night.sky_brightness);
  schedule.kind = sim::IlluminationKind::kJump;
  EXPECT_DOUBLE_EQ(schedule.at(0.49).ambient, day.ambient);
  EXPECT_DOUBLE_EQ(schedule.at(0.5).noise_sigma, night.noise_sigma);
  schedule.kind = sim::IlluminationKind::kConstant;
  EXPECT_DOUBLE_EQ(schedule.at(1.0).ambient, day.ambient);
  schedule = IlluminationSchedule{};
  schedule.transition_end = 0.1;
  EXPECT_THROW(schedule.validate(), ConfigError);
}

}  // namespace
}  // namespace loopgate::sim
