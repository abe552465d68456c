// All-pairs sparse similarity of 4541 random descriptors with a safety margin of 200 frames
// (~9.4 million L1 distances), on 1 and 2 threads (target <= 0.3 s on 2 cores).
// Threads take interleaved blocks of current frames (std::thread here; the pipeline uses TBB).
#include <benchmark/benchmark.h>

#include <cstdio>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <random>
#include <thread>
#include <vector>

#include "stages/dird/dird_similarity.hpp"

namespace {

constexpr std::size_t kFrames = 4541;
constexpr std::int64_t kMargin = 200;
constexpr std::size_t kBlock = 16;  // current frames per work item

const std::vector<loopgate::Descriptor>& descriptors() {
  static const std::vector<loopgate::Descriptor> all = [] {
    std::mt19937 rng(1);
    std::uniform_int_distribution<int> byte(0, 255);
    std::vector<loopgate::Descriptor> out(kFrames);
    for (auto& d : out) {
      for (auto& b : d) b = static_cast<std::uint8_t>(byte(rng));
    }
    return out;
  }();
  return all;
}

// The 4540 KITTI 00 thumbnails in l2 mode with their calibrated constants (real distance distribution:
// most pairs lie just above the cut-off, so the kernel's early exit rarely helps). Empty when absent.
const std::vector<loopgate::Descriptor>& kitti_thumbs() {
  static const std::vector<loopgate::Descriptor> all = [] {
    std::vector<loopgate::Descriptor> out;
    const auto dir = std::filesystem::path(LOOPGATE_SHARED_DATA_DIR) / "kitti/00/thumbs/image_0";
    loopgate::DirdConfig config;
    config.normalization = loopgate::DirdNormalization::kL2;
    const loopgate::DirdExtractor extractor(config);
    for (std::size_t f = 0;; ++f) {
      char name[32];
      std::snprintf(name, sizeof name, "%06zu.png", f % 1000000);
      const auto path = dir / name;
      if (!std::filesystem::exists(path)) break;
      out.push_back(extractor.extract(cv::imread(path.string(), cv::IMREAD_GRAYSCALE)));
    }
    return out;
  }();
  return all;
}

void run_all_pairs(benchmark::State& state, const std::vector<loopgate::Descriptor>& all,
                   const loopgate::DirdConfig& config) {
  const int threads = static_cast<int>(state.range(0));
  const std::size_t frames = all.size();
  const loopgate::DirdSimilarity similarity{config};
  std::vector<std::vector<loopgate::SimilarityEntry>> columns(frames);
  const std::size_t blocks = (frames + kBlock - 1) / kBlock;
  auto work = [&](int t) {
    for (std::size_t b = static_cast<std::size_t>(t); b < blocks; b += static_cast<std::size_t>(threads)) {
      const std::size_t begin = b * kBlock;
      const std::size_t end = std::min(frames, begin + kBlock);
      similarity.sparse_columns(
          all, kMargin, begin, end,
          std::span<std::vector<loopgate::SimilarityEntry>>(columns.data() + begin, end - begin));
    }
  };
  for (auto _ : state) {
    std::vector<std::thread> pool;
    for (int t = 1; t < threads; ++t) pool.emplace_back(work, t);
    work(0);
    for (auto& thread : pool) thread.join();
    benchmark::DoNotOptimize(columns.data());
  }
  std::size_t pairs = 0;
  for (std::size_t i = static_cast<std::size_t>(kMargin); i < frames; ++i)
    pairs += i - static_cast<std::size_t>(kMargin) + 1;
  std::size_t stored = 0;
  for (const auto& column : columns) stored += column.size();
  state.counters["pairs"] = static_cast<double>(pairs);
  state.counters["stored"] = static_cast<double>(stored);
  state.counters["pairs_per_s"] =
      benchmark::Counter(static_cast<double>(pairs), benchmark::Counter::kIsIterationInvariantRate);
}

void all_pairs(benchmark::State& state) {
  run_all_pairs(state, descriptors(), loopgate::DirdConfig{});
}

void all_pairs_kitti_thumbs(benchmark::State& state) {
  const auto& all = kitti_thumbs();
  if (all.size() < 1000) {
    state.SkipWithError("kitti/00/thumbs absent");
    return;
  }
  loopgate::DirdConfig config;
  config.normalization = loopgate::DirdNormalization::kL2;
  config.mu = 48477.5;  // loopgate calibrate kitti/00/thumbs --normalization l2
  config.sigma = 1796.7769;
  run_all_pairs(state, all, config);
}

// One current frame against all earlier ones (what a serial streaming match node does per frame).
void one_row(benchmark::State& state) {
  const auto& all = descriptors();
  const loopgate::DirdSimilarity similarity{loopgate::DirdConfig{}};
  std::vector<loopgate::SimilarityEntry> row;
  const std::size_t current = kFrames - 1;
  for (auto _ : state) {
    row.clear();
    similarity.sparse_row(all[current], all.data(), current - static_cast<std::size_t>(kMargin) + 1, 0, row);
    benchmark::DoNotOptimize(row.data());
  }
}

}  // namespace

BENCHMARK(all_pairs)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(2.0);
BENCHMARK(all_pairs_kitti_thumbs)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(2.0);
BENCHMARK(one_row)->Unit(benchmark::kMicrosecond);

BENCHMARK_MAIN();
