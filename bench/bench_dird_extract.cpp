// DIRD extraction of one decoded 1241 x 376 grey image on one core (target <= 0.5 ms median), with the
// specified nearest-neighbour working image and with dird.resize area.
// Uses KITTI 00 frame 0 from ../shared/data when present, otherwise a synthetic textured image.
#include <benchmark/benchmark.h>

#include <filesystem>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "stages/dird/dird_extractor.hpp"

namespace {

cv::Mat bench_image() {
  const std::filesystem::path path =
      std::filesystem::path(LOOPGATE_SHARED_DATA_DIR) / "kitti/00/frames/image_0/000000.png";
  if (std::filesystem::exists(path)) {
    cv::Mat image = cv::imread(path.string(), cv::IMREAD_GRAYSCALE);
    if (!image.empty()) return image;
  }
  cv::Mat image(376, 1241, CV_8UC1);
  cv::RNG rng(42);
  rng.fill(image, cv::RNG::UNIFORM, 0, 256);
  return image;
}

void run(benchmark::State& state, loopgate::DirdNormalization normalization, bool colour,
         loopgate::DirdResize resize = loopgate::DirdResize::kNearest) {
  cv::Mat image = bench_image();
  if (colour) {
    cv::Mat channels[3] = {image, image, image};
    cv::merge(channels, 3, image);
  }
  loopgate::DirdConfig config;
  config.normalization = normalization;
  config.resize = resize;
  const loopgate::DirdExtractor extractor(config);
  loopgate::Descriptor descriptor{};
  for (auto _ : state) {
    extractor.extract(image, descriptor);
    benchmark::DoNotOptimize(descriptor.data());
    benchmark::ClobberMemory();
  }
  state.SetLabel(std::to_string(image.cols) + "x" + std::to_string(image.rows));
}

void BM_DirdExtractLibdird(benchmark::State& state) {
  run(state, loopgate::DirdNormalization::kLibdird, false);
}
void BM_DirdExtractL2(benchmark::State& state) {
  run(state, loopgate::DirdNormalization::kL2, false);
}
void BM_DirdExtractColourBgr(benchmark::State& state) {
  run(state, loopgate::DirdNormalization::kLibdird, true);
}
// dird.resize area: the box filter over every source pixel before the working image.
void BM_DirdExtractAreaL2(benchmark::State& state) {
  run(state, loopgate::DirdNormalization::kL2, false, loopgate::DirdResize::kArea);
}
void BM_DirdExtractAreaLibdird(benchmark::State& state) {
  run(state, loopgate::DirdNormalization::kLibdird, false, loopgate::DirdResize::kArea);
}

}  // namespace

BENCHMARK(BM_DirdExtractLibdird)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_DirdExtractL2)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_DirdExtractColourBgr)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_DirdExtractAreaL2)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_DirdExtractAreaLibdird)->Unit(benchmark::kMillisecond);

BENCHMARK_MAIN();
