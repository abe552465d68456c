// Per-frame cost of the ekf source at 752 x 480: the KLT front end on real EuRoC images, the MSCKF on a
// simulated scene (~150 features, window 11), and optionally a whole rendered EuRoC-layout dataset
// (LOOPGATE_EKF_DATASET=<dir>, e.g. rendered by `loopgate simulate --preset euroc-mh05`) with the ATE.
// OpenCV runs on one thread here (cv::setNumThreads(1)): the figures are single-core costs. With
// LOOPGATE_EKF_DATASET set, BM_EkfTracking tracks the first 400 images of that dataset (with the gyro
// rotation prediction the odometry node uses) instead of the real V1_01 excerpt.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>
#include <random>
#include <string>
#include <type_traits>
#include <vector>

#include "../tests/ekf_sim_support.hpp"
#include "core/geometry.hpp"
#include "core/klt.hpp"
#include "io/dataset.hpp"
#include "stages/ekf/feature_tracker.hpp"
#include "stages/ekf/msckf.hpp"
#include "stages/ekf/vio_ekf.hpp"

namespace {

using namespace loopgate;

std::filesystem::path micro_dir() {
  return std::filesystem::path(LOOPGATE_SHARED_DATA_DIR) / "euroc/V1_01_easy_micro";
}

// Config overrides "key=value,key=value" from LOOPGATE_EKF_SET (bench only; the app uses the config system).
EkfConfig config_from_env() {
  EkfConfig config;
  const char* env = std::getenv("LOOPGATE_EKF_SET");
  if (env == nullptr) return config;
  std::string list(env);
  std::size_t start = 0;
  while (start < list.size()) {
    const std::size_t end = std::min(list.find(',', start), list.size());
    const std::string item = list.substr(start, end - start);
    const std::size_t eq = item.find('=');
    if (eq != std::string::npos) {
      const std::string key = item.substr(0, eq);
      const std::string value = item.substr(eq + 1);
      EkfConfig::fields(config, [&](const char* name, auto& field) {
        using T = std::decay_t<decltype(field)>;
        if (key != name) return;
        if constexpr (std::is_same_v<T, bool>) {
          field = value == "true" || value == "1";
        } else if constexpr (std::is_same_v<T, std::string>) {
          field = value;
        } else if constexpr (std::is_same_v<T, double>) {
          field = std::stod(value);
        } else {
          field = static_cast<T>(std::stoll(value));
        }
      });
    }
    start = end + 1;
  }
  config.validate();
  return config;
}

void BM_EkfTracking(benchmark::State& state) {
  const char* dataset_env = std::getenv("LOOPGATE_EKF_DATASET");
  const std::filesystem::path dir = dataset_env != nullptr ? std::filesystem::path(dataset_env) : micro_dir();
  if (!std::filesystem::exists(dir)) {
    state.SkipWithError("shared data absent: euroc/V1_01_easy_micro");
    return;
  }
  const auto dataset = open_dataset(dir);
  // LOOPGATE_EKF_FIRST_FRAME: where the 400 images start (e.g. the dark part of a day-to-night dataset).
  const char* first_env = std::getenv("LOOPGATE_EKF_FIRST_FRAME");
  const std::size_t first = std::min<std::size_t>(
      first_env != nullptr ? std::strtoul(first_env, nullptr, 10) : 0, dataset->frame_count() - 1);
  const std::size_t frames = std::min<std::size_t>(dataset->frame_count() - first, 400);
  std::vector<cv::Mat> images;
  for (std::size_t i = 0; i < frames; ++i) images.push_back(dataset->load_image(first + i));
  // Gyro rotation between consecutive images, camera frame (ground-truth biases when known).
  const Eigen::Matrix3d R_i_c =
      (dataset->imu_calibration()->T_b_i.inverse() * dataset->camera()->T_b_c).rotation();
  std::vector<Eigen::Matrix3d> R_cur_prev(frames, Eigen::Matrix3d::Identity());
  for (std::size_t i = 1; i < frames; ++i) {
    const auto imu = dataset->imu_between(dataset->frame_t_ns(first + i - 1), dataset->frame_t_ns(first + i));
    const auto gt = ground_truth_state_at(dataset->ground_truth(), dataset->frame_t_ns(first + i));
    const Eigen::Vector3d bias = gt.has_value() ? gt->gyro_bias_radps : Eigen::Vector3d::Zero().eval();
    Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
    for (std::size_t k = 0; k + 1 < imu.size(); ++k) {
      q = q * so3_exp_quat((0.5 * (imu[k].gyro_radps + imu[k + 1].gyro_radps) - bias) *
                           ns_to_s(imu[k + 1].t_ns - imu[k].t_ns));
    }
    R_cur_prev[i] = R_i_c.transpose() * q.toRotationMatrix().transpose() * R_i_c;
  }
  EkfConfig config = config_from_env();
  FeatureTracker tracker(config, *dataset->camera());
  std::size_t i = 0;
  long tracked = 0;
  long detected = 0;
  long rejected = 0;
  double pyramid_ms = 0;
  double klt_ms = 0;
  double ransac_ms = 0;
  double detect_ms = 0;
  for (auto _ : state) {
    // Forward through the sequence, then restart (a jump the tracker survives by re-detecting).
    const bool predict = config.klt_predict_rotation && i > 0;
    const auto& features = tracker.track(images[i], predict ? &R_cur_prev[i] : nullptr);
    benchmark::DoNotOptimize(features.data());
    const TrackerStats& st = tracker.last_stats();
    tracked += st.tracked;
    detected += st.detected;
    rejected += st.rejected_fb + st.rejected_ransac;
    pyramid_ms += st.pyramid_ms;
    klt_ms += st.klt_ms;
    ransac_ms += st.ransac_ms;
    detect_ms += st.detect_ms;
    i = (i + 1) % images.size();
  }
  const auto avg = [](double v) { return benchmark::Counter(v, benchmark::Counter::kAvgIterations); };
  state.counters["tracked_per_frame"] = avg(static_cast<double>(tracked));
  state.counters["detected_per_frame"] = avg(static_cast<double>(detected));
  state.counters["rejected_per_frame"] = avg(static_cast<double>(rejected));
  state.counters["pyramid_ms"] = avg(pyramid_ms);
  state.counters["klt_ms"] = avg(klt_ms);
  state.counters["ransac_ms"] = avg(ransac_ms);
  state.counters["detect_ms"] = avg(detect_ms);
}
BENCHMARK(BM_EkfTracking)->Unit(benchmark::kMillisecond);

// The corner detection's steps on one grid cell (6 x 4 cells, as ekf.grid_cols / grid_rows), over every cell
// of every 10th of the first 400 images (LOOPGATE_EKF_DATASET or the real V1_01 excerpt): OpenCV's Shi-Tomasi
// response of a cell (BM_DetectionCellResponse) and the noise median of a cell's responses, by nth_element
// over every second row and column (arg 0, the former way) or by quarter_median() (arg 1).
std::vector<cv::Mat> detection_cells(benchmark::State& state, bool responses) {
  const char* dataset_env = std::getenv("LOOPGATE_EKF_DATASET");
  const std::filesystem::path dir = dataset_env != nullptr ? std::filesystem::path(dataset_env) : micro_dir();
  std::vector<cv::Mat> cells;
  if (!std::filesystem::exists(dir)) {
    state.SkipWithError("shared data absent: euroc/V1_01_easy_micro");
    return cells;
  }
  const auto dataset = open_dataset(dir);
  const EkfConfig config;
  for (std::size_t i = 0; i < std::min<std::size_t>(dataset->frame_count(), 400); i += 10) {
    const cv::Mat image = dataset->load_image(i);
    const int w = image.cols / config.grid_cols, h = image.rows / config.grid_rows;
    for (int cy = 0; cy < config.grid_rows; ++cy) {
      for (int cx = 0; cx < config.grid_cols; ++cx) {
        const cv::Mat cell = image(cv::Rect(cx * w, cy * h, w, h));
        if (!responses) {
          cells.push_back(cell);
          continue;
        }
        cv::Mat response;
        cv::cornerMinEigenVal(cell, response, config.shi_tomasi_block_size, 3);
        cells.push_back(response);
      }
    }
  }
  return cells;
}

void BM_DetectionCellResponse(benchmark::State& state) {
  const std::vector<cv::Mat> cells = detection_cells(state, false);
  if (cells.empty()) return;
  const EkfConfig config;
  const bool ours = state.range(0) == 1;
  std::size_t k = 0;
  cv::Mat response;
  for (auto _ : state) {
    // A cell is a view of its image: both read the image's pixels around it.
    if (ours) {
      shi_tomasi_response(cells[k], cv::Rect(0, 0, cells[k].cols, cells[k].rows),
                          config.shi_tomasi_block_size, response);
    } else {
      cv::cornerMinEigenVal(cells[k], response, config.shi_tomasi_block_size, 3);
    }
    benchmark::DoNotOptimize(response.data);
    k = (k + 1) % cells.size();
  }
  state.SetLabel(ours ? "shi_tomasi_response" : "cv::cornerMinEigenVal");
}
BENCHMARK(BM_DetectionCellResponse)->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond);

// The KLT's pyramid (window 15, levels 0-2, derivatives) of every 10th of the first 400 images, and the KLT
// of 150 Shi-Tomasi corners from each of them into the next image (ekf.klt_* defaults): OpenCV (arg 0) or
// core/klt.hpp (arg 1, what the tracker runs).
struct KltPairs {
  std::vector<cv::Mat> images;                     // image, next image, ...
  std::vector<std::vector<cv::Point2f>> corners;   // per pair
  std::vector<std::vector<cv::Mat>> ours, opencv;  // pyramids per image
};

KltPairs klt_pairs(benchmark::State& state) {
  KltPairs p;
  const char* dataset_env = std::getenv("LOOPGATE_EKF_DATASET");
  const std::filesystem::path dir = dataset_env != nullptr ? std::filesystem::path(dataset_env) : micro_dir();
  if (!std::filesystem::exists(dir)) {
    state.SkipWithError("shared data absent: euroc/V1_01_easy_micro");
    return p;
  }
  const auto dataset = open_dataset(dir);
  const EkfConfig config;
  const cv::Size window(config.klt_window_px, config.klt_window_px);
  for (std::size_t i = 0; i + 1 < std::min<std::size_t>(dataset->frame_count(), 400); i += 10) {
    for (const std::size_t f : {i, i + 1}) {
      p.images.push_back(dataset->load_image(f));
      p.ours.emplace_back();
      p.opencv.emplace_back();
      build_klt_pyramid(p.images.back(), window, config.klt_pyramid_levels, p.ours.back());
      cv::buildOpticalFlowPyramid(p.images.back(), p.opencv.back(), window, config.klt_pyramid_levels);
    }
    p.corners.emplace_back();
    cv::goodFeaturesToTrack(p.images[p.images.size() - 2], p.corners.back(), config.max_features,
                            config.shi_tomasi_quality, config.min_feature_distance_px);
  }
  return p;
}

void BM_KltPyramid(benchmark::State& state) {
  const KltPairs p = klt_pairs(state);
  if (p.images.empty()) return;
  const EkfConfig config;
  const cv::Size window(config.klt_window_px, config.klt_window_px);
  const bool ours = state.range(0) == 1;
  std::size_t k = 0;
  for (auto _ : state) {
    std::vector<cv::Mat> pyramid;
    if (ours) {
      build_klt_pyramid(p.images[k], window, config.klt_pyramid_levels, pyramid);
    } else {
      cv::buildOpticalFlowPyramid(p.images[k], pyramid, window, config.klt_pyramid_levels);
    }
    benchmark::DoNotOptimize(pyramid.data());
    k = (k + 1) % p.images.size();
  }
  state.SetLabel(ours ? "build_klt_pyramid" : "cv::buildOpticalFlowPyramid");
}
BENCHMARK(BM_KltPyramid)->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond);

void BM_KltTrack(benchmark::State& state) {
  const KltPairs p = klt_pairs(state);
  if (p.images.empty()) return;
  const EkfConfig config;
  const cv::Size window(config.klt_window_px, config.klt_window_px);
  const cv::TermCriteria criteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, config.klt_max_iterations,
                                  config.klt_epsilon);
  const bool ours = state.range(0) == 1;
  std::size_t k = 0;
  std::vector<cv::Point2f> found;
  std::vector<unsigned char> status;
  for (auto _ : state) {
    const std::vector<cv::Point2f>& corners = p.corners[k];
    found = corners;
    if (ours) {
      track_klt(p.ours[2 * k], p.ours[2 * k + 1], corners, found, status, window, config.klt_pyramid_levels,
                criteria, true);
    } else {
      cv::calcOpticalFlowPyrLK(p.opencv[2 * k], p.opencv[2 * k + 1], corners, found, status, cv::noArray(),
                               window, config.klt_pyramid_levels, criteria, cv::OPTFLOW_USE_INITIAL_FLOW);
    }
    benchmark::DoNotOptimize(found.data());
    k = (k + 1) % p.corners.size();
  }
  state.SetLabel(ours ? "track_klt" : "cv::calcOpticalFlowPyrLK");
}
BENCHMARK(BM_KltTrack)->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond);

void BM_DetectionNoiseMedian(benchmark::State& state) {
  const std::vector<cv::Mat> responses = detection_cells(state, true);
  if (responses.empty()) return;
  const bool histogram = state.range(0) == 1;
  std::size_t k = 0;
  for (auto _ : state) {
    const cv::Mat& r = responses[k];
    float median = 0.0F;
    if (histogram) {
      median = quarter_median(r);
    } else {
      std::vector<float> values;
      values.reserve(r.total() / 4 + 1);
      for (int y = 0; y < r.rows; y += 2) {
        for (int x = 0; x < r.cols; x += 2) values.push_back(r.at<float>(y, x));
      }
      const auto mid = values.begin() + static_cast<std::ptrdiff_t>(values.size() / 2);
      std::nth_element(values.begin(), mid, values.end());
      median = *mid;
    }
    benchmark::DoNotOptimize(median);
    k = (k + 1) % responses.size();
  }
  state.SetLabel(histogram ? "quarter_median" : "nth_element");
}
BENCHMARK(BM_DetectionNoiseMedian)->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond);

// The filter alone: propagation + clone + update + marginalisation per 20 Hz frame on a simulated scene.
void BM_EkfFilter(benchmark::State& state) {
  const ekf_test::CircleMotion motion;
  std::mt19937_64 rng(5);
  std::normal_distribution<double> n01(0.0, 1.0);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  std::vector<Eigen::Vector3d> landmarks;
  for (int i = 0; i < 1500; ++i) {
    const double a = 2.0 * M_PI * u01(rng);
    const double r = 7.0 + 2.0 * u01(rng);
    landmarks.emplace_back(r * std::cos(a), r * std::sin(a), -2.5 + 5.5 * u01(rng));
  }
  Eigen::Matrix3d R_i_c;
  R_i_c << 0, 0, 1, -1, 0, 0, 0, -1, 0;
  Eigen::Isometry3d T_i_c = Eigen::Isometry3d::Identity();
  T_i_c.linear() = R_i_c;
  const double focal = 460.0;
  const double duration_s = 60.0;
  const double rate_hz = 20.0;
  const ImuNoise noise{1.6968e-04, 1.9393e-05, 2.0e-3, 3.0e-3};
  Eigen::Vector3d bg = Eigen::Vector3d::Zero();
  Eigen::Vector3d ba = Eigen::Vector3d::Zero();
  const auto imu = ekf_test::make_imu(
      motion, 0.0, duration_s + 1.0, 200.0,
      {noise.gyro_noise_density, noise.gyro_random_walk, noise.accel_noise_density, noise.accel_random_walk},
      &rng, &bg, &ba);
  // Observations per frame: at most 150 visible landmarks (as the tracker keeps), pixel noise 1 px.
  const auto frames = static_cast<int>(duration_s * rate_hz);
  std::vector<std::vector<FeatureObservation>> observations(static_cast<std::size_t>(frames));
  for (int k = 0; k < frames; ++k) {
    const Eigen::Isometry3d T_c_w = (motion.pose(k / rate_hz) * T_i_c).inverse();
    for (std::size_t id = 0; id < landmarks.size() && observations[static_cast<std::size_t>(k)].size() < 150;
         ++id) {
      const Eigen::Vector3d p_c = T_c_w * landmarks[id];
      if (p_c.z() < 0.3) continue;
      const Eigen::Vector2d xy = p_c.head<2>() / p_c.z();
      if (std::abs(focal * xy.x()) > 375.0 || std::abs(focal * xy.y()) > 239.0) continue;
      observations[static_cast<std::size_t>(k)].push_back(
          FeatureObservation{id, xy + Eigen::Vector2d(n01(rng), n01(rng)) / focal});
    }
  }
  EkfConfig config;
  config.pixel_sigma_px = 1.0;  // the simulated pixel noise
  ImuState init;
  init.q_w_i = Eigen::Quaterniond(motion.rotation(0.0));
  init.p_w_m = motion.position(0.0);
  init.v_w_mps = motion.velocity(0.0);
  const ImuMatrix P0 = ImuMatrix::Identity() * 1e-4;
  Msckf filter(config, noise, T_i_c, focal);
  filter.initialize(init, P0);
  int k = 0;
  std::size_t imu_begin = 0;
  long used = 0;
  for (auto _ : state) {
    if (k == frames) {
      state.PauseTiming();
      filter.initialize(init, P0);
      k = 0;
      imu_begin = 0;
      state.ResumeTiming();
    }
    const Timestamp t_ns = s_to_ns(k / rate_hz);
    std::size_t imu_end = imu_begin;
    while (imu_end < imu.size() && imu[imu_end].t_ns <= t_ns) ++imu_end;
    const MsckfUpdateStats stats =
        filter.process_frame(t_ns, std::span<const ImuSample>(imu.data() + imu_begin, imu_end - imu_begin),
                             observations[static_cast<std::size_t>(k)]);
    used += stats.used_features;
    if (std::getenv("LOOPGATE_EKF_VERBOSE") != nullptr && k % 100 == 0) {
      std::string reason;
      std::printf("k %d used %d rej %d/%d healthy %d %s p_err %.3f\n", k, stats.used_features,
                  stats.rejected_triangulation, stats.rejected_chi2, filter.healthy(&reason) ? 1 : 0,
                  reason.c_str(), (filter.state().p_w_m - motion.position(k / rate_hz)).norm());
    }
    imu_begin = imu_end > 0 ? imu_end - 1 : 0;
    ++k;
  }
  state.counters["features_used_per_frame"] =
      benchmark::Counter(static_cast<double>(used), benchmark::Counter::kAvgIterations);
}
BENCHMARK(BM_EkfFilter)->Unit(benchmark::kMillisecond);

// Position + yaw alignment (4 DoF, as for VIO) of estimate onto truth; returns the RMSE.
double ate_rmse_position_yaw(const std::vector<Eigen::Vector3d>& est,
                             const std::vector<Eigen::Vector3d>& truth) {
  const auto n = static_cast<double>(est.size());
  Eigen::Vector3d ce = Eigen::Vector3d::Zero();
  Eigen::Vector3d ct = Eigen::Vector3d::Zero();
  for (std::size_t i = 0; i < est.size(); ++i) {
    ce += est[i];
    ct += truth[i];
  }
  ce /= n;
  ct /= n;
  double s_cross = 0.0;
  double s_dot = 0.0;
  for (std::size_t i = 0; i < est.size(); ++i) {
    const Eigen::Vector3d e = est[i] - ce;
    const Eigen::Vector3d t = truth[i] - ct;
    s_cross += e.x() * t.y() - e.y() * t.x();
    s_dot += e.x() * t.x() + e.y() * t.y();
  }
  const Eigen::Matrix3d Rz =
      Eigen::AngleAxisd(std::atan2(s_cross, s_dot), Eigen::Vector3d::UnitZ()).toRotationMatrix();
  double sum = 0.0;
  for (std::size_t i = 0; i < est.size(); ++i) sum += (Rz * (est[i] - ce) + ct - truth[i]).squaredNorm();
  return std::sqrt(sum / n);
}

// A whole dataset through the VioEkf (ground-truth initialisation), one iteration = the whole sequence.
void BM_EkfDataset(benchmark::State& state) {
  const char* dir = std::getenv("LOOPGATE_EKF_DATASET");
  if (dir == nullptr) {
    state.SkipWithError("set LOOPGATE_EKF_DATASET to a rendered EuRoC-layout dataset");
    return;
  }
  const auto dataset = open_dataset(dir);
  const auto limit_env = std::getenv("LOOPGATE_EKF_FRAMES");
  const std::size_t frames =
      limit_env != nullptr
          ? std::min<std::size_t>(dataset->frame_count(), std::strtoul(limit_env, nullptr, 10))
          : dataset->frame_count();
  std::vector<cv::Mat> images(frames);
  for (std::size_t i = 0; i < frames; ++i) images[i] = dataset->load_image(i);
  const bool verbose = std::getenv("LOOPGATE_EKF_VERBOSE") != nullptr;
  const EkfConfig config = config_from_env();
  for (auto _ : state) {
    VioEkf vio(config, *dataset->camera(), *dataset->imu_calibration());
    std::vector<Eigen::Vector3d> est;
    std::vector<Eigen::Vector3d> truth;
    double tracking_ms = 0.0;
    double filter_ms = 0.0;
    double pyramid_ms = 0.0;
    double klt_ms = 0.0;
    double ransac_ms = 0.0;
    double detect_ms = 0.0;
    long detected = 0;
    int lost = 0;
    double path_m = 0.0;
    for (std::size_t i = 0; i < frames; ++i) {
      const Timestamp t_ns = dataset->frame_t_ns(i);
      const Timestamp t_prev_ns = i > 0 ? dataset->frame_t_ns(i - 1) : t_ns;
      EkfFrameInput in;
      in.t_ns = t_ns;
      in.imu = dataset->imu_between(t_prev_ns - 10'000'000, t_ns + 10'000'001);
      in.image = &images[i];
      in.ground_truth = ground_truth_state_at(dataset->ground_truth(), t_ns);
      const EkfFrameOutput out = vio.process(in);
      tracking_ms += out.tracking_ms;
      filter_ms += out.filter_ms;
      const TrackerStats& st = vio.tracker().last_stats();
      pyramid_ms += st.pyramid_ms;
      klt_ms += st.klt_ms;
      ransac_ms += st.ransac_ms;
      detect_ms += st.detect_ms;
      detected += st.detected;
      if (out.pose.status == OdometryStatus::kLost) ++lost;
      if (verbose && in.ground_truth.has_value()) {
        const Eigen::Vector3d e = out.pose.T_w_b.translation() - in.ground_truth->T_w_b.translation();
        std::printf(
            "frame %zu status %s tracked %d disp %.2f zupt %d used %d rejtri %d rejchi2 %d err %.3f sigma "
            "%.3f v %.3f %.3f %.3f klt_lost %d fb %d ransac %d detected %d\n",
            i, to_string(out.pose.status), out.tracked_features, out.median_disparity_px,
            out.zero_velocity ? 1 : 0, out.update.used_features, out.update.rejected_triangulation,
            out.update.rejected_chi2, e.norm(), out.position_sigma_m, vio.filter().state().v_w_mps.x(),
            vio.filter().state().v_w_mps.y(), vio.filter().state().v_w_mps.z(), st.lost_klt, st.rejected_fb,
            st.rejected_ransac, st.detected);
      }
      if (out.pose.status == OdometryStatus::kTracking && in.ground_truth.has_value()) {
        if (!truth.empty()) path_m += (in.ground_truth->T_w_b.translation() - truth.back()).norm();
        est.push_back(out.pose.T_w_b.translation());
        truth.push_back(in.ground_truth->T_w_b.translation());
      }
    }
    double sum_raw = 0.0;
    for (std::size_t i = 0; i < est.size(); ++i) sum_raw += (est[i] - truth[i]).squaredNorm();
    state.counters["frames"] = static_cast<double>(frames);
    state.counters["tracking_ms_per_frame"] = tracking_ms / static_cast<double>(frames);
    state.counters["filter_ms_per_frame"] = filter_ms / static_cast<double>(frames);
    state.counters["pyramid_ms"] = pyramid_ms / static_cast<double>(frames);
    state.counters["klt_ms"] = klt_ms / static_cast<double>(frames);
    state.counters["ransac_ms"] = ransac_ms / static_cast<double>(frames);
    state.counters["detect_ms"] = detect_ms / static_cast<double>(frames);
    state.counters["detected_per_frame"] = static_cast<double>(detected) / static_cast<double>(frames);
    state.counters["lost_frames"] = lost;
    // Lengths in centimetres so that the counters print without SI prefixes ("m" would read as milli).
    state.counters["path_cm"] = 100.0 * path_m;
    state.counters["ate_rmse_cm_noalign"] =
        est.empty() ? -1.0 : 100.0 * std::sqrt(sum_raw / static_cast<double>(est.size()));
    state.counters["ate_rmse_cm_posyaw"] = est.empty() ? -1.0 : 100.0 * ate_rmse_position_yaw(est, truth);
    state.counters["final_error_cm"] = est.empty() ? -1.0 : 100.0 * (est.back() - truth.back()).norm();
  }
}
BENCHMARK(BM_EkfDataset)->Unit(benchmark::kSecond)->Iterations(1);

}  // namespace

int main(int argc, char** argv) {
  cv::setNumThreads(1);  // single-core figures
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
