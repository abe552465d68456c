// Reader speed: the real MH_05 IMU (22 721 rows) and ground-truth (22 212 rows) CSVs, opening whole
// datasets, and writing an IMU CSV. Skips (with a message) when ../shared/data is absent.
#include <benchmark/benchmark.h>
#include <spdlog/spdlog.h>

#include <filesystem>

#include "io/dataset.hpp"
#include "io/trajectory_io.hpp"

namespace {

namespace fs = std::filesystem;

const fs::path kData = LOOPGATE_SHARED_DATA_DIR;

bool require(benchmark::State& state, const fs::path& path) {
  if (fs::exists(path)) return true;
  state.SkipWithError(("shared data absent: " + path.string()).c_str());
  return false;
}

void BM_ReadEurocImuCsv(benchmark::State& state) {
  const fs::path file = kData / "euroc/MH_05_difficult/mav0/imu0/data.csv";
  if (!require(state, file)) return;
  std::size_t rows = 0;
  for (auto _ : state) {
    const auto samples = loopgate::read_euroc_imu(file);
    rows = samples.size();
    benchmark::DoNotOptimize(samples.data());
  }
  state.counters["rows"] = static_cast<double>(rows);
  state.counters["rows/s"] =
      benchmark::Counter(static_cast<double>(rows), benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_ReadEurocImuCsv)->Unit(benchmark::kMillisecond);

void BM_ReadEurocGroundTruthCsv(benchmark::State& state) {
  const fs::path file = kData / "euroc/MH_05_difficult/mav0/state_groundtruth_estimate0/data.csv";
  if (!require(state, file)) return;
  std::size_t rows = 0;
  for (auto _ : state) {
    const auto states = loopgate::read_euroc_groundtruth(file);
    rows = states.size();
    benchmark::DoNotOptimize(states.data());
  }
  state.counters["rows"] = static_cast<double>(rows);
  state.counters["rows/s"] =
      benchmark::Counter(static_cast<double>(rows), benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_ReadEurocGroundTruthCsv)->Unit(benchmark::kMillisecond);

void BM_OpenMh05(benchmark::State& state) {
  const fs::path dir = kData / "euroc/MH_05_difficult";
  if (!require(state, dir)) return;
  for (auto _ : state) benchmark::DoNotOptimize(loopgate::open_dataset(dir)->frame_count());
}
BENCHMARK(BM_OpenMh05)->Unit(benchmark::kMillisecond);

void BM_OpenKittiThumbs(benchmark::State& state) {
  const fs::path dir = kData / "kitti/00/thumbs";
  if (!require(state, dir)) return;
  for (auto _ : state) benchmark::DoNotOptimize(loopgate::open_dataset(dir)->frame_count());
}
BENCHMARK(BM_OpenKittiThumbs)->Unit(benchmark::kMillisecond);

void BM_LoadKittiThumb(benchmark::State& state) {
  const fs::path dir = kData / "kitti/00/thumbs";
  if (!require(state, dir)) return;
  const auto dataset = loopgate::open_dataset(dir);
  std::size_t frame = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(dataset->load_image(frame).data);
    frame = (frame + 1) % dataset->frame_count();
  }
}
BENCHMARK(BM_LoadKittiThumb)->Unit(benchmark::kMicrosecond);

void BM_WriteEurocImuCsv(benchmark::State& state) {
  const fs::path file = kData / "euroc/MH_05_difficult/mav0/imu0/data.csv";
  if (!require(state, file)) return;
  const auto samples = loopgate::read_euroc_imu(file);
  const fs::path out = fs::temp_directory_path() / "loopgate-bench-imu.csv";
  for (auto _ : state) loopgate::write_euroc_imu(out, samples);
  fs::remove(out);
}
BENCHMARK(BM_WriteEurocImuCsv)->Unit(benchmark::kMillisecond);

}  // namespace

int main(int argc, char** argv) {
  spdlog::set_level(spdlog::level::warn);  // opening a dataset logs a summary at info level
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
