// Simulator driver speed per preset: planning (trajectory fit + IMU synthesis / pass-through + ground
// truth) and the end-to-end run (world, parallel rendering, PNG encoding, EuRoC writing) in frames/s.
// Presets on shared data are skipped when it is absent.
#include <benchmark/benchmark.h>
#include <spdlog/spdlog.h>

#include <filesystem>
#include <string>

#include "sim/simulator.hpp"

namespace {

namespace fs = std::filesystem;
namespace sim = loopgate::sim;

const fs::path kShared = LOOPGATE_SHARED_DATA_DIR;

bool preset_available(const std::string& preset) {
  if (preset == "kitti00") return fs::exists(kShared / "kitti/00/poses.txt");
  if (preset == "euroc-mh05") return fs::exists(kShared / "euroc/MH_05_difficult/mav0/imu0/data.csv");
  return true;
}

void BM_PlanPreset(benchmark::State& state, const std::string& preset) {
  if (!preset_available(preset)) {
    state.SkipWithError("shared data absent");
    return;
  }
  spdlog::set_level(spdlog::level::warn);
  std::size_t frames = 0;
  for (auto _ : state) {
    sim::SimulationConfig config = sim::make_preset(preset, kShared);
    const sim::SimulationPlan plan = sim::plan_simulation(config);
    frames = plan.frame_t_ns.size();
    benchmark::DoNotOptimize(plan.ground_truth.data());
  }
  state.counters["frames"] = static_cast<double>(frames);
}

// End to end: the first `frames` frames of the preset (state.range(0)).
void BM_RunPreset(benchmark::State& state, const std::string& preset) {
  if (!preset_available(preset)) {
    state.SkipWithError("shared data absent");
    return;
  }
  spdlog::set_level(spdlog::level::warn);
  const fs::path out = fs::temp_directory_path() / ("loopgate-bench-sim-" + preset);
  const std::int64_t frames = state.range(0);
  double render_s = 0.0;
  for (auto _ : state) {
    sim::SimulationConfig config = sim::make_preset(preset, kShared);
    config.simulation.max_frames = frames;
    sim::SimulationRunOptions options;
    options.force = true;
    const sim::SimulationSummary summary = sim::run_simulation(config, out, options);
    render_s += summary.render_s;
  }
  std::error_code ec;
  fs::remove_all(out, ec);
  state.counters["frames_per_s"] = benchmark::Counter(
      static_cast<double>(frames) * static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
  state.counters["render_encode_s_per_frame"] =
      render_s / (static_cast<double>(frames) * static_cast<double>(state.iterations()));
}

BENCHMARK_CAPTURE(BM_PlanPreset, demo, std::string("demo"))->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_PlanPreset, kitti00, std::string("kitti00"))->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_PlanPreset, euroc_mh05, std::string("euroc-mh05"))->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_RunPreset, demo, std::string("demo"))
    ->Arg(600)
    ->Unit(benchmark::kSecond)
    ->Iterations(1)
    ->UseRealTime();
BENCHMARK_CAPTURE(BM_RunPreset, kitti00, std::string("kitti00"))
    ->Arg(100)
    ->Unit(benchmark::kSecond)
    ->Iterations(1)
    ->UseRealTime();
BENCHMARK_CAPTURE(BM_RunPreset, euroc_mh05, std::string("euroc-mh05"))
    ->Arg(100)
    ->Unit(benchmark::kSecond)
    ->Iterations(1)
    ->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
