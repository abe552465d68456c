// Query cost of the pose gate's exact nearest-neighbour search at 1k, 10k, 100k and 1M stored poses.
// Trajectory: a planar random walk of a vehicle (1 m steps, heading noise 0.05 rad/step, small height
// noise); covariance: sigma^2 = 0.0025 m^2 + 0.002 m^2/m * distance since the last relocalisation, reset
// every 1000 m (a VIO corrected now and then), with a random anisotropy of up to 3:1. The gate holds n
// poses in its KD-tree (built through process(), i.e. insert as a stream would); then queries at positions of
// the trajectory perturbed by a few metres (revisits) are timed with PoseGate::query (no insertion, so n
// stays fixed). Counters: candidates rescored per query, gated fraction.
#include <benchmark/benchmark.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdint>
#include <map>
#include <memory>
#include <random>
#include <utility>
#include <vector>

#include "stages/gate/pose_gate.hpp"

namespace {

using loopgate::GateConfig;
using loopgate::GateDecision;
using loopgate::PoseGate;

struct Pose {
  Eigen::Vector3d p_m;
  Eigen::Matrix3d P_m2;
};

Eigen::Matrix3d covariance(double travelled_m, std::mt19937_64& rng) {
  constexpr double kSigma2FloorM2 = 0.0025;
  constexpr double kSigma2PerMetreM2 = 0.002;
  constexpr double kResetPeriodM = 1000.0;
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  const double var_m2 = kSigma2FloorM2 + kSigma2PerMetreM2 * std::fmod(travelled_m, kResetPeriodM);
  const Eigen::Vector3d shape(1.0, 1.0 / (1.0 + 2.0 * unit(rng)), 0.5);
  const Eigen::Matrix3d R =
      Eigen::AngleAxisd(2.0 * M_PI * unit(rng), Eigen::Vector3d::UnitZ()).toRotationMatrix();
  return var_m2 * R * shape.asDiagonal() * R.transpose();
}

std::vector<Pose> random_walk(std::size_t n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> heading_noise(0.0, 0.05);
  std::normal_distribution<double> height_noise(0.0, 0.01);
  std::vector<Pose> out;
  out.reserve(n);
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
  double heading = 0.0;
  for (std::size_t k = 0; k < n; ++k) {
    heading += heading_noise(rng);
    p += Eigen::Vector3d(std::cos(heading), std::sin(heading), height_noise(rng));
    out.push_back({p, covariance(static_cast<double>(k), rng)});
  }
  return out;
}

struct Fixture {
  std::vector<Pose> poses;
  std::unique_ptr<PoseGate> gate;
};

// One gate per size, built once (1M takes seconds): n + gap frames processed -> n in the tree.
Fixture& fixture(std::size_t n) {
  static std::map<std::size_t, Fixture> cache;
  auto it = cache.find(n);
  if (it != cache.end()) return it->second;
  GateConfig config;
  config.beta_m = 5.0;
  Fixture f;
  f.poses = random_walk(n + static_cast<std::size_t>(config.gap_frames), 42);
  f.gate = std::make_unique<PoseGate>(config);
  for (std::size_t k = 0; k < f.poses.size(); ++k) {
    f.gate->process(static_cast<std::int64_t>(k), f.poses[k].p_m, f.poses[k].P_m2);
  }
  return cache.emplace(n, std::move(f)).first->second;
}

void BM_GateQuery(benchmark::State& state) {
  const auto n = static_cast<std::size_t>(state.range(0));
  Fixture& f = fixture(n);
  std::mt19937_64 rng(7);
  std::normal_distribution<double> offset(0.0, 3.0);
  // Pre-drawn queries so the RNG is not timed.
  constexpr std::size_t kQueries = 4096;
  std::vector<Pose> queries;
  for (std::size_t q = 0; q < kQueries; ++q) {
    const Pose& base = f.poses[static_cast<std::size_t>(rng() % n)];
    queries.push_back({base.p_m + Eigen::Vector3d(offset(rng), offset(rng), 0.0), covariance(500.0, rng)});
  }
  const auto frame = static_cast<std::int64_t>(f.poses.size() + 1000);
  std::size_t q = 0;
  double rescored = 0.0;
  double gated = 0.0;
  for (auto _ : state) {
    const Pose& query = queries[q];
    const GateDecision d = f.gate->query(frame, query.p_m, query.P_m2);
    benchmark::DoNotOptimize(d.distance_m);
    rescored += static_cast<double>(d.candidates_rescored);
    gated += d.gated ? 1.0 : 0.0;
    q = (q + 1) % kQueries;
  }
  state.counters["stored"] = static_cast<double>(f.gate->frames_in_tree());
  state.counters["rescored_per_query"] = benchmark::Counter(rescored, benchmark::Counter::kAvgIterations);
  state.counters["gated_fraction"] = benchmark::Counter(gated, benchmark::Counter::kAvgIterations);
}
// The streaming cost: a fresh gate fed n frames with process() (delayed insertion + exact search per frame);
// the time reported is for the whole stream, frames_per_second gives the per-frame rate.
void BM_GateProcessStream(benchmark::State& state) {
  const auto n = static_cast<std::size_t>(state.range(0));
  const std::vector<Pose> poses = random_walk(n, 43);
  GateConfig config;
  config.beta_m = 5.0;
  for (auto _ : state) {
    PoseGate gate(config);
    std::size_t gated = 0;
    for (std::size_t k = 0; k < n; ++k) {
      gated += gate.process(static_cast<std::int64_t>(k), poses[k].p_m, poses[k].P_m2).gated ? 1 : 0;
    }
    benchmark::DoNotOptimize(gated);
  }
  state.counters["frames_per_second"] =
      benchmark::Counter(static_cast<double>(n), benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_GateProcessStream)
    ->ArgName("frames")
    ->Arg(1000)
    ->Arg(10000)
    ->Arg(100000)
    ->Unit(benchmark::kMillisecond);

BENCHMARK(BM_GateQuery)
    ->ArgName("stored")
    ->Arg(1000)
    ->Arg(10000)
    ->Arg(100000)
    ->Arg(1000000)
    ->Unit(benchmark::kMicrosecond);

}  // namespace

BENCHMARK_MAIN();
