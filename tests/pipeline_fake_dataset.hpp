// An in-memory Dataset for the pipeline tests: frames at 10 Hz on a circle, 200 Hz IMU, generated
// images, and knobs for bad input (corrupt frames, an IMU gap, slow decoding, a crashing frame).
#pragma once

#include <chrono>
#include <cmath>
#include <functional>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <set>
#include <stdexcept>
#include <thread>

#include "core/error.hpp"
#include "io/dataset.hpp"
#include "pipeline/pipeline_config.hpp"
#include "test_support.hpp"

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

  // Called first by load_image with the frame: a test's event (a stop request once frame N is read).
  std::function<void(std::size_t)> on_load;
  std::set<std::size_t> corrupt_frames;   // load_image throws DataError
  std::set<std::size_t> crashing_frames;  // load_image throws std::runtime_error (escapes: cancels the graph)
  int decode_delay_ms = 0;
  bool images = true;  // false: a dataset without images (trajectory and IMU only)

  DatasetLayout layout() const override { return DatasetLayout::kMemory; }
  const std::filesystem::path& root() const override { return root_; }
  std::size_t frame_count() const override { return times_.size(); }
  Timestamp frame_t_ns(std::size_t frame) const override { return times_.at(frame); }
  bool has_images() const override { return images; }
  std::filesystem::path image_path(std::size_t frame) const override {
    return root_ / ("image_" + std::to_string(frame) + ".png");
  }
  cv::Mat load_image(std::size_t frame) const override {
    if (on_load) on_load(frame);
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

// A drive around a circle of `period` frames, `laps` times: frame k shows place k % period (a random
// texture seeded by the place) with a little noise that differs per lap, and sits on the circle at the
// place's position; so frame i revisits frame i - period. `noise_seed` changes the per-lap noise only.
// Frames in [detour_begin, detour_end) keep their images but are 500 m away (ground truth and hence
// odometry): perceptual aliasing, the same views in a far place.
class RevisitDataset : public FakeDataset {
 public:
  RevisitDataset(std::size_t period, std::size_t laps, int noise_seed = 0)
      : FakeDataset(period * laps), period_(period), noise_seed_(noise_seed) {}

  cv::Mat load_image(std::size_t frame) const override {
    if (on_load) on_load(frame);
    if (corrupt_frames.count(frame))
      throw DataError(image_path(frame), "frame " + std::to_string(frame) + ": corrupt PNG");
    const std::size_t place = frame % period_;
    const std::size_t lap = frame / period_;
    cv::Mat small(8, 16, CV_8UC1);
    cv::RNG place_rng(0x9e3779b9u + static_cast<std::uint64_t>(place));
    place_rng.fill(small, cv::RNG::UNIFORM, 0, 256);
    cv::Mat image;
    cv::resize(small, image, cv::Size(64, 32), 0, 0, cv::INTER_LINEAR);
    cv::Mat noise(image.size(), CV_16SC1);
    cv::RNG noise_rng(static_cast<std::uint64_t>(1000003 * (lap + 1) + 7919 * frame) +
                      static_cast<std::uint64_t>(noise_seed_));
    noise_rng.fill(noise, cv::RNG::UNIFORM, -6, 7);
    cv::Mat noisy;
    image.convertTo(noisy, CV_16SC1);
    noisy += noise;
    noisy.convertTo(image, CV_8UC1);  // saturating
    return image;
  }
  std::optional<Eigen::Isometry3d> ground_truth_T_w_b(std::size_t frame) const override {
    const double theta = 2.0 * M_PI * static_cast<double>(frame % period_) / static_cast<double>(period_);
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.translation() = Eigen::Vector3d(30 * std::sin(theta), 30 * (1 - std::cos(theta)), 0);
    if (frame >= detour_begin && frame < detour_end) T.translation().x() += 500.0;
    T.linear() = Eigen::AngleAxisd(theta, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    return T;
  }

  std::size_t detour_begin = 0, detour_end = 0;

 private:
  std::size_t period_;
  int noise_seed_;
};

// Three laps of `period` frames whose frames [begin, end) are 500 m away: the same views in a far place.
inline RevisitDataset detour_dataset(std::size_t period, std::size_t begin, std::size_t end) {
  RevisitDataset dataset(period, 3);
  dataset.detour_begin = begin;
  dataset.detour_end = end;
  return dataset;
}

// The keys every pipeline test over RevisitDataset's 120-frame laps shares: `method` in `mode` on `threads`,
// drift odometry small enough that a detour's 500 m each way, counted as distance driven, does not shrink the
// combined distance of its frames below the gate's threshold; margin 30 and sequences of 10 frames; the
// gate's gap, beta and area margins for such a lap. Each test sets its method's own keys.
inline PipelineConfig revisit_config(Detector method, RunMode mode, int threads = 2) {
  PipelineConfig config;
  config.run.method = method;
  config.run.mode = mode;
  config.run.threads = threads;
  config.output.progress = Progress::kOff;
  config.odometry.source =
      OdometrySourceKind::kDrift;  // ground truth + a random-walk drift, sigma growing with distance
  config.odometry.drift_position_sigma_m_per_sqrt_m = 0.001;
  config.odometry.drift_heading_sigma_rad_per_sqrt_m = 0.00005;
  config.odometry.drift_scale_sigma_per_sqrt_m = 0.0001;
  config.match.margin = 30;
  config.match.sequence_length = 10;
  config.gate.gap_frames = 30;
  config.gate.beta_m = 5.0;
  config.gate.area_margin_query_frames = 10;
  config.gate.area_margin_reference_frames = 10;
  config.gate.area_max_hole_frames = 5;
  config.gate.row_horizon_frames = 20;
  return config;
}

// Causal standardisation that warms up within RevisitDataset's first lap.
inline void small_standardize(StandardizeConfig& standardize) {
  standardize.warm_up = 20;
  standardize.window = 40;
  standardize.refresh_every = 3;
  standardize.observe_every = 2;
}

// candidate_cells.csv (rows i, j0, j1) as the set of its (i, j) cells.
inline std::set<std::pair<std::int64_t, std::int64_t>> read_cells(const std::filesystem::path& file) {
  std::set<std::pair<std::int64_t, std::int64_t>> cells;
  for (const auto& row : read_csv(file)) {
    const std::int64_t i = std::stoll(row[0]);
    for (std::int64_t j = std::stoll(row[1]); j <= std::stoll(row[2]); ++j) cells.insert({i, j});
  }
  return cells;
}

}  // namespace loopgate::testing
