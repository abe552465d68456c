// Geometric verification on rendered views of a textured plane with known poses: the relative pose is
// recovered with metric scale; unrelated views, tiny images and a missing calibration are rejected with a
// reason, never an exception.
#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <set>
#include <string>
#include <string_view>

#include "core/error.hpp"
#include "stages/verify/geometric_verifier.hpp"

namespace loopgate {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kPlaneZ_m = 8.0;       // the textured plane z = 8 m in the world
constexpr double kTexelM = 0.02;        // texture resolution
constexpr double kTextureHalfM = 20.0;  // texture spans [-20, 20] m in x and y

CameraCalibration calibration(const Eigen::Isometry3d& T_b_c) {
  CameraCalibration c;
  c.width_px = 640;
  c.height_px = 480;
  c.fx = c.fy = 400;
  c.cx = 319.5;
  c.cy = 239.5;
  c.T_b_c = T_b_c;
  return c;
}

cv::Mat texture(std::uint64_t seed) {
  const int size = static_cast<int>(2 * kTextureHalfM / kTexelM);
  cv::Mat t(size, size, CV_8UC1, cv::Scalar(128));
  cv::RNG rng(seed);
  for (int k = 0; k < 6000; ++k) {
    const cv::Point p(rng.uniform(0, size), rng.uniform(0, size));
    const int r = rng.uniform(3, 25);
    const cv::Scalar grey(rng.uniform(0, 256));
    if (k % 2) {
      cv::rectangle(t, p, p + cv::Point(r, rng.uniform(3, 25)), grey, cv::FILLED);
    } else {
      cv::circle(t, p, r, grey, cv::FILLED);
    }
  }
  return t;
}

// The view of camera T_w_c of the plane textured with `tex`.
cv::Mat render(const cv::Mat& tex, const CameraCalibration& c, const Eigen::Isometry3d& T_w_c) {
  cv::Mat map_x(c.height_px, c.width_px, CV_32FC1), map_y(c.height_px, c.width_px, CV_32FC1);
  for (int v = 0; v < c.height_px; ++v) {
    for (int u = 0; u < c.width_px; ++u) {
      const Eigen::Vector3d d_w = T_w_c.rotation() * Eigen::Vector3d((u - c.cx) / c.fx, (v - c.cy) / c.fy, 1);
      const Eigen::Vector3d o = T_w_c.translation();
      const double t = (kPlaneZ_m - o.z()) / d_w.z();
      const Eigen::Vector3d X = o + t * d_w;
      map_x.at<float>(v, u) = static_cast<float>((X.x() + kTextureHalfM) / kTexelM);
      map_y.at<float>(v, u) = static_cast<float>((X.y() + kTextureHalfM) / kTexelM);
    }
  }
  cv::Mat out;
  cv::remap(tex, out, map_x, map_y, cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar(0));
  return out;
}

Eigen::Isometry3d camera_pose(double x, double y, double z, double pan_rad) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation() = Eigen::Vector3d(x, y, z);
  T.linear() = Eigen::AngleAxisd(pan_rad, Eigen::Vector3d::UnitY()).toRotationMatrix();
  return T;
}

struct Scene {
  CameraCalibration camera;
  VerifyFrame i, j, n;
  Eigen::Isometry3d T_j_i;
};

Scene scene(const Eigen::Isometry3d& T_b_c, std::uint64_t seed_i = 7,
            const Eigen::Isometry3d& T_w_ci = camera_pose(1.0, 0.3, -0.6, 5 * kPi / 180)) {
  Scene s;
  s.camera = calibration(T_b_c);
  const cv::Mat tex = texture(7);
  const Eigen::Isometry3d T_w_cj = camera_pose(0, 0, 0, 0);
  const Eigen::Isometry3d T_w_cn = camera_pose(0.5, 0, 0.3, 0.02);
  const Eigen::Isometry3d T_c_b = T_b_c.inverse();
  s.j = {render(tex, s.camera, T_w_cj), T_w_cj * T_c_b};
  s.n = {render(tex, s.camera, T_w_cn), T_w_cn * T_c_b};
  s.i = {render(seed_i == 7 ? tex : texture(seed_i), s.camera, T_w_ci), T_w_ci * T_c_b};
  s.T_j_i = s.j.T_w_b.inverse() * s.i.T_w_b;
  s.i.T_w_b = Eigen::Isometry3d::Identity();  // the verifier must not need frame i's pose
  return s;
}

void expect_recovered(const Scene& s) {
  const GeometricVerifier verifier(VerifyConfig{}, s.camera);
  const VerifyResult r = verifier.verify(s.i, s.j, s.n);
  ASSERT_TRUE(r.verified) << r.reason;
  EXPECT_EQ(r.reason, "verified");
  EXPECT_EQ(r.key, VerifyReason::kVerified);
  EXPECT_GE(r.inliers, VerifyConfig{}.min_inliers);
  // Points 8 m away triangulated from a 0.6 m baseline in rendered (interpolated) images: ~1 % of the depth.
  EXPECT_LT((r.T_j_i.translation() - s.T_j_i.translation()).norm(), 0.15)
      << r.T_j_i.translation().transpose() << " vs " << s.T_j_i.translation().transpose();
  EXPECT_LT(Eigen::AngleAxisd(r.T_j_i.rotation().transpose() * s.T_j_i.rotation()).angle(), 0.02);
  EXPECT_GT(r.cov(0, 0), 0.0);
}

TEST(GeometricVerifier, RecoversTheMetricRelativePose) {
  expect_recovered(scene(Eigen::Isometry3d::Identity()));
}

TEST(GeometricVerifier, RecoversTheBodyPoseWithARotatedCamera) {
  // Camera z forward = body x forward (EuRoC / robot convention).
  Eigen::Isometry3d T_b_c = Eigen::Isometry3d::Identity();
  T_b_c.linear() << 0, 0, 1, -1, 0, 0, 0, -1, 0;
  T_b_c.translation() = Eigen::Vector3d(0.2, 0.0, 1.5);
  expect_recovered(scene(T_b_c));
}

TEST(GeometricVerifier, CachedFeaturesGiveTheSameResultAndItIsOffByDefault) {
  EXPECT_FALSE(VerifyConfig{}.enabled);  // runs that do not ask for it are unchanged
  const Scene s = scene(Eigen::Isometry3d::Identity());
  const GeometricVerifier verifier(VerifyConfig{}, s.camera);
  const VerifyResult from_frames = verifier.verify(s.i, s.j, s.n);
  const VerifyResult from_features = verifier.verify(verifier.detect(s.i.image), verifier.detect(s.j.image),
                                                     s.j.T_w_b, verifier.detect(s.n.image), s.n.T_w_b);
  ASSERT_TRUE(from_features.verified) << from_features.reason;
  EXPECT_EQ(from_features.inliers, from_frames.inliers);
  EXPECT_TRUE(from_features.T_j_i.isApprox(from_frames.T_j_i));
  // Features of an image too small are detected (none useful) and the loop is rejected with the reason.
  const OrbFeatures tiny = verifier.detect(cv::Mat(32, 64, CV_8UC1, cv::Scalar(100)));
  const VerifyResult from_tiny = verifier.verify(tiny, tiny, s.j.T_w_b, tiny, s.n.T_w_b);
  EXPECT_NE(from_tiny.reason.find("image too small"), std::string::npos);
  EXPECT_EQ(from_tiny.key, VerifyReason::kImageTooSmall);
}

// The matcher gives exactly the matches of OpenCV's brute-force knn matcher with the ratio test, on random
// descriptors with planted near copies (unique best matches), exact copies of one train row (a tie for the
// best: no match), ORB's 32-byte rows and a width that is not a multiple of 8 bytes.
// Each reason has its stable key (summary.json's loop_closure.rejected_by_reason and skipped_by_reason), set
// where the reason is given: every key of the table is named once, and the verifier's rejections carry
// theirs.
TEST(GeometricVerifier, ReasonKeys) {
  std::set<std::string_view> names;
  for (int k = 0; k <= static_cast<int>(VerifyReason::kOther); ++k) {
    const std::string_view name = enum_name(static_cast<VerifyReason>(k));
    EXPECT_NE(name, "?") << "VerifyReason " << k << " has no key";
    EXPECT_TRUE(names.insert(name).second) << "key " << name << " twice";
  }
  const Scene s = scene(Eigen::Isometry3d::Identity());
  const GeometricVerifier verifier(VerifyConfig{}, s.camera);
  const VerifyResult no_baseline = verifier.verify(s.i, s.j, s.j);  // the neighbour where j is
  EXPECT_EQ(no_baseline.key, VerifyReason::kShortBaseline) << no_baseline.reason;
  VerifyFrame blank = s.n;
  blank.image = cv::Mat();
  EXPECT_EQ(verifier.verify(s.i, s.j, blank).key, VerifyReason::kImageMissing);
  VerifyConfig near = VerifyConfig{};
  near.max_translation_m = 1e-3;
  near.track_pyramid_levels = 0;  // ORB's reason stands (the tracking fallback would add its own)
  const VerifyResult too_far = GeometricVerifier(near, s.camera).verify(s.i, s.j, s.n);
  EXPECT_EQ(too_far.key, VerifyReason::kTranslationTooLarge) << too_far.reason;
}

TEST(GeometricVerifier, RatioMatchIsOpenCvsKnnMatchWithTheRatioTest) {
  std::mt19937 rng(7);
  for (const int cols : {32, 13}) {
    cv::Mat train(300, cols, CV_8U), query(200, cols, CV_8U);
    cv::randu(train, 0, 256);
    cv::randu(query, 0, 256);
    for (int r = 0; r < 100; ++r) {  // near copies: a few bits flipped
      train.row(static_cast<int>(rng() % 300)).copyTo(query.row(r));
      for (int b = 0; b < 1 + r % 12; ++b)
        query.at<std::uint8_t>(r, static_cast<int>(rng() % cols)) ^= 1U << (rng() % 8);
    }
    train.row(5).copyTo(train.row(6));  // a tie for the best match of query row 150
    train.row(5).copyTo(query.row(150));
    for (const double ratio : {0.6, 0.8, 1.0}) {
      std::vector<std::vector<cv::DMatch>> knn;
      cv::BFMatcher(cv::NORM_HAMMING).knnMatch(query, train, knn, 2);
      std::vector<int> expected(static_cast<std::size_t>(query.rows), -1);
      for (const auto& m : knn) {
        if (m.size() == 2 && m[0].distance < ratio * m[1].distance)
          expected[static_cast<std::size_t>(m[0].queryIdx)] = m[0].trainIdx;
      }
      const std::vector<int> got = ratio_match_hamming(query, train, ratio);
      EXPECT_EQ(got, expected) << cols << " bytes, ratio " << ratio;
      EXPECT_EQ(got[150], -1);
      if (ratio < 1.0) {
        EXPECT_GT(std::count_if(got.begin(), got.end(), [](int k) { return k >= 0; }), 80);
      }
    }
  }
  EXPECT_EQ(ratio_match_hamming(cv::Mat(3, 32, CV_8U, cv::Scalar(1)), cv::Mat(1, 32, CV_8U), 0.8),
            std::vector<int>(3, -1));  // one train row: no second best
  EXPECT_THROW(ratio_match_hamming(cv::Mat(3, 32, CV_8U), cv::Mat(3, 16, CV_8U), 0.8), std::invalid_argument);
}

TEST(GeometricVerifier, RejectsAnUnrelatedView) {
  const Scene s = scene(Eigen::Isometry3d::Identity(), 99);
  const GeometricVerifier verifier(VerifyConfig{}, s.camera);
  const VerifyResult r = verifier.verify(s.i, s.j, s.n);
  EXPECT_FALSE(r.verified);
  EXPECT_EQ(r.reason.rfind("geometry: ", 0), 0u) << r.reason;
  // ORB's reason, or illumination when the tracking fallback ran (the two images' noise differs) and failed.
  if (r.reason.find("; tracked: ") != std::string::npos)
    EXPECT_EQ(r.key, VerifyReason::kIllumination) << r.reason;
  else
    EXPECT_TRUE(r.key == VerifyReason::kTooFewFeatures || r.key == VerifyReason::kTooFewInliers) << r.reason;
}

// Frame i "at night": the day view dimmed to a few grey levels under a lamp's fall-off (a smooth gain from 3%
// to 13% across the image), with photon-like noise of 3 grey levels, quantised to 8 bits.
cv::Mat at_night(const cv::Mat& day, std::uint64_t seed) {
  cv::Mat out(day.size(), CV_8UC1);
  cv::RNG rng(seed);
  const double cx = 0.7 * day.cols, cy = 0.3 * day.rows, r2 = 0.25 * day.cols * day.cols;
  for (int v = 0; v < day.rows; ++v) {
    for (int u = 0; u < day.cols; ++u) {
      const double gain = 0.03 + 0.1 * std::exp(-((u - cx) * (u - cx) + (v - cy) * (v - cy)) / r2);
      const double value = gain * day.at<std::uint8_t>(v, u) + rng.gaussian(3.0);
      out.at<std::uint8_t>(v, u) = cv::saturate_cast<std::uint8_t>(value);
    }
  }
  return out;
}

TEST(GeometricVerifier, NoiseSigmaEstimatesWhiteNoiseAndIgnoresSmoothShading) {
  cv::Mat flat(480, 640, CV_8UC1, cv::Scalar(100));
  cv::Mat noise(flat.size(), CV_32F);
  cv::RNG(3).fill(noise, cv::RNG::NORMAL, 0.0, 5.0);
  cv::Mat noisy;
  cv::Mat(noise + 100.0).convertTo(noisy, CV_8U);
  EXPECT_NEAR(noise_sigma(noisy), 5.0, 0.3);
  cv::Mat ramp(480, 640, CV_8UC1);
  for (int v = 0; v < ramp.rows; ++v)
    for (int u = 0; u < ramp.cols; ++u) ramp.at<std::uint8_t>(v, u) = static_cast<std::uint8_t>((u + v) / 5);
  EXPECT_LT(noise_sigma(ramp), 0.5);
  EXPECT_EQ(noise_sigma(cv::Mat()), 0.0);
}

// Normalisation cancels a smooth illumination: the day view and the same view under a lamp's fall-off (no
// noise) normalise to nearly the same image, an unrelated view does not.
TEST(GeometricVerifier, IlluminationNormalisationCancelsASmoothGain) {
  const Scene s = scene(Eigen::Isometry3d::Identity());
  cv::Mat lit(s.j.image.size(), CV_8UC1);
  for (int v = 0; v < lit.rows; ++v)
    for (int u = 0; u < lit.cols; ++u)
      lit.at<std::uint8_t>(v, u) =
          cv::saturate_cast<std::uint8_t>((0.2 + 0.6 * u / lit.cols) * s.j.image.at<std::uint8_t>(v, u));
  const cv::Rect inner(20, 20, lit.cols - 40, lit.rows - 40);
  const auto mean_difference = [&](const cv::Mat& a, const cv::Mat& b) {
    cv::Mat d;
    cv::absdiff(normalise_illumination(a, 4.0, 0.0)(inner), normalise_illumination(b, 4.0, 0.0)(inner), d);
    return cv::mean(d)[0];
  };
  const double same = mean_difference(s.j.image, lit);
  const double other = mean_difference(s.j.image, scene(Eigen::Isometry3d::Identity(), 99).i.image);
  EXPECT_LT(same, 4.0);
  EXPECT_GT(other, 5.0 * same);
}

// Day against night: ORB's matches do not verify the loop, tracking j's points into i on normalised images
// does, with the metric pose; with the fallback off the loop is rejected and the reason says both. Frame i
// revisits j as a car does, half a metre aside and 2 degrees off.
TEST(GeometricVerifier, TracksTheLoopIntoANightImageWhereOrbFails) {
  Scene s = scene(Eigen::Isometry3d::Identity(), 7, camera_pose(0.5, 0.1, -0.2, 2 * kPi / 180));
  s.i.image = at_night(s.i.image, 5);
  VerifyConfig orb_only;
  orb_only.track_pyramid_levels = 0;
  const VerifyResult without = GeometricVerifier(orb_only, s.camera).verify(s.i, s.j, s.n);
  EXPECT_FALSE(without.verified) << "ORB alone verified the night view: the test's premise is lost";
  const GeometricVerifier verifier(VerifyConfig{}, s.camera);
  const VerifyResult r = verifier.verify(s.i, s.j, s.n);
  ASSERT_TRUE(r.verified) << r.reason;
  EXPECT_TRUE(r.tracked);
  EXPECT_EQ(r.reason.rfind("verified by tracking (", 0), 0u) << r.reason;
  EXPECT_LT((r.T_j_i.translation() - s.T_j_i.translation()).norm(), 0.15)
      << r.T_j_i.translation().transpose() << " vs " << s.T_j_i.translation().transpose();
  EXPECT_LT(Eigen::AngleAxisd(r.T_j_i.rotation().transpose() * s.T_j_i.rotation()).angle(), 0.02);
  // The odometry's pose of i starts the tracking where i sees j's points: the same pose.
  const Eigen::Isometry3d T_w_bi = s.j.T_w_b * s.T_j_i;
  const VerifyResult predicted = verifier.verify(verifier.detect(s.i.image), verifier.detect(s.j.image),
                                                 s.j.T_w_b, verifier.detect(s.n.image), s.n.T_w_b, &T_w_bi);
  ASSERT_TRUE(predicted.verified) << predicted.reason;
  EXPECT_LT((predicted.T_j_i.translation() - s.T_j_i.translation()).norm(), 0.15);
  // An unrelated view at night is rejected by both, and the reason gives both counts.
  Scene unrelated = scene(Eigen::Isometry3d::Identity(), 99);
  unrelated.i.image = at_night(unrelated.i.image, 6);
  const VerifyResult no = verifier.verify(unrelated.i, unrelated.j, unrelated.n);
  EXPECT_FALSE(no.verified);
  EXPECT_NE(no.reason.find("; tracked: "), std::string::npos) << no.reason;
}

// A tracked edge is no more certain than its inliers' geometry: with many inliers the model's covariance
// (verify.sigma_position_m shrinking as sqrt(min_inliers / inliers)) would claim a few centimetres, and the
// graph would call a true loop an outlier; the edge's position sigma is the one the reason gives for its
// inliers, its rotation sigma scaled alike.
TEST(GeometricVerifier, ATrackedEdgeIsAsUncertainAsItsInliersGeometry) {
  Scene s = scene(Eigen::Isometry3d::Identity(), 7, camera_pose(0.5, 0.1, -0.2, 2 * kPi / 180));
  s.i.image = at_night(s.i.image, 5);
  const auto geometry_sigma_m = [](const VerifyResult& r) {
    const std::size_t at = r.reason.find("position sigma ");
    return at == std::string::npos ? -1.0 : std::stod(r.reason.substr(at + 15));
  };
  const VerifyResult first = GeometricVerifier(VerifyConfig{}, s.camera).verify(s.i, s.j, s.n);
  ASSERT_TRUE(first.verified && first.tracked) << first.reason;
  // A bound just above this edge's geometry: the model at its inliers, sigma_position_m sqrt(25 / inliers),
  // is then more certain than the geometry.
  VerifyConfig config;
  config.sigma_position_m = 1.25 * geometry_sigma_m(first);
  const VerifyResult r = GeometricVerifier(config, s.camera).verify(s.i, s.j, s.n);
  ASSERT_TRUE(r.verified && r.tracked) << r.reason;
  const double geometry_m = geometry_sigma_m(r);
  const double model_m = config.sigma_position_m * std::sqrt(25.0 / r.inliers);
  ASSERT_GT(geometry_m, model_m + 0.01)
      << "the premise: the model is more certain than the geometry; " << r.reason;
  EXPECT_NEAR(std::sqrt(r.cov(0, 0)), geometry_m, 0.006) << r.reason;
  EXPECT_NEAR(std::sqrt(r.cov(3, 3)) / std::sqrt(r.cov(0, 0)),
              config.sigma_rotation_rad / config.sigma_position_m, 1e-9);
}

// After a long loop the odometry's pose of i carries its heading drift: started where that pose sees
// j's points, the tracking misses them by tens of pixels and the loop is lost. The second
// start, j's points where they are (i sees the place as j did), verifies it, and the reason says which start
// failed first.
TEST(GeometricVerifier, TracksFromTheImagesWhenTheOdometrysRotationHasDrifted) {
  Scene s = scene(Eigen::Isometry3d::Identity(), 7, camera_pose(0.5, 0.1, -0.2, 2 * kPi / 180));
  s.i.image = at_night(s.i.image, 5);
  const GeometricVerifier verifier(VerifyConfig{}, s.camera);
  Eigen::Isometry3d T_drifted = s.j.T_w_b * s.T_j_i;
  T_drifted.linear() =
      T_drifted.linear() * Eigen::AngleAxisd(15 * kPi / 180, Eigen::Vector3d::UnitY()).matrix();
  const VerifyResult r = verifier.verify(verifier.detect(s.i.image), verifier.detect(s.j.image), s.j.T_w_b,
                                         verifier.detect(s.n.image), s.n.T_w_b, &T_drifted);
  ASSERT_TRUE(r.verified) << r.reason;
  EXPECT_TRUE(r.tracked);
  // The drifted start alone did not verify it (the premise of the second start).
  EXPECT_NE(r.reason.find("; from the images' rotation, after; tracked: "), std::string::npos) << r.reason;
  EXPECT_LT((r.T_j_i.translation() - s.T_j_i.translation()).norm(), 0.15);
  EXPECT_EQ(r.key, VerifyReason::kVerifiedByTracking);
}

// A revisit metres aside of a near facade at night: j's points move by the parallax of the offset, further
// than the tracking reaches on a noisy night image from where they are in j. Started where the odometry's
// pose of i sees j's triangulated points, the tracking verifies the loop with the metric pose.
TEST(GeometricVerifier, TracksFromWhereTheOdometrysPoseOfISeesTheNightImagesPoints) {
  Scene s = scene(Eigen::Isometry3d::Identity(), 7, camera_pose(2.4, 0.2, -0.3, 2 * kPi / 180));
  s.i.image = at_night(s.i.image, 5);
  const GeometricVerifier verifier(VerifyConfig{}, s.camera);
  const OrbFeatures fi = verifier.detect(s.i.image), fj = verifier.detect(s.j.image),
                    fn = verifier.detect(s.n.image);
  const VerifyResult from_j = verifier.verify(fi, fj, s.j.T_w_b, fn, s.n.T_w_b);
  EXPECT_FALSE(from_j.verified) << "tracked from where the points are in j: the test's premise is lost";
  // The odometry's pose of i, 0.2 m and 1 degree off the truth (its drift from j to i).
  Eigen::Isometry3d T_w_bi = s.j.T_w_b * s.T_j_i;
  T_w_bi.translation() += Eigen::Vector3d(0.15, -0.1, 0.08);
  T_w_bi.linear() = T_w_bi.linear() * Eigen::AngleAxisd(kPi / 180, Eigen::Vector3d::UnitZ()).matrix();
  const VerifyResult r = verifier.verify(fi, fj, s.j.T_w_b, fn, s.n.T_w_b, &T_w_bi);
  ASSERT_TRUE(r.verified) << r.reason;
  EXPECT_TRUE(r.tracked);
  EXPECT_LT((r.T_j_i.translation() - s.T_j_i.translation()).norm(), 0.15)
      << r.T_j_i.translation().transpose() << " vs " << s.T_j_i.translation().transpose();
  EXPECT_LT(Eigen::AngleAxisd(r.T_j_i.rotation().transpose() * s.T_j_i.rotation()).angle(), 0.02);
}

// A copy of j's place elsewhere (the aliasing preset's copied block), seen at night: the images agree with j,
// the odometry puts frame i 40 m away. Started from that pose, the points fall outside i or where nothing
// matches; started where they are in j, the tracking finds the copy, and the odometry check rejects the pose.
TEST(GeometricVerifier, AnAliasedNightViewIsRejectedByTheOdometry) {
  Scene s = scene(Eigen::Isometry3d::Identity(), 7, camera_pose(0.5, 0.1, -0.2, 2 * kPi / 180));
  s.i.image = at_night(s.i.image, 5);
  const GeometricVerifier verifier(VerifyConfig{}, s.camera);
  Eigen::Isometry3d T_w_bi = s.j.T_w_b * s.T_j_i;
  T_w_bi.translation() += Eigen::Vector3d(40.0, 0.0, 0.0);
  const auto veto = [&](const VerifyResult& loop) {
    return odometry_disagreement(T_w_bi, s.j.T_w_b, loop, 1.0, 0.6, VerifyConfig{}.odometry_chi2);
  };
  const VerifyResult r = verifier.verify(verifier.detect(s.i.image), verifier.detect(s.j.image), s.j.T_w_b,
                                         verifier.detect(s.n.image), s.n.T_w_b, &T_w_bi, veto);
  EXPECT_FALSE(r.verified) << r.reason;
  EXPECT_NE(r.reason.find("from the odometry's frame i"), std::string::npos) << r.reason;
  EXPECT_EQ(r.key, VerifyReason::kIllumination);  // the tracking ran and the odometry rejected its pose
  // Without the odometry check the images alone would take it: the check is what rejects it.
  const VerifyResult unchecked = verifier.verify(verifier.detect(s.i.image), verifier.detect(s.j.image),
                                                 s.j.T_w_b, verifier.detect(s.n.image), s.n.T_w_b, &T_w_bi);
  EXPECT_TRUE(unchecked.verified) << unchecked.reason;
}

TEST(GeometricVerifier, SkipsTinyImagesAndMissingCalibrationWithAReason) {
  CameraCalibration thumbs = calibration(Eigen::Isometry3d::Identity());
  thumbs.width_px = 64;
  thumbs.height_px = 32;
  const GeometricVerifier small(VerifyConfig{}, thumbs);
  const VerifyFrame f{cv::Mat(32, 64, CV_8UC1, cv::Scalar(100)), Eigen::Isometry3d::Identity()};
  VerifyFrame moved = f;
  moved.T_w_b.translation().x() = 1.0;
  const VerifyResult r = small.verify(f, f, moved);
  EXPECT_FALSE(r.verified);
  EXPECT_NE(r.reason.find("image too small for features (64x32"), std::string::npos) << r.reason;
  ASSERT_TRUE(small.unusable_reason(cv::Size(64, 32)).has_value());
  EXPECT_EQ(small.unusable_reason(cv::Size(64, 32))->key, VerifyReason::kImageTooSmall);
  EXPECT_FALSE(small.unusable_reason(cv::Size(640, 480)).has_value());

  const GeometricVerifier uncalibrated(VerifyConfig{}, std::nullopt);
  EXPECT_EQ(uncalibrated.verify(f, f, moved).reason, "geometry: no camera calibration");
  EXPECT_EQ(uncalibrated.verify(f, f, moved).key, VerifyReason::kNoCalibration);
  EXPECT_FALSE(uncalibrated.verify(VerifyFrame{}, f, moved).verified);
}

TEST(GeometricVerifier, ConfigErrorsNameTheKey) {
  const auto expect_error_naming = [](const std::string& key, auto&& set) {
    VerifyConfig config;
    set(config);
    try {
      config.validate();
      ADD_FAILURE() << key << ": no error";
    } catch (const ConfigError& e) {
      EXPECT_NE(std::string(e.what()).find("verify." + key), std::string::npos) << e.what();
    }
  };
  expect_error_naming("min_inliers", [](VerifyConfig& c) { c.min_inliers = 3; });
  expect_error_naming("track_window_px", [](VerifyConfig& c) { c.track_window_px = 20; });
  expect_error_naming("track_min_noise_ratio", [](VerifyConfig& c) { c.track_min_noise_ratio = 0.5; });
  expect_error_naming("odometry_chi2", [](VerifyConfig& c) { c.odometry_chi2 = -1.0; });
}

// A loop verified by the images, checked against the odometry: sigma^2 = sigma_i^2 - sigma_j^2 + the edge's
// largest position variance; the distance between the loop's frame i and the odometry's over sigma.
TEST(GeometricVerifier, ALoopFarFromWhereTheOdometryPutsFrameIIsRejected) {
  VerifyResult loop;
  loop.verified = true;
  loop.T_j_i = Eigen::Translation3d(2.0, 0.0, 0.0) * Eigen::Isometry3d::Identity();
  loop.cov = Eigen::Matrix<double, 6, 6>::Identity() * 0.01;
  loop.cov(1, 1) = 0.09;  // the largest position variance counts: edge sigma 0.3 m
  // Frame j faces +y (yaw 90 degrees): the loop puts frame i at (10, 22, 0).
  Eigen::Isometry3d T_w_bj = Eigen::Isometry3d::Identity();
  T_w_bj.linear() = Eigen::AngleAxisd(kPi / 2, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T_w_bj.translation() = Eigen::Vector3d(10.0, 20.0, 0.0);
  const auto at = [](double x, double y) {
    return Eigen::Isometry3d(Eigen::Translation3d(x, y, 0.0) * Eigen::Isometry3d::Identity());
  };
  // sigma^2 = 1.0^2 - 0.6^2 + 0.09 = 0.73; bound sqrt(16.27) = 4.03 sigma = 3.446 m.
  const double sigma = std::sqrt(0.73);
  const double bound = 16.27;
  EXPECT_EQ(odometry_disagreement(at(10.0, 22.0), T_w_bj, loop, 1.0, 0.6, bound), "");
  EXPECT_EQ(
      odometry_disagreement(at(10.0 + 0.99 * std::sqrt(bound) * sigma, 22.0), T_w_bj, loop, 1.0, 0.6, bound),
      "");
  EXPECT_EQ(
      odometry_disagreement(at(10.0 + 1.01 * std::sqrt(bound) * sigma, 22.0), T_w_bj, loop, 1.0, 0.6, bound)
          .rfind("geometry: 3.48 m from the odometry's frame i, 4.1 sigma > 4.03", 0),
      0u);
  // j's heading counts: without it the loop would put frame i at (12, 20), 1 m from this odometry position.
  EXPECT_NE(odometry_disagreement(at(13.0, 20.0), T_w_bj, loop, 1.0, 0.6, bound), "");
  // The copy of the place 40 m away (the aliasing preset's second street).
  EXPECT_EQ(odometry_disagreement(at(50.0, 22.0), T_w_bj, loop, 1.0, 0.6, bound),
            "geometry: 40.00 m from the odometry's frame i, 46.8 sigma > 4.03");
  // No growth from j to i: the edge's sigma alone (0.3 m, bound 1.21 m).
  EXPECT_EQ(odometry_disagreement(at(11.0, 22.0), T_w_bj, loop, 0.6, 0.6, bound), "");  // 3.3 sigma
  EXPECT_NE(odometry_disagreement(at(11.5, 22.0), T_w_bj, loop, 0.6, 0.6, bound), "");  // 5 sigma
  // Uncertainty that shrank from j to i: the odometry learnt where it is in between, no bound.
  EXPECT_EQ(odometry_disagreement(at(50.0, 22.0), T_w_bj, loop, 0.5, 0.6, bound), "");
  // No check: bound 0, or an odometry without a sigma.
  EXPECT_EQ(odometry_disagreement(at(50.0, 22.0), T_w_bj, loop, 1.0, 0.6, 0.0), "");
  EXPECT_EQ(odometry_disagreement(at(50.0, 22.0), T_w_bj, loop, 0.0, 0.0, bound), "");
  EXPECT_EQ(odometry_disagreement(at(50.0, 22.0), T_w_bj, loop, std::nan(""), 0.6, bound), "");
}

}  // namespace
}  // namespace loopgate
