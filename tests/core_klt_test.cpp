// build_klt_pyramid (core/klt.hpp) against cv::buildOpticalFlowPyramid: the same levels, the same
// bytes in every buffer, borders included, for images of every small shape, windows and level counts; and
// cv::calcOpticalFlowPyrLK gives the same points on either. scharr_derivatives against cv::Scharr.
#include <gtest/gtest.h>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>
#include <random>
#include <string>
#include <tuple>
#include <vector>

#include "core/klt.hpp"

namespace loopgate {
namespace {

cv::Mat random_image(int rows, int cols, std::mt19937& rng) {
  cv::Mat image(rows, cols, CV_8UC1);
  std::uniform_int_distribution<int> value(0, 255);
  for (int y = 0; y < rows; ++y)
    for (int x = 0; x < cols; ++x) image.at<std::uint8_t>(y, x) = static_cast<std::uint8_t>(value(rng));
  return image;
}

// A smooth image with texture (what a tracker sees), for the tracking comparison.
cv::Mat textured_image(int rows, int cols, std::mt19937& rng) {
  cv::Mat image = random_image(rows, cols, rng);
  cv::GaussianBlur(image, image, cv::Size(0, 0), 2.0);
  cv::normalize(image, image, 0, 255, cv::NORM_MINMAX);
  return image;
}

// The whole buffer behind a view `m` made with `border` on every side.
cv::Mat with_border(const cv::Mat& m, cv::Size border) {
  cv::Mat whole = m;
  whole.adjustROI(border.height, border.height, border.width, border.width);
  return whole;
}

// Empty when equal, else what differs.
std::string compare_pyramids(const std::vector<cv::Mat>& expected, const std::vector<cv::Mat>& actual,
                             cv::Size window) {
  if (expected.size() != actual.size())
    return "levels: " + std::to_string(expected.size()) + " mats expected, " + std::to_string(actual.size());
  for (std::size_t k = 0; k < expected.size(); ++k) {
    const std::string which = "mat " + std::to_string(k) + " (level " + std::to_string(k / 2) +
                              (k % 2 == 0 ? ", image)" : ", derivatives)");
    if (expected[k].size() != actual[k].size() || expected[k].type() != actual[k].type())
      return which + ": size or type differs";
    const cv::Mat a = with_border(expected[k], window);
    const cv::Mat b = with_border(actual[k], window);
    if (a.size() != b.size()) return which + ": border differs in size";
    if (cv::norm(a.reshape(1), b.reshape(1), cv::NORM_INF) != 0.0) return which + ": bytes differ";
  }
  return {};
}

TEST(CoreKltPyramid, EqualsOpenCVForEverySmallShapeWindowAndLevelCount) {
  std::mt19937 rng(7);
  for (int rows = 1; rows <= 41; rows += 4) {
    for (int cols = 1; cols <= 70; cols += 3) {
      const cv::Mat image = random_image(rows, cols, rng);
      for (const cv::Size window : {cv::Size(3, 3), cv::Size(5, 7), cv::Size(15, 15)}) {
        for (int levels = 0; levels <= 3; ++levels) {
          std::vector<cv::Mat> expected;
          std::vector<cv::Mat> actual;
          const int expected_top = cv::buildOpticalFlowPyramid(image, expected, window, levels);
          const int actual_top = build_klt_pyramid(image, window, levels, actual);
          SCOPED_TRACE(std::to_string(rows) + "x" + std::to_string(cols) + " window " +
                       std::to_string(window.width) + "x" + std::to_string(window.height) + " levels " +
                       std::to_string(levels));
          EXPECT_EQ(expected_top, actual_top);
          EXPECT_EQ(compare_pyramids(expected, actual, window), "");
        }
      }
    }
  }
}

TEST(CoreKltPyramid, EqualsOpenCVOnACameraSizedImageAndAView) {
  std::mt19937 rng(11);
  const cv::Mat image = random_image(480, 752, rng);
  const cv::Size window(15, 15);
  std::vector<cv::Mat> expected;
  std::vector<cv::Mat> actual;
  EXPECT_EQ(cv::buildOpticalFlowPyramid(image, expected, window, 4),
            build_klt_pyramid(image, window, 4, actual));
  EXPECT_EQ(compare_pyramids(expected, actual, window), "");
  // A view inside a larger image: the image around it fills the border as far as it reaches, as OpenCV does
  // (which tracks on the view itself when there is room; build_klt_pyramid copies it).
  const cv::Mat big = random_image(300, 400, rng);
  for (const cv::Rect roi : {cv::Rect(20, 20, 300, 200), cv::Rect(3, 5, 390, 290)}) {
    const cv::Mat view = big(roi);
    EXPECT_EQ(cv::buildOpticalFlowPyramid(view, expected, window, 2),
              build_klt_pyramid(view, window, 2, actual));
    EXPECT_EQ(compare_pyramids(expected, actual, window), "") << "view at " << roi.x << "," << roi.y;
    EXPECT_NE(actual[0].data, view.data) << "level 0 is always a copy (track_klt reads a row past it)";
  }
}

TEST(CoreKltPyramid, TracksTheSamePointsAsOpenCVsPyramid) {
  std::mt19937 rng(3);
  const cv::Mat previous = textured_image(240, 320, rng);
  cv::Mat next;
  const cv::Mat shift = (cv::Mat_<double>(2, 3) << 1, 0, 2.6, 0, 1, -1.3);
  cv::warpAffine(previous, next, shift, previous.size(), cv::INTER_LINEAR, cv::BORDER_REFLECT_101);
  std::vector<cv::Point2f> points;
  for (int y = 20; y < 220; y += 17)
    for (int x = 20; x < 300; x += 23) points.emplace_back(static_cast<float>(x), static_cast<float>(y));
  const cv::Size window(15, 15);
  std::vector<cv::Mat> cv_previous, cv_next, our_previous, our_next;
  cv::buildOpticalFlowPyramid(previous, cv_previous, window, 2);
  cv::buildOpticalFlowPyramid(next, cv_next, window, 2);
  build_klt_pyramid(previous, window, 2, our_previous);
  build_klt_pyramid(next, window, 2, our_next);
  std::vector<cv::Point2f> cv_points, our_points;
  std::vector<unsigned char> cv_status, our_status;
  cv::calcOpticalFlowPyrLK(cv_previous, cv_next, points, cv_points, cv_status, cv::noArray(), window, 2);
  cv::calcOpticalFlowPyrLK(our_previous, our_next, points, our_points, our_status, cv::noArray(), window, 2);
  ASSERT_EQ(cv_points.size(), our_points.size());
  int tracked = 0;
  for (std::size_t k = 0; k < points.size(); ++k) {
    EXPECT_EQ(cv_status[k], our_status[k]) << k;
    EXPECT_EQ(cv_points[k].x, our_points[k].x) << k;
    EXPECT_EQ(cv_points[k].y, our_points[k].y) << k;
    tracked += our_status[k];
  }
  EXPECT_GT(tracked, static_cast<int>(points.size()) / 2);  // the comparison is about tracked points
}

TEST(CoreKltPyramid, DerivativesAreScharrsWithReflectedEdges) {
  std::mt19937 rng(5);
  for (const cv::Size size :
       {cv::Size(1, 1), cv::Size(2, 3), cv::Size(17, 1), cv::Size(33, 9), cv::Size(64, 48)}) {
    const cv::Mat image = random_image(size.height, size.width, rng);
    cv::Mat deriv(image.size(), CV_16SC2);
    scharr_derivatives(image, deriv);
    cv::Mat dx, dy;
    cv::Scharr(image, dx, CV_16S, 1, 0, 1.0, 0.0, cv::BORDER_REFLECT_101);
    cv::Scharr(image, dy, CV_16S, 0, 1, 1.0, 0.0, cv::BORDER_REFLECT_101);
    cv::Mat ours[2];
    cv::split(deriv, ours);
    if (size.width > 1) {
      EXPECT_EQ(cv::norm(ours[0], dx, cv::NORM_INF), 0.0) << size;
    }
    if (size.height > 1) {
      EXPECT_EQ(cv::norm(ours[1], dy, cv::NORM_INF), 0.0) << size;
    }
  }
}

TEST(CoreKltPyramid, RejectsWhatItCannotBuild) {
  std::vector<cv::Mat> pyramid;
  EXPECT_THROW(build_klt_pyramid(cv::Mat(), cv::Size(15, 15), 2, pyramid), std::invalid_argument);
  EXPECT_THROW(build_klt_pyramid(cv::Mat(10, 10, CV_8UC3), cv::Size(15, 15), 2, pyramid),
               std::invalid_argument);
  EXPECT_THROW(build_klt_pyramid(cv::Mat(10, 10, CV_8UC1), cv::Size(2, 15), 2, pyramid),
               std::invalid_argument);
  cv::Mat wrong(5, 5, CV_16SC1);
  EXPECT_THROW(scharr_derivatives(cv::Mat(5, 5, CV_8UC1), wrong), std::invalid_argument);
}

// Points on a grid of a textured image, and the image moved by (dx, dy) and turned by `degrees`.
struct Scene {
  cv::Mat previous, next;
  std::vector<cv::Point2f> points;
};

Scene moved_scene(std::mt19937& rng, double dx, double dy, double degrees,
                  cv::Size size = cv::Size(320, 240)) {
  Scene s;
  s.previous = textured_image(size.height, size.width, rng);
  cv::Mat motion = cv::getRotationMatrix2D(cv::Point2f(size.width * 0.5F, size.height * 0.5F), degrees, 1.0);
  motion.at<double>(0, 2) += dx;
  motion.at<double>(1, 2) += dy;
  cv::warpAffine(s.previous, s.next, motion, size, cv::INTER_LINEAR, cv::BORDER_REFLECT_101);
  for (int y = 4; y < size.height - 4; y += 13)
    for (int x = 3; x < size.width - 3; x += 11)
      s.points.emplace_back(static_cast<float>(x) + 0.37F, static_cast<float>(y) + 0.61F);
  return s;
}

TEST(CoreKltTrack, FindsWhatOpenCVFindsToItsLastBits) {
  std::mt19937 rng(21);
  const cv::TermCriteria criteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 30, 0.01);
  std::size_t points = 0, same_status = 0, compared = 0, within = 0;
  double worst = 0.0;
  for (const cv::Size window : {cv::Size(15, 15), cv::Size(21, 21), cv::Size(9, 7)}) {
    for (const auto& [dx, dy, degrees] : {std::tuple{2.3, -1.7, 0.0}, std::tuple{7.9, 4.2, 3.0},
                                          std::tuple{-15.0, 9.5, -6.0}, std::tuple{0.2, 0.1, 0.5}}) {
      const Scene s = moved_scene(rng, dx, dy, degrees);
      for (int levels = 0; levels <= 3; ++levels) {
        std::vector<cv::Mat> cv_previous, cv_next, our_previous, our_next;
        cv::buildOpticalFlowPyramid(s.previous, cv_previous, window, levels);
        cv::buildOpticalFlowPyramid(s.next, cv_next, window, levels);
        build_klt_pyramid(s.previous, window, levels, our_previous);
        build_klt_pyramid(s.next, window, levels, our_next);
        std::vector<cv::Point2f> cv_found, our_found;
        std::vector<unsigned char> cv_status, our_status;
        cv::calcOpticalFlowPyrLK(cv_previous, cv_next, s.points, cv_found, cv_status, cv::noArray(), window,
                                 levels, criteria);
        track_klt(our_previous, our_next, s.points, our_found, our_status, window, levels, criteria, false);
        ASSERT_EQ(our_found.size(), s.points.size());
        for (std::size_t k = 0; k < s.points.size(); ++k) {
          ++points;
          same_status += cv_status[k] == our_status[k];
          if (cv_status[k] == 0 || our_status[k] == 0) continue;
          ++compared;
          const double d = cv::norm(cv_found[k] - our_found[k]);
          worst = std::max(worst, d);
          within += d <= 1e-3;
        }
      }
    }
  }
  // The sums differ from OpenCV's float sums in their last bits: the same points are lost, and 99% of the
  // positions agree to a thousandth of a pixel. The rest are points that have not converged in 30 steps (a
  // small window, a large motion), where one step more or fewer moves them by a few hundredths (measured:
  // 13 of 4 000 beyond 0.005 px, the worst 0.05 px).
  EXPECT_GE(same_status, points - points / 500) << "of " << points;
  EXPECT_GE(within, compared - compared / 100) << "of " << compared << ", worst " << worst << " px";
  EXPECT_LE(worst, 0.1) << "px";
  EXPECT_GT(compared, points / 2);
}

TEST(CoreKltTrack, GivesTheSameBitsWithAndWithoutAvx2) {
  std::mt19937 rng(8);
  const cv::TermCriteria criteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 30, 0.01);
  for (const cv::Size window :
       {cv::Size(15, 15), cv::Size(21, 21), cv::Size(9, 7), cv::Size(33, 5), cv::Size(101, 41)}) {
    const Scene s = moved_scene(rng, 5.3, -3.1, 2.0);
    std::vector<cv::Mat> previous, next;
    build_klt_pyramid(s.previous, window, 2, previous);
    build_klt_pyramid(s.next, window, 2, next);
    // Starts off the image and far out too: the losses must agree as well.
    std::vector<cv::Point2f> start = s.points;
    for (std::size_t k = 0; k < start.size(); k += 7) start[k] += cv::Point2f(40.0F, -25.0F);
    std::vector<cv::Point2f> a = start, b = start;
    std::vector<unsigned char> status_a, status_b;
    track_klt(previous, next, s.points, a, status_a, window, 2, criteria, true);
    track_klt_portable(previous, next, s.points, b, status_b, window, 2, criteria, true);
    EXPECT_EQ(status_a, status_b) << window;
    for (std::size_t k = 0; k < a.size(); ++k) {
      EXPECT_EQ(a[k].x, b[k].x) << window << " point " << k;
      EXPECT_EQ(a[k].y, b[k].y) << window << " point " << k;
    }
  }
}

TEST(CoreKltTrack, LosesPointsOffTheImageOrOnFlatGround) {
  const cv::Size window(15, 15);
  std::mt19937 rng(2);
  cv::Mat image = textured_image(120, 160, rng);
  image(cv::Rect(0, 0, 60, 60)).setTo(100);  // flat: no structure to track
  std::vector<cv::Mat> pyramid;
  build_klt_pyramid(image, window, 1, pyramid);
  const std::vector<cv::Point2f> points{{30.0F, 30.0F}, {-40.0F, 50.0F}, {100.0F, 80.0F}};
  std::vector<cv::Point2f> found{{30.0F, 30.0F}, {-40.0F, 50.0F}, {100.0F, 80.0F}};
  std::vector<unsigned char> status;
  track_klt(pyramid, pyramid, points, found, status, window, 1,
            cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 30, 0.01), true);
  EXPECT_EQ(status, (std::vector<unsigned char>{0, 0, 1}));
  EXPECT_NEAR(found[2].x, 100.0F, 1e-3F);  // the same image: found where it was
  EXPECT_NEAR(found[2].y, 80.0F, 1e-3F);
}

TEST(CoreKltTrack, RejectsPyramidsItDidNotBuild) {
  std::mt19937 rng(4);
  const cv::Mat image = textured_image(100, 100, rng);
  std::vector<cv::Mat> ours, opencv;
  build_klt_pyramid(image, cv::Size(15, 15), 1, ours);
  cv::buildOpticalFlowPyramid(image, opencv, cv::Size(15, 15), 1);
  const std::vector<cv::Point2f> points{{50.0F, 50.0F}};
  std::vector<cv::Point2f> found;
  std::vector<unsigned char> status;
  const cv::TermCriteria criteria(cv::TermCriteria::COUNT, 10, 0);
  EXPECT_THROW(track_klt(opencv, opencv, points, found, status, cv::Size(15, 15), 1, criteria, false),
               std::invalid_argument);  // no extra row
  EXPECT_THROW(track_klt(ours, ours, points, found, status, cv::Size(21, 21), 1, criteria, false),
               std::invalid_argument);  // another window
  EXPECT_THROW(track_klt(ours, ours, points, found, status, cv::Size(15, 15), 1, criteria, true),
               std::invalid_argument);  // no start for the point
  EXPECT_NO_THROW(track_klt(ours, ours, points, found, status, cv::Size(15, 15), 1, criteria, false));
}

}  // namespace
}  // namespace loopgate
