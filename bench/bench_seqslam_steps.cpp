// SeqSLAM throughput: difference matrix (SAD kernel), contrast enhancement, sequence search, and the
// whole KITTI 00 thumbnail run (4540 x 4540, reference image_0 vs query image_1, +-100 band).
#include <benchmark/benchmark.h>

#include <cstdio>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <random>

#include "stages/seqslam/seqslam.hpp"

namespace {

using loopgate::SeqSlam;
using loopgate::SeqSlamConfig;
using loopgate::SeqSlamExclusion;
using loopgate::SeqSlamImages;
using loopgate::SeqSlamMatrix;

constexpr std::size_t kPixels = 64 * 32;

SeqSlamImages random_images(std::size_t count, unsigned seed) {
  std::mt19937 rng(seed);
  SeqSlamImages images(kPixels);
  std::vector<std::uint8_t> img(kPixels);
  for (std::size_t i = 0; i < count; ++i) {
    for (auto& x : img) x = static_cast<std::uint8_t>(rng() % 136);
    images.add(img);
  }
  return images;
}

void BM_DifferenceMatrix(benchmark::State& state) {
  const auto n = static_cast<std::size_t>(state.range(0));
  const SeqSlamImages ref = random_images(n, 1), query = random_images(n, 2);
  SeqSlamMatrix D(n, n);
  for (auto _ : state) {
    seqslam_difference_block(ref, query, SeqSlamExclusion{}, 0, n, 0, n, D);
    benchmark::DoNotOptimize(D.column(0));
  }
  const double entries = static_cast<double>(n * n);
  state.counters["entries/s"] = benchmark::Counter(entries, benchmark::Counter::kIsIterationInvariantRate);
  state.counters["bytes/s"] =
      benchmark::Counter(entries * kPixels, benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_DifferenceMatrix)->Arg(512)->Arg(1024)->Unit(benchmark::kMillisecond);

void BM_ContrastEnhancement(benchmark::State& state) {
  const auto n = static_cast<std::size_t>(state.range(0));
  std::mt19937 rng(3);
  SeqSlamMatrix original(n, n);
  for (std::size_t q = 0; q < n; ++q)
    for (std::size_t r = 0; r < n; ++r) original.at(r, q) = 20.0 + static_cast<double>(rng() % 1000) / 100.0;
  for (auto _ : state) {
    state.PauseTiming();
    SeqSlamMatrix M = original;
    state.ResumeTiming();
    benchmark::DoNotOptimize(seqslam_enhance_contrast(M, 10, 0, n));
  }
  state.counters["entries/s"] =
      benchmark::Counter(static_cast<double>(n * n), benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_ContrastEnhancement)->Arg(1024)->Unit(benchmark::kMillisecond);

void BM_SequenceSearch(benchmark::State& state) {
  const auto n = static_cast<std::size_t>(state.range(0));
  std::mt19937 rng(4);
  SeqSlamMatrix E(n, n);
  for (std::size_t q = 0; q < n; ++q)
    for (std::size_t r = 0; r < n; ++r) E.at(r, q) = static_cast<double>(rng() % 1000) / 100.0;
  const SeqSlamConfig config;
  for (auto _ : state) {
    for (std::size_t q = 0; q < n; ++q) benchmark::DoNotOptimize(seqslam_match_query(E, q, config));
  }
  state.counters["queries/s"] =
      benchmark::Counter(static_cast<double>(n), benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_SequenceSearch)->Arg(1024)->Unit(benchmark::kMillisecond);

SeqSlamImages load_thumbs(const std::filesystem::path& dir) {
  SeqSlamImages images(kPixels);
  for (std::size_t i = 0;; ++i) {
    char name[32];
    std::snprintf(name, sizeof(name), "%06zu.png", i);
    if (!std::filesystem::exists(dir / name)) break;
    images.add(cv::imread((dir / name).string(), cv::IMREAD_GRAYSCALE));
  }
  return images;
}

// Steps 2-4 on the 4540 KITTI 00 thumbnails, single thread (image loading excluded).
void BM_KittiThumbsRun(benchmark::State& state) {
  const std::filesystem::path thumbs = std::filesystem::path(LOOPGATE_SHARED_DATA_DIR) / "kitti/00/thumbs";
  if (!std::filesystem::exists(thumbs / "image_1")) {
    state.SkipWithError("shared data absent: kitti/00/thumbs");
    return;
  }
  const SeqSlamImages ref = load_thumbs(thumbs / "image_0"), query = load_thumbs(thumbs / "image_1");
  SeqSlamConfig config;
  config.exclusion = loopgate::SeqSlamExclusionKind::kBand;
  config.exclusion_margin_frames = 101;
  const SeqSlam seqslam(config);
  for (auto _ : state) benchmark::DoNotOptimize(seqslam.run(ref, query));
  state.counters["frames"] = static_cast<double>(query.size());
}
BENCHMARK(BM_KittiThumbsRun)->Unit(benchmark::kMillisecond)->Iterations(2);

}  // namespace

BENCHMARK_MAIN();
