// Descriptor standardisation (dird_standardize.hpp) on one core: the cost per descriptor of the statistics
// and of standardising (batch and streaming), and the cost per pair of the distances: raw L1 vs int8-code
// L1 (the same psadbw kernel) vs int8-code cosine vs float z-score L1 / cosine vs the compact codes of
// dird_codes.hpp (sign: Hamming, ternary and int2: popcount dots; the dispatched kernel, AVX-512 or AVX2, and
// the portable one), pair by pair and as one frame's row over the set.
// Every iteration is one descriptor or one pair (BM_RowCompact: one row of 4541 pairs), so the reported time
// is per descriptor / per pair (per row).
// Distances run over a KITTI-00-sized set of 4541 descriptors (raw / codes 15.7 MB, floats 62.8 MB: the
// database a query is compared with) and over 2 descriptors (everything in L1 cache).
// Medians: build/release/bench_dird_standardize --benchmark_repetitions=5 --benchmark_report_aggregates_only
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "stages/dird/dird_codes.hpp"
#include "stages/dird/dird_similarity.hpp"
#include "stages/dird/dird_standardize.hpp"

namespace {

using loopgate::Descriptor;

constexpr std::size_t kDatabase = 4541;

// Random descriptors with DIRD-like per-dimension statistics (centre 60..140, spread 0..40).
const std::vector<Descriptor>& raw_set() {
  static const std::vector<Descriptor> all = [] {
    std::mt19937 rng(7);
    std::uniform_int_distribution<int> centre(60, 140), spread(0, 40);
    std::vector<int> c(loopgate::kDirdBytes), s(loopgate::kDirdBytes);
    for (std::size_t k = 0; k < loopgate::kDirdBytes; ++k) {
      c[k] = centre(rng);
      s[k] = spread(rng);
    }
    std::vector<Descriptor> out(kDatabase);
    for (auto& d : out) {
      for (std::size_t k = 0; k < loopgate::kDirdBytes; ++k) {
        std::normal_distribution<double> noise(c[k], s[k] + 0.5);
        d[k] = static_cast<std::uint8_t>(std::clamp(static_cast<int>(noise(rng)), 0, 255));
      }
    }
    return out;
  }();
  return all;
}

loopgate::StandardizeConfig causal_config(std::int64_t refresh, std::int64_t window) {
  loopgate::StandardizeConfig c;
  c.mode = loopgate::StandardizeMode::kCausal;
  c.refresh_every = refresh;
  c.window = window;
  return c;
}

const loopgate::Standardization& statistics() {
  static const loopgate::Standardization s = loopgate::standardization_of(raw_set(), {});
  return s;
}

const std::vector<Descriptor>& code_set() {
  static const std::vector<Descriptor> all = loopgate::standardize_batch(raw_set(), {});
  return all;
}

const std::vector<double>& code_norms() {
  static const std::vector<double> all = [] {
    std::vector<double> out;
    for (const auto& c : code_set()) out.push_back(loopgate::standard_norm(c));
    return out;
  }();
  return all;
}

const std::vector<loopgate::StandardizedFloat>& float_set() {
  static const std::vector<loopgate::StandardizedFloat> all = [] {
    std::vector<loopgate::StandardizedFloat> out;
    out.reserve(kDatabase);
    loopgate::StandardizedFloat z;
    for (const auto& d : raw_set()) {
      statistics().apply_float(d, z);
      out.push_back(z);
    }
    return out;
  }();
  return all;
}

const std::vector<double>& float_norms() {
  static const std::vector<double> all = [] {
    std::vector<double> out;
    for (const auto& z : float_set())
      out.push_back(std::sqrt(static_cast<double>(loopgate::float_dot(z, z))));
    return out;
  }();
  return all;
}

// ---- per descriptor

void BM_MomentsAdd(benchmark::State& state) {
  loopgate::DescriptorMoments moments(state.range(0));
  const auto& set = raw_set();
  std::size_t k = 0;
  for (auto _ : state) {
    moments.add(set[k]);
    k = k + 1 == set.size() ? 0 : k + 1;
  }
  benchmark::DoNotOptimize(moments.count());
}
BENCHMARK(BM_MomentsAdd)->Arg(0)->Arg(300)->ArgName("window");

void BM_StatisticsSnapshot(benchmark::State& state) {
  loopgate::DescriptorMoments moments;
  for (const auto& d : raw_set()) moments.add(d);
  for (auto _ : state) {
    loopgate::Standardization s(moments, {});
    benchmark::DoNotOptimize(s.count());
  }
}
BENCHMARK(BM_StatisticsSnapshot);

void BM_ApplyCodes(benchmark::State& state) {
  const auto& set = raw_set();
  Descriptor codes;
  std::size_t k = 0;
  for (auto _ : state) {
    statistics().apply(set[k], codes);
    benchmark::DoNotOptimize(codes.data());
    benchmark::ClobberMemory();
    k = k + 1 == set.size() ? 0 : k + 1;
  }
}
BENCHMARK(BM_ApplyCodes);

void BM_ApplyFloat(benchmark::State& state) {
  const auto& set = raw_set();
  loopgate::StandardizedFloat z;
  std::size_t k = 0;
  for (auto _ : state) {
    statistics().apply_float(set[k], z);
    benchmark::DoNotOptimize(z.data());
    benchmark::ClobberMemory();
    k = k + 1 == set.size() ? 0 : k + 1;
  }
}
BENCHMARK(BM_ApplyFloat);

// Batch mode, whole cost per descriptor: statistics of the set, then every descriptor standardised.
void BM_BatchStandardize(benchmark::State& state) {
  const auto& set = raw_set();
  for (auto _ : state) {
    const std::vector<Descriptor> codes = loopgate::standardize_batch(set, {});
    benchmark::DoNotOptimize(codes.data());
  }
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations()) *
                          static_cast<std::int64_t>(set.size()));
}
BENCHMARK(BM_BatchStandardize)->Unit(benchmark::kMillisecond);

// Streaming mode, per frame: observe + standardise (a snapshot every `refresh` frames), over a whole
// 4541-frame sequence (time per iteration / 4541 = per frame; items/s = frames/s).
void BM_CausalStream(benchmark::State& state) {
  const auto& set = raw_set();
  const loopgate::StandardizeConfig config = causal_config(state.range(0), state.range(1));
  Descriptor codes;
  for (auto _ : state) {
    loopgate::CausalStandardizer causal(config);
    for (std::size_t f = 0; f < set.size(); ++f) {
      causal.observe(static_cast<std::int64_t>(f), set[f]);
      if (causal.ready()) causal.standardize(static_cast<std::int64_t>(f), set[f], codes);
    }
    benchmark::DoNotOptimize(codes.data());
  }
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations()) *
                          static_cast<std::int64_t>(set.size()));
}
BENCHMARK(BM_CausalStream)
    ->Args({1, 0})
    ->Args({10, 0})
    ->Args({10, 300})
    ->ArgNames({"refresh", "window"})
    ->Unit(benchmark::kMillisecond);

// ---- per pair: query k against database entry j, j running over the set (range(0) = set size)

template <class Distance>
void run_pairs(benchmark::State& state, Distance distance) {
  const std::size_t n = static_cast<std::size_t>(state.range(0));
  std::size_t j = 0;
  double sink = 0.0;
  for (auto _ : state) {
    sink += distance(n - 1 - j, j);
    j = j + 1 == n ? 0 : j + 1;
  }
  benchmark::DoNotOptimize(sink);
}

void BM_PairRawL1(benchmark::State& state) {
  const auto& set = raw_set();
  run_pairs(state, [&](std::size_t a, std::size_t b) { return loopgate::l1_distance(set[a], set[b]); });
}
void BM_PairCodeL1(benchmark::State& state) {
  const auto& set = code_set();
  run_pairs(state, [&](std::size_t a, std::size_t b) { return loopgate::l1_distance(set[a], set[b]); });
}
void BM_PairCodeCosine(benchmark::State& state) {
  const auto& set = code_set();
  const auto& norms = code_norms();
  run_pairs(state, [&](std::size_t a, std::size_t b) {
    return loopgate::standard_cosine_distance(set[a], norms[a], set[b], norms[b]);
  });
}
void BM_PairFloatL1(benchmark::State& state) {
  const auto& set = float_set();
  run_pairs(state, [&](std::size_t a, std::size_t b) { return loopgate::float_l1_distance(set[a], set[b]); });
}
void BM_PairFloatCosine(benchmark::State& state) {
  const auto& set = float_set();
  const auto& norms = float_norms();
  run_pairs(state, [&](std::size_t a, std::size_t b) {
    return 1.0 - static_cast<double>(loopgate::float_dot(set[a], set[b])) / (norms[a] * norms[b]);
  });
}
// The compact codes of the int8 codes, as the pipeline keeps them (one contiguous matrix).
const loopgate::CompactCodeMatrix& compact_set(loopgate::DirdCode code) {
  static const auto make = [](loopgate::DirdCode c) {
    loopgate::CompactCodeMatrix m({c, 0.5}, loopgate::StandardizeConfig{}.clamp_sigma, kDatabase);
    for (std::size_t k = 0; k < kDatabase; ++k) m.set(k, code_set()[k]);
    return m;
  };
  static const loopgate::CompactCodeMatrix sign = make(loopgate::DirdCode::kSign);
  static const loopgate::CompactCodeMatrix ternary = make(loopgate::DirdCode::kTernary);
  static const loopgate::CompactCodeMatrix int2 = make(loopgate::DirdCode::kInt2);
  return code == loopgate::DirdCode::kSign ? sign : (code == loopgate::DirdCode::kTernary ? ternary : int2);
}
void BM_PairSignHamming(benchmark::State& state) {
  const auto& m = compact_set(loopgate::DirdCode::kSign);
  run_pairs(state, [&](std::size_t a, std::size_t b) { return m.distance(a, b); });
}
void BM_PairTernaryDot(benchmark::State& state) {
  const auto& m = compact_set(loopgate::DirdCode::kTernary);
  run_pairs(state, [&](std::size_t a, std::size_t b) { return m.distance(a, b); });
}
void BM_PairInt2Dot(benchmark::State& state) {
  const auto& m = compact_set(loopgate::DirdCode::kInt2);
  run_pairs(state, [&](std::size_t a, std::size_t b) { return m.distance(a, b); });
}
// The distance row of one frame: the query against every frame of the set in one pass over the contiguous
// code matrix (CompactCodeMatrix::distances, what the pipeline runs per block); time per pair.
void BM_RowCompact(benchmark::State& state) {
  const auto code = static_cast<loopgate::DirdCode>(state.range(0));
  const auto& m = compact_set(code);
  static const std::vector<std::uint8_t> coded(kDatabase, 1);
  std::vector<double> row(kDatabase);
  std::size_t query = 0;
  for (auto _ : state) {
    m.distances(query, 0, kDatabase, coded.data(), row.data());
    benchmark::DoNotOptimize(row.data());
    query = query + 1 == kDatabase ? 0 : query + 1;
  }
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations()) *
                          static_cast<std::int64_t>(kDatabase));
  state.SetLabel(std::string(loopgate::enum_name(code)) + ", " +
                 std::string(loopgate::enum_name(loopgate::best_popcount_kernel())) +
                 " kernel; per pair = time / " + std::to_string(kDatabase));
}
// The portable popcount kernel on the same sign codes (its own copy, as contiguous words).
void BM_PairSignHammingPortable(benchmark::State& state) {
  static const std::vector<std::uint64_t> words = [] {
    std::vector<std::uint64_t> out(kDatabase * loopgate::kCodePlaneWords);
    for (std::size_t k = 0; k < kDatabase; ++k)
      loopgate::make_compact_code({loopgate::DirdCode::kSign, 0.5}, loopgate::StandardizeConfig{}.clamp_sigma,
                                  code_set()[k], out.data() + k * loopgate::kCodePlaneWords);
    return out;
  }();
  run_pairs(state, [&](std::size_t a, std::size_t b) {
    return loopgate::hamming_words_portable(words.data() + a * loopgate::kCodePlaneWords,
                                            words.data() + b * loopgate::kCodePlaneWords,
                                            loopgate::kCodePlaneWords);
  });
}
BENCHMARK(BM_PairSignHamming)->Arg(2)->Arg(kDatabase)->ArgName("set");
BENCHMARK(BM_PairSignHammingPortable)->Arg(2)->Arg(kDatabase)->ArgName("set");
BENCHMARK(BM_PairTernaryDot)->Arg(2)->Arg(kDatabase)->ArgName("set");
BENCHMARK(BM_PairInt2Dot)->Arg(2)->Arg(kDatabase)->ArgName("set");
BENCHMARK(BM_RowCompact)
    ->Arg(static_cast<int>(loopgate::DirdCode::kSign))
    ->Arg(static_cast<int>(loopgate::DirdCode::kTernary))
    ->Arg(static_cast<int>(loopgate::DirdCode::kInt2))
    ->ArgName("code");
BENCHMARK(BM_PairRawL1)->Arg(2)->Arg(kDatabase)->ArgName("set");
BENCHMARK(BM_PairCodeL1)->Arg(2)->Arg(kDatabase)->ArgName("set");
BENCHMARK(BM_PairCodeCosine)->Arg(2)->Arg(kDatabase)->ArgName("set");
BENCHMARK(BM_PairFloatL1)->Arg(2)->Arg(kDatabase)->ArgName("set");
BENCHMARK(BM_PairFloatCosine)->Arg(2)->Arg(kDatabase)->ArgName("set");

}  // namespace

BENCHMARK_MAIN();
