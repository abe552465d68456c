// Cost of dird-seqslam's matching per frame (stages/match/contrast_search.hpp), on one core: the contrast of
// one row and one push of the streaming search (contrast + every line ending in the row + the cover), for a
// gated row (a candidate area's ~100 references) and full rows of 1 000 to 100 000 references (a full run's
// row grows with the map). L = 20, the default velocity grid (5 values), random distances.
// Run: build/release/bench_match_contrast_search --benchmark_repetitions=5 --benchmark_report_aggregates_only
#include <benchmark/benchmark.h>

#include <random>
#include <vector>

#include "stages/match/contrast_search.hpp"

namespace {

std::vector<loopgate::DistanceEntry> random_row(std::int64_t width, std::mt19937& rng) {
  std::uniform_real_distribution<double> distance(0.5, 1.5);
  std::vector<loopgate::DistanceEntry> row(static_cast<std::size_t>(width));
  for (std::int64_t j = 0; j < width; ++j) row[static_cast<std::size_t>(j)] = {j, distance(rng)};
  return row;
}

void BM_ContrastRow(benchmark::State& state) {
  std::mt19937 rng(1);
  const auto row = random_row(state.range(0), rng);
  for (auto _ : state) {
    std::vector<float> z = loopgate::contrast_enhance_row(row, 10, 5);
    benchmark::DoNotOptimize(z.data());
  }
  state.SetItemsProcessed(state.iterations() * state.range(0));
}

// One push into a search that already holds L rows of the same width (the steady state of a run).
void BM_SearchPush(benchmark::State& state) {
  constexpr int kLength = 20;
  std::mt19937 rng(2);
  const std::int64_t width = state.range(0);
  std::vector<std::vector<loopgate::DistanceEntry>> rows;
  for (int k = 0; k < 64; ++k) rows.push_back(random_row(width, rng));
  loopgate::ContrastSearchConfig config;
  loopgate::ContrastSequenceSearch search(config, kLength,
                                          loopgate::ContrastSequenceSearch::Mode::kTwoSequence);
  loopgate::ContrastOutput out;
  std::int64_t i = 0;
  for (; i < kLength; ++i) search.push(i, rows[static_cast<std::size_t>(i % 64)], out);
  for (auto _ : state) {
    search.push(i, rows[static_cast<std::size_t>(i % 64)], out);
    ++i;
    if (out.frames.size() > 4096) {
      out.frames.clear();
      out.loops.clear();
    }
  }
  state.SetItemsProcessed(state.iterations() * width);
}

}  // namespace

BENCHMARK(BM_ContrastRow)->Arg(100)->Arg(4540)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_SearchPush)
    ->Arg(100)
    ->Arg(1000)
    ->Arg(4540)
    ->Arg(10000)
    ->Arg(100000)
    ->Unit(benchmark::kMicrosecond);

BENCHMARK_MAIN();
