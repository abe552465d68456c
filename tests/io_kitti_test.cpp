// KITTI odometry reader: generated sequences (normal layout, poses/NN.txt, the official tree, a subset
// folder without times.txt, damaged parts) and the shared kitti/00 thumbs, frames and metadata.
#include <gtest/gtest.h>
#include <spdlog/sinks/ostream_sink.h>
#include <spdlog/spdlog.h>

#include <cstdio>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>

#include "core/error.hpp"
#include "io/dataset.hpp"
#include "io/trajectory_io.hpp"
#include "test_support.hpp"

namespace loopgate {
namespace {

namespace fs = std::filesystem;

constexpr int kWidth = 48;
constexpr int kHeight = 16;
constexpr int kFrames = 10;
constexpr Timestamp kPeriod = 103'735'900;

void write_file(const fs::path& file, const std::string& text) {
  fs::create_directories(file.parent_path());
  std::ofstream(file, std::ios::binary) << text;
}

std::string image_name(int i) {
  char name[16];
  std::snprintf(name, sizeof(name), "%06d.png", i);
  return name;
}

cv::Mat frame_image(int i, int width = kWidth) {
  cv::Mat image(kHeight, width, CV_8UC1, cv::Scalar(static_cast<double>(10 + i)));
  image.at<unsigned char>(0, 0) = static_cast<unsigned char>(200 + i);
  return image;
}

Eigen::Isometry3d pose(int i) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::AngleAxisd(0.05 * i, Eigen::Vector3d::UnitY()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(0.1 * i, 0.0, 0.9 * i);
  return T;
}

const char* kCalib =
    "P0: 7.188560000000e+02 0 6.071928000000e+02 0 0 7.188560000000e+02 1.852157000000e+02 0 0 0 1 0\n"
    "P1: 7.188560000000e+02 0 6.071928000000e+02 -3.861448000000e+02 0 7.188560000000e+02 1.852157000000e+02 "
    "0 "
    "0 0 1 0\n";

// Sequence metadata (times, poses, calib) in `meta`, images of `indices` in `image_dir`.
void make_kitti(const fs::path& meta, const fs::path& image_dir, const std::vector<int>& indices,
                const fs::path& poses_file) {
  std::vector<Timestamp> times;
  std::vector<Eigen::Isometry3d> poses;
  for (int i = 0; i < kFrames; ++i) {
    times.push_back(i * kPeriod);
    poses.push_back(pose(i));
  }
  write_kitti_times(meta / "times.txt", times);
  write_kitti_poses(poses_file, poses);
  write_file(meta / "calib.txt", kCalib);
  fs::create_directories(image_dir);
  for (const int i : indices) cv::imwrite((image_dir / image_name(i)).string(), frame_image(i));
}

std::vector<int> all_frames() {
  std::vector<int> v;
  for (int i = 0; i < kFrames; ++i) v.push_back(i);
  return v;
}

using testing::catch_data_error;

TEST(IoKitti, GeneratedSequence) {
  const fs::path dir = testing::make_temp_dir("io-kitti") / "05";
  make_kitti(dir, dir / "image_0", all_frames(), dir / "poses.txt");
  const auto d = open_dataset(dir);
  EXPECT_EQ(d->layout(), DatasetLayout::kKitti);
  ASSERT_EQ(d->frame_count(), static_cast<std::size_t>(kFrames));
  EXPECT_TRUE(d->has_images());
  EXPECT_FALSE(d->has_imu());
  EXPECT_TRUE(d->imu_samples().empty());
  EXPECT_FALSE(d->imu_calibration());
  for (std::size_t i = 0; i < d->frame_count(); ++i) {
    const int k = static_cast<int>(i);
    EXPECT_EQ(d->frame_t_ns(i), k * kPeriod);
    EXPECT_EQ(d->source_index(i), i);
    const cv::Mat image = d->load_image(i);
    EXPECT_EQ(cv::norm(image, frame_image(k), cv::NORM_INF), 0.0);
    const auto T = d->ground_truth_T_w_b(i);
    ASSERT_TRUE(T);
    EXPECT_EQ(T->matrix(), pose(k).matrix());  // frame times are pose times: no interpolation
  }
  ASSERT_TRUE(d->camera());
  EXPECT_EQ(d->camera()->width_px, kWidth);  // from the first image
  EXPECT_EQ(d->camera()->height_px, kHeight);
  EXPECT_DOUBLE_EQ(d->camera()->fx, 718.856);
  EXPECT_DOUBLE_EQ(d->camera()->cy, 185.2157);
  EXPECT_NEAR(d->camera()->rate_hz, 1e9 / static_cast<double>(kPeriod), 1e-9);
  EXPECT_TRUE(d->camera()->T_b_c.matrix().isIdentity(0.0));  // body = camera 0
  EXPECT_EQ(d->camera()->distortion_model, DistortionModel::kNone);
}

TEST(IoKitti, RightCameraAndPoseLocations) {
  const fs::path root = testing::make_temp_dir("io-kitti-tree");
  // Official tree: dataset/sequences/07/{image_0,image_1,times.txt,calib.txt}, dataset/poses/07.txt.
  const fs::path seq = root / "dataset/sequences/07";
  make_kitti(seq, seq / "image_0", all_frames(), root / "dataset/poses/07.txt");
  make_kitti(seq, seq / "image_1", all_frames(), root / "dataset/poses/07.txt");
  OpenOptions right;
  right.camera_index = 1;
  const auto d = open_kitti(seq, right);
  EXPECT_EQ(d->image_path(3).parent_path().filename(), "image_1");
  EXPECT_NEAR(d->camera()->T_b_c.translation().x(), 0.537165, 1e-6);
  ASSERT_TRUE(d->has_ground_truth());
  EXPECT_EQ(d->ground_truth_T_w_b(4)->matrix(), pose(4).matrix());
  // poses/NN.txt inside the sequence folder.
  const fs::path seq2 = root / "flat/03";
  make_kitti(seq2, seq2 / "image_0", all_frames(), seq2 / "poses/03.txt");
  EXPECT_EQ(open_kitti(seq2)->ground_truth().size(), static_cast<std::size_t>(kFrames));
  // No poses and no calib at all: still a dataset.
  fs::remove_all(seq2 / "poses");
  fs::remove(seq2 / "calib.txt");
  const auto bare = open_kitti(seq2);
  EXPECT_FALSE(bare->has_ground_truth());
  EXPECT_FALSE(bare->camera());
  EXPECT_FALSE(bare->ground_truth_T_w_b(0));
  EXPECT_EQ(bare->load_image(2).cols, kWidth);
}

// kitti/00/frames-like: images 0, 4, 9 in a subfolder, times/poses/calib one level up.
TEST(IoKitti, SubsetFolderTakesMetadataFromParent) {
  const fs::path seq = testing::make_temp_dir("io-kitti-subset") / "00";
  make_kitti(seq, seq / "frames/image_0", {0, 4, 9}, seq / "poses.txt");
  const auto d = open_dataset(seq / "frames");
  EXPECT_EQ(d->layout(), DatasetLayout::kKitti);
  ASSERT_EQ(d->frame_count(), 3u);
  const std::vector<int> expected = {0, 4, 9};
  for (std::size_t i = 0; i < 3; ++i) {
    EXPECT_EQ(d->source_index(i), static_cast<std::size_t>(expected[i]));
    EXPECT_EQ(d->frame_t_ns(i), expected[i] * kPeriod);
    EXPECT_EQ(d->ground_truth_T_w_b(i)->matrix(), pose(expected[i]).matrix());
    EXPECT_EQ(cv::norm(d->load_image(i), frame_image(expected[i]), cv::NORM_INF), 0.0);
  }
  EXPECT_EQ(d->ground_truth().size(), static_cast<std::size_t>(kFrames));  // the whole trajectory
  // Every row of the parent's times.txt by its frame number: what times a 12-column odometry.file.
  const auto source_times = d->source_times();
  ASSERT_EQ(source_times.size(), static_cast<std::size_t>(kFrames));
  for (int i = 0; i < kFrames; ++i) EXPECT_EQ(source_times[static_cast<std::size_t>(i)], i * kPeriod);
  ASSERT_TRUE(d->camera());
  EXPECT_EQ(d->camera()->width_px, kWidth);
  // The parent alone (no images) is a KITTI dataset with timestamps and poses only.
  const auto meta = open_dataset(seq);
  EXPECT_EQ(meta->layout(), DatasetLayout::kKitti);
  EXPECT_EQ(meta->frame_count(), static_cast<std::size_t>(kFrames));
  EXPECT_FALSE(meta->has_images());
  EXPECT_THROW(meta->load_image(0), DataError);
}

TEST(IoKitti, BadInput) {
  const fs::path root = testing::make_temp_dir("io-kitti-bad");
  // No times.txt anywhere.
  fs::create_directories(root / "a/image_0");
  cv::imwrite((root / "a/image_0/000000.png").string(), frame_image(0));
  const DataError e1 = catch_data_error([&] { open_kitti(root / "a"); });
  EXPECT_NE(std::string(e1.what()).find("times.txt not found"), std::string::npos) << e1.what();
  EXPECT_THROW(open_kitti(root / "missing"), DataError);

  const fs::path seq = root / "b";
  make_kitti(seq, seq / "image_0", all_frames(), seq / "poses.txt");
  // A stray image name and an image beyond times.txt: errors in strict mode, issues in lenient mode.
  cv::imwrite((seq / "image_0/extra.png").string(), frame_image(0));
  cv::imwrite((seq / "image_0" / image_name(kFrames)).string(), frame_image(0));
  const DataError e2 = catch_data_error([&] { open_kitti(seq); });
  EXPECT_EQ(e2.file().filename(), image_name(kFrames));  // natural order: digits before letters
  EXPECT_NE(e2.message().find("image 10 has no row in"), std::string::npos) << e2.what();
  OpenOptions lenient;
  lenient.strict = false;
  const auto d = open_kitti(seq, lenient);
  EXPECT_EQ(d->frame_count(), static_cast<std::size_t>(kFrames));
  ASSERT_EQ(d->issues().size(), 2u);
  EXPECT_NE(d->issues()[1].message.find("not a frame number"), std::string::npos)
      << d->issues()[1].to_string();
  EXPECT_EQ(d->issues()[1].file.filename(), "extra.png");
  fs::remove(seq / "image_0/extra.png");
  fs::remove(seq / "image_0" / image_name(kFrames));

  // A missing image and a wrong-size image fail their frame only.
  fs::remove(seq / "image_0" / image_name(3));
  cv::imwrite((seq / "image_0" / image_name(5)).string(), frame_image(5, kWidth * 2));
  const auto d2 = open_kitti(seq);
  EXPECT_EQ(d2->frame_count(), static_cast<std::size_t>(kFrames));
  const DataError e3 = catch_data_error([&] { d2->load_image(3); });
  EXPECT_EQ(e3.file().filename(), image_name(3));
  EXPECT_NE(e3.message().find("frame 3: image file missing"), std::string::npos);
  const DataError e4 = catch_data_error([&] { d2->load_image(5); });
  EXPECT_NE(e4.message().find("frame 5: image is 96x16, expected 48x16 like most frames"), std::string::npos)
      << e4.what();
  EXPECT_EQ(d2->load_image(4).cols, kWidth);

  // Damaged times.txt: strict throws with the line; lenient drops that frame only (indices keep).
  std::string text;
  for (int i = 0; i < kFrames; ++i) {
    char row[32];
    std::snprintf(row, sizeof(row), "%.9f\n", ns_to_s(i * kPeriod));
    text += i == 2 ? std::string("abc\n") : std::string(row);
  }
  write_file(seq / "times.txt", text);
  const DataError e5 = catch_data_error([&] { open_kitti(seq); });
  EXPECT_EQ(e5.line(), 3u);
  EXPECT_NE(e5.message().find("expected a finite time in seconds, got 'abc'"), std::string::npos)
      << e5.what();
  const auto d3 = open_kitti(seq, lenient);
  EXPECT_EQ(d3->frame_count(), static_cast<std::size_t>(kFrames - 1));
  EXPECT_EQ(d3->source_index(2), 3u);
  EXPECT_EQ(d3->frame_t_ns(2), 3 * kPeriod);
  EXPECT_EQ(d3->ground_truth_T_w_b(2)->matrix(), pose(3).matrix());

  // Poses with fewer rows than times: strict error naming both counts; lenient ground truth ends early.
  std::vector<Timestamp> times;
  for (int i = 0; i < kFrames; ++i) times.push_back(i * kPeriod);
  write_kitti_times(seq / "times.txt", times);
  write_kitti_poses(seq / "poses.txt", {pose(0), pose(1)});
  const DataError e6 = catch_data_error([&] { open_kitti(seq); });
  EXPECT_EQ(e6.file().filename(), "poses.txt");
  EXPECT_NE(e6.message().find("2 poses, expected 10"), std::string::npos) << e6.what();
  const auto d4 = open_kitti(seq, lenient);
  EXPECT_EQ(d4->ground_truth().size(), 2u);
  EXPECT_TRUE(d4->ground_truth_T_w_b(1));
  EXPECT_FALSE(d4->ground_truth_T_w_b(5));
}

// KITTI's colour cameras (data_odometry_color: image_2/ and image_3/ only, no image_0/): camera_index 2 or 3
// picks the folder and calib.txt's P2 / P3; the colour images are read as grey.
TEST(IoKitti, ColourCameras) {
  const fs::path seq = testing::make_temp_dir("io-kitti-colour") / "00";
  make_kitti(seq, seq / "image_2", {}, seq / "poses.txt");
  // KITTI 00's calib.txt rows P2 and P3 (camera 2 sits 6 cm left of camera 0, camera 3 47 cm right).
  write_file(seq / "calib.txt",
             std::string(kCalib) +
                 "P2: 7.188560000000e+02 0 6.071928000000e+02 4.538225000000e+01 0 7.188560000000e+02 "
                 "1.852157000000e+02 -1.130887000000e-01 0 0 1 3.779761000000e-03\n"
                 "P3: 7.188560000000e+02 0 6.071928000000e+02 -3.372877000000e+02 0 7.188560000000e+02 "
                 "1.852157000000e+02 2.369057000000e+00 0 0 1 4.915215000000e-03\n");
  for (const char* folder : {"image_2", "image_3"}) {
    fs::create_directories(seq / folder);
    for (int i = 0; i < kFrames; ++i) {
      cv::Mat colour(kHeight, kWidth, CV_8UC3, cv::Scalar(10 + i, 100, 200 - i));  // BGR
      if (folder[6] == '3') colour.setTo(cv::Scalar(200 - i, 100, 10 + i));
      cv::imwrite((seq / folder / image_name(i)).string(), colour);
    }
  }
  for (const int camera : {2, 3}) {
    OpenOptions options;
    options.camera_index = camera;
    const auto d = open_dataset(seq, options);  // found as KITTI by image_2/ and image_3/ alone
    EXPECT_EQ(d->layout(), DatasetLayout::kKitti);
    ASSERT_EQ(d->frame_count(), static_cast<std::size_t>(kFrames));
    EXPECT_EQ(d->image_path(4).parent_path().filename(), "image_" + std::to_string(camera));
    const cv::Mat grey = d->load_image(4);
    ASSERT_EQ(grey.type(), CV_8UC1);
    cv::Mat expected;
    cv::cvtColor(cv::imread((seq / ("image_" + std::to_string(camera)) / image_name(4)).string()), expected,
                 cv::COLOR_BGR2GRAY);
    EXPECT_EQ(cv::norm(grey, expected, cv::NORM_INF), 0.0);
    ASSERT_TRUE(d->camera());
    // The camera's offset from camera 0 (the body): -K^-1 P[:, 3] of its row.
    const double x_m = camera == 2 ? -(45.38225 - 607.1928 * 3.779761e-3) / 718.856
                                   : -(-337.2877 - 607.1928 * 4.915215e-3) / 718.856;
    EXPECT_NEAR(d->camera()->T_b_c.translation().x(), x_m, 1e-12) << camera;
    EXPECT_NEAR(d->camera()->T_b_c.translation().x(), camera == 2 ? -0.06 : 0.47, 0.01);
    EXPECT_EQ(d->ground_truth_T_w_b(4)->matrix(), pose(4).matrix());  // ground truth stays camera 0's
  }
  OpenOptions bad;
  bad.camera_index = 4;
  EXPECT_THROW(open_kitti(seq, bad), ConfigError);

  // The default camera 0 on this colour-only tree: the warning names the folder and the key to set.
  std::ostringstream log;
  const auto sink = std::make_shared<spdlog::sinks::ostream_sink_mt>(log);
  spdlog::default_logger()->sinks().push_back(sink);
  const auto grey_default = open_dataset(seq);
  spdlog::default_logger()->sinks().pop_back();
  EXPECT_FALSE(grey_default->has_images());
  EXPECT_NE(log.str().find("but image_2/ is there: set run.camera_index=2 to read it"), std::string::npos)
      << log.str();
}

// Pose files with 13 columns, a time in seconds first: each pose is timed by itself (the rows need not be one
// per frame) and interpolated to the frame times.
TEST(IoKitti, PosesWithTimeColumn) {
  const fs::path seq = testing::make_temp_dir("io-kitti-timed") / "04";
  make_kitti(seq, seq / "image_0", all_frames(), seq / "poses.txt");
  std::string text = "# t_s r11 r12 r13 tx r21 r22 r23 ty r31 r32 r33 tz\n";
  for (int i = 0; i < kFrames; i += 2) {  // every other frame
    const Eigen::Matrix4d M = pose(i).matrix();
    char time[32];
    std::snprintf(time, sizeof(time), "%.9f", ns_to_s(i * kPeriod));
    text += time;
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 4; ++c) text += " " + std::to_string(M(r, c));
    }
    text += "\n";
  }
  write_file(seq / "poses.txt", text);
  const auto d = open_kitti(seq);
  ASSERT_EQ(d->ground_truth().size(), static_cast<std::size_t>(kFrames / 2));
  EXPECT_EQ(d->ground_truth()[1].t_ns, 2 * kPeriod);
  EXPECT_TRUE(d->ground_truth_T_w_b(4)->matrix().isApprox(pose(4).matrix(), 1e-6));
  const Eigen::Isometry3d between = *d->ground_truth_T_w_b(3);  // interpolated between frames 2 and 4
  EXPECT_NEAR(between.translation().z(), 0.9 * 3, 1e-5);
  EXPECT_TRUE(d->issues().empty());
  // The public reader takes the times from the file too (times.txt is not needed).
  const auto poses = read_kitti_poses(seq / "poses.txt", seq / "no-such-times.txt");
  ASSERT_EQ(poses.size(), static_cast<std::size_t>(kFrames / 2));
  EXPECT_EQ(poses[2].t_ns, 4 * kPeriod);
}

TEST(IoKitti, PoseColumnCountErrorsNameFileAndLine) {
  const fs::path seq = testing::make_temp_dir("io-kitti-columns") / "02";
  make_kitti(seq, seq / "image_0", all_frames(), seq / "poses.txt");
  const std::string twelve = "1 0 0 0 0 1 0 0 0 0 1 0";
  // A 14-column row: neither format (first data row), or not the format of the first row.
  write_file(seq / "poses.txt", "# poses\n0.2 " + twelve + " 7\n" + twelve + "\n");
  const DataError e1 = catch_data_error([&] { open_kitti(seq); });
  EXPECT_EQ(e1.file(), seq / "poses.txt");
  EXPECT_EQ(e1.line(), 2u);
  EXPECT_NE(
      e1.message().find("expected 12 columns (row-major 3x4 T_w_cam0) or 13 (time [s], then the 12), got 14"),
      std::string::npos)
      << e1.what();
  write_file(seq / "poses.txt", twelve + "\n" + twelve + "\n0.2 " + twelve + " 7\n");
  const DataError e1b = catch_data_error([&] { open_kitti(seq); });
  EXPECT_EQ(e1b.line(), 3u);
  EXPECT_NE(e1b.message().find("expected 12 columns like the first data row (no time), got 14"),
            std::string::npos)
      << e1b.what();
  // A 12-column row in a 13-column file.
  write_file(seq / "poses.txt", "0.0 " + twelve + "\n0.1 " + twelve + "\n\n" + twelve + "\n");
  const DataError e2 = catch_data_error([&] { open_kitti(seq); });
  EXPECT_EQ(e2.line(), 4u);
  EXPECT_NE(e2.message().find("expected 13 columns like the first data row (a time first), got 12"),
            std::string::npos)
      << e2.what();
  // Times going back in a 13-column file.
  write_file(seq / "poses.txt",
             "0.0 " + twelve + "\n0.2 " + twelve + "\n0.1 " + twelve + "\n0.3 " + twelve + "\n");
  const DataError e3 = catch_data_error([&] { open_kitti(seq); });
  EXPECT_EQ(e3.line(), 3u);
  EXPECT_NE(e3.message().find("time 0.100000000 s is before line 2"), std::string::npos) << e3.what();
  // Lenient: the bad row is skipped and recorded, the others are the ground truth.
  OpenOptions lenient;
  lenient.strict = false;
  const auto d = open_kitti(seq, lenient);
  EXPECT_EQ(d->ground_truth().size(), 3u);
  ASSERT_EQ(d->issues().size(), 1u);
  EXPECT_EQ(d->issues()[0].line, 3u);
}

TEST(IoKitti, RealThumbs) {
  LOOPGATE_REQUIRE_SHARED_DATA("kitti/00/thumbs/image_0");
  const auto d = open_dataset(testing::shared_data_dir() / "kitti/00/thumbs");
  EXPECT_EQ(d->layout(), DatasetLayout::kKitti);
  ASSERT_EQ(d->frame_count(), 4540u);
  EXPECT_TRUE(d->has_images());
  EXPECT_EQ(d->frame_t_ns(1), 103735900);
  for (const std::size_t i : {0u, 1234u, 4539u}) {
    const cv::Mat image = d->load_image(i);
    EXPECT_EQ(image.cols, 64);
    EXPECT_EQ(image.rows, 32);
    double max_value = 0;
    cv::minMaxLoc(image, nullptr, &max_value);
    EXPECT_LE(max_value, 135.0);  // SeqSLAM-normalised thumbnails
    EXPECT_GT(max_value, 0.0);
  }
  EXPECT_FALSE(d->camera());  // no calib.txt for thumbnails
  ASSERT_TRUE(d->has_ground_truth());
  EXPECT_EQ(d->ground_truth().size(), 4540u);
  const auto T1 = d->ground_truth_T_w_b(1);
  ASSERT_TRUE(T1);
  EXPECT_DOUBLE_EQ(T1->translation().z(), 8.586941e-01);
  EXPECT_DOUBLE_EQ((*T1)(0, 3), -4.690294e-02);
  EXPECT_TRUE(d->issues().empty());
}

TEST(IoKitti, RealFramesSubset) {
  LOOPGATE_REQUIRE_SHARED_DATA("kitti/00/frames/image_0");
  const fs::path seq = testing::shared_data_dir() / "kitti/00";
  const auto d = open_dataset(seq / "frames");
  ASSERT_EQ(d->frame_count(), 3u);
  const auto times = read_kitti_times(seq / "times.txt");
  const auto poses = read_kitti_poses(seq / "poses.txt", seq / "times.txt");
  for (std::size_t i = 0; i < 3; ++i) {
    EXPECT_EQ(d->source_index(i), 1000 * i);
    EXPECT_EQ(d->frame_t_ns(i), times[1000 * i]);
    EXPECT_EQ(d->ground_truth_T_w_b(i)->matrix(), poses[1000 * i].T_w_b.matrix());
    const cv::Mat image = d->load_image(i);
    EXPECT_EQ(image.cols, 1241);
    EXPECT_EQ(image.rows, 376);
  }
  ASSERT_TRUE(d->camera());
  EXPECT_EQ(d->camera()->width_px, 1241);
  EXPECT_EQ(d->camera()->height_px, 376);
  EXPECT_DOUBLE_EQ(d->camera()->fx, 718.856);
  EXPECT_DOUBLE_EQ(d->camera()->cx, 607.1928);
  OpenOptions right;
  right.camera_index = 1;
  const auto r = open_dataset(seq / "frames", right);
  EXPECT_EQ(r->frame_count(), 3u);
  EXPECT_NEAR(r->camera()->T_b_c.translation().x(), 386.1448 / 718.856, 1e-12);
  EXPECT_EQ(r->load_image(2).cols, 1241);
}

TEST(IoKitti, RealSequenceMetadataOnly) {
  LOOPGATE_REQUIRE_SHARED_DATA("kitti/00/times.txt");
  const auto d = open_dataset(testing::shared_data_dir() / "kitti/00");
  EXPECT_EQ(d->frame_count(), 4541u);
  EXPECT_FALSE(d->has_images());
  EXPECT_EQ(d->ground_truth().size(), 4541u);
  EXPECT_NEAR(d->camera()->rate_hz, 9.65, 0.05);
}

}  // namespace
}  // namespace loopgate
