// Full mode (the pure-DIRD baseline) through the whole streaming graph on the shared KITTI 00 thumbnails
// (4540 frames) with the calibrated l2 config: DIRD on every frame, all pairs with i - j >= 200
// (9 419 970), sequence DP and NMS. 1 and 2 worker threads. Counters: frames/s, cores busy, real-time
// factor at 10 Hz, loops found, peak RSS of the process (MB).
//   build/<dir>/bench_pipeline_full --benchmark_counters_tabular=true
#include <benchmark/benchmark.h>

#include <filesystem>

#include "io/config.hpp"
#include "io/dataset.hpp"
#include "pipeline/pipeline.hpp"

namespace loopgate {
namespace {

void BM_FullModeKittiThumbs(benchmark::State& state) {
  const std::filesystem::path root = std::filesystem::path(LOOPGATE_SHARED_DATA_DIR) / "kitti/00/thumbs";
  // The source tree's config (CMake compiles with absolute source paths).
  const std::filesystem::path config_file =
      std::filesystem::path(__FILE__).parent_path().parent_path() / "configs/kitti00-thumbs.yaml";
  if (!std::filesystem::exists(root) || !std::filesystem::exists(config_file)) {
    state.SkipWithError("shared data or configs/kitti00-thumbs.yaml absent");
    return;
  }
  PipelineConfig config = load_config<PipelineConfig>(
      config_file, {"run.mode=full", "output.progress=off", "run.threads=" + std::to_string(state.range(0))});
  const auto dataset = open_dataset(root);
  const auto out = std::filesystem::temp_directory_path() / "loopgate-bench-full";
  RunResult result;
  for (auto _ : state) {
    result = run_pipeline(config, *dataset, out);
    if (result.failed) state.SkipWithError("run failed");
  }
  state.counters["frames_per_s"] =
      benchmark::Counter(static_cast<double>(result.frames_processed) / result.wall_s);
  state.counters["cpu_wall_ratio"] = benchmark::Counter(result.cpu_s / result.wall_s);
  state.counters["realtime_factor"] = benchmark::Counter(result.realtime_factor);
  state.counters["loops"] = benchmark::Counter(result.summary["loops"].get<double>());
  state.counters["peak_rss_mb"] = benchmark::Counter(result.peak_rss_mb);
  std::filesystem::remove_all(out);
}
BENCHMARK(BM_FullModeKittiThumbs)
    ->Arg(1)
    ->Arg(2)
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

}  // namespace
}  // namespace loopgate

BENCHMARK_MAIN();
