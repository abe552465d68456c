// loopgate simulate: renders a synthetic EuRoC-layout dataset (images, IMU, ground truth, loops metadata).
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "app/commands.hpp"
#include "core/error.hpp"
#include "io/config.hpp"
#include "io/file_guard.hpp"
#include "sim/simulator.hpp"

namespace loopgate::app {

namespace {

struct SimulateOptions {
  std::string preset = "demo";
  std::string out_dir;
  std::int64_t seed = 1;
  bool seed_given = false;  // --seed wins over --config / --set simulation.seed
  std::int64_t frames = 0;
  std::string trajectory;
  std::string trajectory_format;
  std::string imu;
  std::string frame_times;
  std::string config_file;
  std::vector<std::string> overrides;
  bool force = false;
};

// kitti (12 numbers per row), tum (8 numbers) or euroc (a .csv), from the file itself.
sim::TrajectorySource detect_trajectory_format(const std::filesystem::path& file) {
  if (file.extension() == ".csv") return sim::TrajectorySource::kEuroc;
  std::ifstream in(file);
  if (!in) throw DataError(file, "cannot open trajectory file");
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream row(line);
    int count = 0;
    double value = 0.0;
    while (row >> value) ++count;
    if (count == 12) return sim::TrajectorySource::kKitti;
    if (count == 8) return sim::TrajectorySource::kTum;
    throw DataError(file, 1,
                    "cannot tell the trajectory format (expected 12 numbers per row for KITTI poses, 8 for "
                    "TUM, or a .csv EuRoC ground truth); pass --trajectory-format");
  }
  throw DataError(file, "empty trajectory file");
}

// Applies --trajectory / --trajectory-format / --imu, deriving the companion files of the layout.
void apply_input_overrides(const SimulateOptions& opt, sim::SimulationConfig& config) {
  sim::SimulationSettings& s = config.simulation;
  if (!opt.trajectory.empty()) {
    const std::filesystem::path file = opt.trajectory;
    require_regular_file(file, "the trajectory file");  // missing, a directory, a FIFO: say which
    s.trajectory_format = opt.trajectory_format.empty()
                              ? detect_trajectory_format(file)
                              : enum_value<sim::TrajectorySource>(opt.trajectory_format).value();
    s.trajectory_file = file.string();
    if (s.trajectory_format == sim::TrajectorySource::kKitti) {
      s.times_file = (file.parent_path() / "times.txt").string();
      s.frame_times_file.clear();  // KITTI: times.txt gives each pose's time
    } else if (s.trajectory_format == sim::TrajectorySource::kEuroc) {
      // .../mav0/state_groundtruth_estimate0/data.csv -> .../mav0/cam0/data.csv and imu0/data.csv
      const std::filesystem::path mav0 = file.parent_path().parent_path();
      const std::filesystem::path cam_csv = mav0 / "cam0" / "data.csv";
      s.frame_times_file = std::filesystem::is_regular_file(cam_csv) ? cam_csv.string() : std::string{};
      const std::filesystem::path imu_csv = mav0 / "imu0" / "data.csv";
      if (s.imu_source == sim::ImuSource::kFile && opt.imu.empty()) {
        if (std::filesystem::is_regular_file(imu_csv)) {
          s.imu_file = imu_csv.string();
        } else {
          s.imu_source = sim::ImuSource::kSynthesised;
        }
      }
    } else {
      s.frame_times_file.clear();
      if (opt.imu.empty()) s.imu_source = sim::ImuSource::kSynthesised;
    }
  } else if (!opt.trajectory_format.empty()) {
    throw ConfigError("--trajectory-format needs --trajectory");
  }
  if (!opt.frame_times.empty()) {
    require_regular_file(opt.frame_times, "the frame times file");
    s.frame_times_file = opt.frame_times;
  }
  if (!opt.imu.empty()) {
    require_regular_file(opt.imu, "the IMU file");
    s.imu_source = sim::ImuSource::kFile;
    s.imu_file = opt.imu;
  }
}

int run_simulate(const SimulateOptions& opt) {
  sim::SimulationConfig config = sim::make_preset(opt.preset, sim::default_shared_data_dir());
  RawConfig raw = opt.config_file.empty() ? RawConfig{} : RawConfig::from_yaml_file(opt.config_file);
  for (const std::string& assignment : opt.overrides) raw.apply_override(assignment);
  apply_config(raw, config);
  if (opt.seed_given) config.simulation.seed = opt.seed;
  if (opt.frames > 0) config.simulation.max_frames = opt.frames;
  apply_input_overrides(opt, config);

  // --force clears OUT/mav0 and OUT/simulation.json before the inputs are read: none of them may be there
  // (outputs never over inputs).
  const std::filesystem::path out_dir = opt.out_dir;
  const sim::SimulationSettings& s = config.simulation;
  for (const auto& [what, file] : std::vector<std::pair<std::string, std::string>>{
           {"--trajectory / simulation.trajectory_file", s.trajectory_file},
           {"simulation.times_file", s.times_file},
           {"--frame-times / simulation.frame_times_file", s.frame_times_file},
           {"--imu / simulation.imu_file", s.imu_file},
           {"--config", opt.config_file},
           {"--preset", opt.preset}}) {
    if (file.empty()) continue;
    if (path_inside(file, out_dir / "mav0") || same_file(file, out_dir / "simulation.json")) {
      throw ConfigError(
          what + " " + file + " lies inside the output " + opt.out_dir +
          " (its mav0/ and simulation.json are replaced): copy it elsewhere or choose another --out");
    }
  }
  const OutputLock lock(out_dir, "loopgate simulate");

  spdlog::info("simulate: preset '{}', seed {}, output {}", opt.preset, config.simulation.seed, opt.out_dir);
  sim::SimulationRunOptions run_options;
  run_options.force = opt.force;
  const sim::SimulationSummary summary = sim::run_simulation(config, opt.out_dir, run_options);

  const double fps = summary.render_s > 0.0 ? static_cast<double>(summary.frames) / summary.render_s : 0.0;
  std::printf("simulated '%s' (seed %lld) into %s\n", opt.preset.c_str(),
              static_cast<long long>(config.simulation.seed), summary.out_dir.string().c_str());
  std::printf("  frames        %zu over %.1f s\n", summary.frames, summary.duration_s);
  std::printf("  distance      %.1f m\n", summary.distance_m);
  std::printf("  loops         %zu ground-truth pairs, %zu query frames\n", summary.loop_pairs,
              summary.loop_query_frames);
  std::printf("  imu           %zu samples (%s)\n", summary.imu_samples,
              std::string(enum_name(config.simulation.imu_source)).c_str());
  std::printf("  ground truth  %zu rows\n", summary.ground_truth_rows);
  std::printf("  time          %.2f s (rendering %.2f s, %.1f frames/s)\n", summary.elapsed_s,
              summary.render_s, fps);
  return kExitOk;
}

}  // namespace

void add_simulate_command(CLI::App& app, int& exit_code) {
  auto opt = std::make_shared<SimulateOptions>();
  CLI::App* cmd = app.add_subcommand(
      "simulate",
      "Render a synthetic dataset (EuRoC ASL layout: images, IMU, ground truth, simulation.json)");
  std::string presets;
  for (const std::string& name : sim::preset_names()) presets += (presets.empty() ? "" : "|") + name;
  const std::string preset_help =
      "Preset: " + presets + " (" + sim::preset_dir().string() + "/NAME.yaml), or a preset FILE.yaml";
  cmd->add_option("--preset", opt->preset, preset_help)->capture_default_str();
  cmd->add_option("--out", opt->out_dir, "Output directory (must be empty or absent unless --force)")
      ->required();
  cmd->add_option("--seed", opt->seed, "Seed (same seed and inputs: byte-identical output)")
      ->capture_default_str();
  cmd->add_option("--frames", opt->frames, "Render only the first N frames (0 = all)")
      ->capture_default_str()
      ->check(CLI::Range(std::int64_t{0}, std::int64_t{10'000'000}));
  cmd->add_option("--trajectory", opt->trajectory,
                  "Trajectory file replacing the preset's (KITTI poses.txt with times.txt beside it, EuRoC "
                  "ground-truth .csv, or TUM)");
  cmd->add_option("--trajectory-format", opt->trajectory_format, "kitti|euroc|tum (default: detected)")
      ->check(CLI::IsMember({"kitti", "euroc", "tum"}));
  cmd->add_option("--frame-times", opt->frame_times,
                  "Frame times for an EuRoC or TUM --trajectory: an EuRoC cam0/data.csv or one time per line "
                  "(integer ns or decimal seconds); sets simulation.frame_times_file (without it an EuRoC "
                  "trajectory takes the cam0/data.csv beside it, else invents times, with a warning)");
  cmd->add_option("--imu", opt->imu,
                  "Real IMU csv (EuRoC imu0/data.csv) passed through instead of synthesis");
  cmd->add_option("--config", opt->config_file, "YAML file of parameters applied over the preset");
  cmd->add_option("--set", opt->overrides, "Parameter override section.key=value (repeatable)");
  cmd->add_flag("--force", opt->force, "Overwrite the simulation in a non-empty --out");
  cmd->callback([opt, cmd, &exit_code]() {
    opt->seed_given = cmd->count("--seed") > 0;
    try {
      exit_code = run_simulate(*opt);
    } catch (const std::exception& e) {
      spdlog::error("simulate: {}", e.what());
      exit_code = kExitFailure;
    }
  });
}

}  // namespace loopgate::app
