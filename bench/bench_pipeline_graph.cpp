// Throughput of the streaming graph and proof that it uses the cores: the whole run_pipeline on an
// in-memory dataset whose frames are PNG-encoded 1241 x 376 images (decode is the parallel node), with
// 1 and 2 worker threads. Counters: frames/s, CPU time / wall time (cores busy), real-time factor at
// 10 Hz data. A second benchmark replays the shared KITTI 00 thumbnails when present.
//   build/<dir>/bench_pipeline_graph --benchmark_counters_tabular=true
#include <benchmark/benchmark.h>

#include <cmath>
#include <filesystem>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "io/dataset.hpp"
#include "pipeline/pipeline.hpp"

namespace loopgate {
namespace {

constexpr int kWidth = 1241;
constexpr int kHeight = 376;
constexpr std::size_t kFrames = 120;
constexpr std::size_t kDistinctImages = 8;

// Frames at 10 Hz on a straight line; image k is one of a few textured PNGs, decoded on each load.
class PngMemoryDataset : public Dataset {
 public:
  PngMemoryDataset() : root_("/memory/png") {
    for (std::size_t k = 0; k < kDistinctImages; ++k) {
      cv::Mat image(kHeight, kWidth, CV_8UC1);
      cv::randu(image, cv::Scalar(0), cv::Scalar(255));
      for (int r = 0; r < kHeight; ++r) {
        for (int c = 0; c < kWidth; ++c) {
          image.at<std::uint8_t>(r, c) =
              static_cast<std::uint8_t>((image.at<std::uint8_t>(r, c) / 4) + 120 +
                                        60 * std::sin(0.05 * c + 0.3 * static_cast<double>(k)));
        }
      }
      std::vector<std::uint8_t> png;
      cv::imencode(".png", image, png);
      pngs_.push_back(std::move(png));
    }
  }
  DatasetLayout layout() const override { return DatasetLayout::kMemory; }
  const std::filesystem::path& root() const override { return root_; }
  std::size_t frame_count() const override { return kFrames; }
  Timestamp frame_t_ns(std::size_t frame) const override {
    return static_cast<Timestamp>(frame) * 100'000'000;
  }
  bool has_images() const override { return true; }
  std::filesystem::path image_path(std::size_t frame) const override { return root_ / std::to_string(frame); }
  cv::Mat load_image(std::size_t frame) const override {
    return cv::imdecode(pngs_[frame % kDistinctImages], cv::IMREAD_GRAYSCALE);
  }
  bool has_imu() const override { return false; }
  const std::vector<ImuSample>& imu_samples() const override { return imu_; }
  bool has_ground_truth() const override { return true; }
  std::optional<Eigen::Isometry3d> ground_truth_T_w_b(std::size_t frame) const override {
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.translation().x() = static_cast<double>(frame);
    return T;
  }
  const std::vector<GroundTruthState>& ground_truth() const override { return gt_; }
  std::optional<CameraCalibration> camera() const override { return std::nullopt; }
  std::optional<ImuCalibration> imu_calibration() const override { return std::nullopt; }
  const std::vector<DataIssue>& issues() const override { return issues_; }

 private:
  std::filesystem::path root_;
  std::vector<std::vector<std::uint8_t>> pngs_;
  std::vector<ImuSample> imu_;
  std::vector<GroundTruthState> gt_;
  std::vector<DataIssue> issues_;
};

void report(benchmark::State& state, double frames, double wall_s, double cpu_s, double data_s) {
  state.counters["frames_per_s"] = benchmark::Counter(frames / wall_s);
  state.counters["cpu_wall_ratio"] = benchmark::Counter(cpu_s / wall_s);
  state.counters["realtime_factor"] = benchmark::Counter(data_s / wall_s);
}

void BM_GraphDecodeAll(benchmark::State& state) {
  static const PngMemoryDataset dataset;
  PipelineConfig config;
  config.run.threads = static_cast<int>(state.range(0));
  config.run.decode = DecodePolicy::kAll;
  config.output.progress = Progress::kOff;
  config.odometry.heading_axis = HeadingAxis::kZ;
  config.match.margin = 50;  // below the 120 frames: a run that cannot compare any pair fails
  const auto out = std::filesystem::temp_directory_path() / "loopgate-bench-pipeline";
  double wall_s = 0, cpu_s = 0, data_s = 0, frames = 0;
  for (auto _ : state) {
    const RunResult result = run_pipeline(config, dataset, out);
    if (result.failed || result.frames_processed != kFrames) state.SkipWithError("run failed");
    wall_s += result.wall_s;
    cpu_s += result.cpu_s;
    data_s += result.data_s;
    frames += static_cast<double>(result.frames_processed);
  }
  report(state, frames, wall_s, cpu_s, data_s);
  std::filesystem::remove_all(out);
}
BENCHMARK(BM_GraphDecodeAll)
    ->Arg(1)
    ->Arg(2)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MeasureProcessCPUTime();

void BM_GraphKittiThumbs(benchmark::State& state) {
  const std::filesystem::path dir = std::filesystem::path(LOOPGATE_SHARED_DATA_DIR) / "kitti/00/thumbs";
  if (!std::filesystem::exists(dir)) {
    state.SkipWithError("shared data absent: kitti/00/thumbs");
    return;
  }
  OpenOptions options;
  options.strict = false;
  const auto dataset = open_dataset(dir, options);
  PipelineConfig config;
  config.run.threads = static_cast<int>(state.range(0));
  config.run.decode = DecodePolicy::kAll;
  config.output.progress = Progress::kOff;
  const auto out = std::filesystem::temp_directory_path() / "loopgate-bench-pipeline-thumbs";
  double wall_s = 0, cpu_s = 0, data_s = 0, frames = 0;
  for (auto _ : state) {
    const RunResult result = run_pipeline(config, *dataset, out);
    wall_s += result.wall_s;
    cpu_s += result.cpu_s;
    data_s += result.data_s;
    frames += static_cast<double>(result.frames_processed);
  }
  report(state, frames, wall_s, cpu_s, data_s);
  std::filesystem::remove_all(out);
}
BENCHMARK(BM_GraphKittiThumbs)
    ->Arg(1)
    ->Arg(2)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MeasureProcessCPUTime();

}  // namespace
}  // namespace loopgate

BENCHMARK_MAIN();
