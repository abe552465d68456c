// An in-memory Dataset for the pipeline tests: frames at 10 Hz on a circle, 200 Hz IMU, generated
// images, and knobs for bad input (corrupt frames, an IMU gap, slow decoding, a crashing frame).
#pragma once

#include <chrono>
#include <cmath>
#include <opencv2/core.hpp>
#include <set>
#include <stdexcept>
#include <thread>

#include "core/error.hpp"
#include "io/dataset.hpp"

namespace loopgate::testing {

class FakeDataset : public Dataset {
 public:
  explicit FakeDataset(std::size_t frames, double frame_rate_hz = 10.0) : root_("/fake/dataset") {
    const auto period_ns = static_cast<Timestamp>(1e9 / frame_rate_hz);
    for (std::size_t i = 0; i < frames; ++i)
      times_.push_back(1'000'000'000 + static_cast<Timestamp>(i) * period_ns);
    for (Timestamp t = times_.front() - 50'000'000; t <= times_.back() + 50'000'000; t += 5'000'000) {
      ImuSample s;
      s.t_ns = t;
      s.gyro_radps = Eigen::Vector3d(0, 0, 0.1);
      s.accel_mps2 = Eigen::Vector3d(0, 0, 9.81);
      imu_.push_back(s);
    }
  }

  // Removes the IMU samples in (from_ns, to_ns): a gap.
  void cut_imu(Timestamp from_ns, Timestamp to_ns) {
    std::erase_if(imu_, [&](const ImuSample& s) { return s.t_ns > from_ns && s.t_ns < to_ns; });
  }
  void add_issue(const std::string& message) {
    issues_.push_back(DataIssue{root_ / "imu0/data.csv", 42, message});
  }

  std::set<std::size_t> corrupt_frames;   // load_image throws DataError
  std::set<std::size_t> crashing_frames;  // load_image throws std::runtime_error (escapes: cancels the graph)
  int decode_delay_ms = 0;

  std::string layout() const override { return "fake"; }
  const std::filesystem::path& root() const override { return root_; }
  std::size_t frame_count() const override { return times_.size(); }
  Timestamp frame_t_ns(std::size_t frame) const override { return times_.at(frame); }
  bool has_images() const override { return true; }
  std::filesystem::path image_path(std::size_t frame) const override {
    return root_ / ("image_" + std::to_string(frame) + ".png");
  }
  cv::Mat load_image(std::size_t frame) const override {
    if (decode_delay_ms > 0) std::this_thread::sleep_for(std::chrono::milliseconds(decode_delay_ms));
    if (corrupt_frames.count(frame))
      throw DataError(image_path(frame), "frame " + std::to_string(frame) + ": corrupt PNG");
    if (crashing_frames.count(frame)) throw std::runtime_error("decoder crashed");
    cv::Mat image(16, 32, CV_8UC1);
    for (int r = 0; r < image.rows; ++r) {
      for (int c = 0; c < image.cols; ++c)
        image.at<std::uint8_t>(r, c) = static_cast<std::uint8_t>((r * 7 + c * 3 + frame) % 256);
    }
    return image;
  }
  bool has_imu() const override { return true; }
  const std::vector<ImuSample>& imu_samples() const override { return imu_; }
  bool has_ground_truth() const override { return true; }
  std::optional<Eigen::Isometry3d> ground_truth_T_w_b(std::size_t frame) const override {
    const double theta = 0.02 * static_cast<double>(frame);
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.translation() = Eigen::Vector3d(50 * std::sin(theta), 50 * (1 - std::cos(theta)), 0);
    T.linear() = Eigen::AngleAxisd(theta, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    return T;
  }
  const std::vector<GroundTruthState>& ground_truth() const override { return ground_truth_; }
  std::optional<CameraCalibration> camera() const override { return std::nullopt; }
  std::optional<ImuCalibration> imu_calibration() const override { return std::nullopt; }
  const std::vector<DataIssue>& issues() const override { return issues_; }

 private:
  std::filesystem::path root_;
  std::vector<Timestamp> times_;
  std::vector<ImuSample> imu_;
  std::vector<GroundTruthState> ground_truth_;
  std::vector<DataIssue> issues_;
};

}  // namespace loopgate::testing
