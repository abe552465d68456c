#include "pipeline/pipeline_config.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <utility>
#include <vector>

#include "core/error.hpp"
#include "io/config.hpp"
#include "pipeline/methods/method_registry.hpp"
#include "test_support.hpp"

namespace loopgate {
namespace {

std::filesystem::path config_file(const std::string& name) {
  return std::filesystem::path(LOOPGATE_SOURCE_DIR) / "configs" / (name + ".yaml");
}

std::string error_of(const std::vector<std::string>& overrides) {
  try {
    load_config<PipelineConfig>({}, overrides);
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "";
}

// The error of load_pipeline_config, which adds the checks that depend on the method's row.
std::string method_error_of(const std::vector<std::string>& overrides) {
  try {
    load_pipeline_config({}, overrides, {}, ConfigPaths::kAsWritten);
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "";
}

TEST(PipelineConfig, ShippedConfigsLoad) {
  for (const std::string name : {"demo", "kitti00-thumbs", "euroc-mh05", "kitti00"}) {
    SCOPED_TRACE(name);
    const auto config = load_config<PipelineConfig>(config_file(name));
    EXPECT_FALSE(config.run.dataset.empty());
    EXPECT_EQ(config.run.rate, "max");
    EXPECT_EQ(config.run.threads, 2);
  }
  const auto thumbs = load_config<PipelineConfig>(config_file("kitti00-thumbs"));
  EXPECT_EQ(thumbs.odometry.source, OdometrySourceKind::kDrift);
  EXPECT_EQ(thumbs.odometry.heading_axis, HeadingAxis::kY);
  const auto mh05 = load_config<PipelineConfig>(config_file("euroc-mh05"));
  EXPECT_EQ(mh05.odometry.source, OdometrySourceKind::kFile);
  EXPECT_DOUBLE_EQ(mh05.odometry.file_sigma2_b_m2_per_m, 0.002);
}

TEST(PipelineConfig, SetOverridesEverySection) {
  const auto config = load_config<PipelineConfig>(
      config_file("demo"),
      {"run.rate=1.5", "sync.max_gap_ms=7.5", "odometry.seed=42", "output.trace=true", "run.frames=10:20"});
  EXPECT_EQ(config.run.rate_factor(), 1.5);
  EXPECT_DOUBLE_EQ(config.sync.max_gap_ms, 7.5);
  EXPECT_EQ(config.odometry.seed, 42);
  EXPECT_TRUE(config.output.trace);
  EXPECT_EQ(config.run.frame_range(100), std::make_pair(std::size_t{10}, std::size_t{20}));
  EXPECT_EQ(config.run.frame_range(15), std::make_pair(std::size_t{10}, std::size_t{15}));
}

TEST(PipelineConfig, BadValuesNameTheKey) {
  EXPECT_NE(error_of({"run.rate=fast"}).find("run.rate: 'fast' is not 'max' or a positive number"),
            std::string::npos);
  EXPECT_NE(error_of({"run.rate=-1"}).find("run.rate"), std::string::npos);
  EXPECT_NE(error_of({"run.threads=0"}).find("run.threads: must be in 1..256"), std::string::npos);
  EXPECT_NE(error_of({"run.threads=two"}).find("run.threads: expected an integer"), std::string::npos);
  EXPECT_NE(error_of({"run.decode=sometimes"}).find("run.decode: 'sometimes' is not one of lazy|all"),
            std::string::npos);
  EXPECT_NE(error_of({"run.frames=20:10"}).find("run.frames"), std::string::npos);
  EXPECT_NE(error_of({"run.frames=a:b"}).find("run.frames"), std::string::npos);
  EXPECT_NE(error_of({"odometry.source=ekf2"}).find("odometry.source: 'ekf2' is not one of drift|file"),
            std::string::npos);
  EXPECT_NE(error_of({"odometry.file_format=csv"})
                .find("odometry.file_format: 'csv' is not one of auto|tum|kitti|euroc"),
            std::string::npos);
  EXPECT_NE(error_of({"odometry.sorce=drift"}).find("unknown key 'odometry.sorce'"), std::string::npos);
  EXPECT_NE(error_of({"bogus.radius=1"}).find("unknown section 'bogus'"), std::string::npos);
  EXPECT_NE(error_of({"output.progress=maybe"}).find("output.progress"), std::string::npos);
}

// Parameters that could hang a run or exhaust memory are bounded, and the error says the bound.
TEST(PipelineConfig, EveryParameterIsBounded) {
  EXPECT_NE(error_of({"match.nms_half_window=2000000000"})
                .find("match.nms_half_window: must be in [0, 1000] frames (got 2000000000)"),
            std::string::npos);
  for (const std::string set :
       {"match.sequence_length=100000", "match.max_step=1000000", "match.tau3=5", "gate.kdtree_leaf_size=0",
        "gate.area_margin_query_frames=1000000", "seqslam.image_width_px=100000",
        "seqslam.velocity_max=1e300", "seqslam.sequence_length_frames=200000", "run.max_in_flight=100000000",
        "run.image_cache_frames=2000000000", "output.flush_every=2000000000", "ekf.image_blur_sigma_px=1e6",
        "ekf.max_features=2000000000", "sync.max_gap_ms=1e300", "eval.truth_radius_m=1e300",
        "eval.min_travel_m=1e300", "eval.min_travel_m=-1", "odometry.initial_sigma_m=1e300"}) {
    SCOPED_TRACE(set);
    const std::string error = error_of({set});
    EXPECT_NE(error.find(set.substr(set.find('.') + 1, set.find('=') - set.find('.') - 1)), std::string::npos)
        << error;
    EXPECT_NE(error.find("must be"), std::string::npos) << error;
  }
  // The sections main added with dird-seqslam, and the standardisation statistics it shares: each message
  // names the full key and states the bound.
  for (const auto& [set, bound] : std::vector<std::pair<std::string, std::string>>{
           {"dird_seqslam.contrast_half_window_frames=2000000000", "in [1, 1000] frames"},
           {"dird_seqslam.contrast_min_cells=2000000000", "in [2, 2 * contrast_half_window_frames + 1]"},
           {"dird_seqslam.velocity_min=1e300", "in (0, 10] reference frames per query frame"},
           {"dird_seqslam.velocity_max=1e300", "in [velocity_min, 10] reference frames per query frame"},
           {"dird_seqslam.velocity_steps=2000000000", "in [1, 64]"},
           {"dird_seqslam.min_score=1e300", "in [-100, 100] (a mean z"},
           {"standardize.warm_up=2000000000", "in [2, 1000000] observations"},
           {"standardize.window=2000000000", "or in [standardize.warm_up, 1000000] observations"},
           {"standardize.refresh_every=2000000000", "in [1, 1000000] observations"},
           {"standardize.observe_every=2000000000", "in [1, 1000000] frames"},
           {"standardize.min_stddev=1e300", "in (0, 128] descriptor byte units"},
           {"scale.min_distances=9000000000000000000", "in [1, 1000000000] distances"}}) {
    SCOPED_TRACE(set);
    const std::string error = error_of({set});
    EXPECT_EQ(error.rfind(set.substr(0, set.find('=')) + ": must be", 0), 0u) << error;
    EXPECT_NE(error.find(bound), std::string::npos) << error;
  }
  // Choices are bounded by their list, which the message gives.
  for (const std::string set : {"dird.resize=cubic", "dird_seqslam.resize=cubic",
                                "dird_seqslam.normalization=none", "dird_seqslam.standardize=always"}) {
    SCOPED_TRACE(set);
    const std::string error = error_of({set});
    EXPECT_EQ(error.rfind(set.substr(0, set.find('=')) + ": '", 0), 0u) << error;
    EXPECT_NE(error.find("is not one of"), std::string::npos) << error;
  }
}

// --rate 1e-300 overflowed (t - t0) / rate in int64; --frames 500:100 said "no frame of the
// 18446744073709551615 in the dataset".
TEST(PipelineConfig, RatesAndRangesSayWhatIsWrong) {
  EXPECT_NE(
      error_of({"run.rate=1e-300"}).find("run.rate: '1e-300' is out of range: 'max' or a rate in [0.001, "),
      std::string::npos);
  EXPECT_NE(error_of({"run.rate=1e300"}).find("out of range"), std::string::npos);
  EXPECT_EQ(error_of({"run.rate=0.5"}), "");
  EXPECT_EQ(error_of({"run.frames=500:100"}),
            "run.frames: '500:100' is empty: A (500) must be below B (100); B is exclusive (--set "
            "run.frames=500:100)");
  RunConfig run;
  run.frames = "5000:";
  try {
    run.frame_range(4540);
    FAIL() << "no ConfigError";
  } catch (const ConfigError& e) {
    EXPECT_STREQ(e.what(),
                 "run.frames: '5000:' starts at frame 5000, and the dataset has 4540 frames (0..4539)");
  }
  run.frames = "10:20";
  EXPECT_EQ(run.frame_range(15), (std::pair<std::size_t, std::size_t>{10, 15}));
}

// odometry.source none: appearance only, with run.mode full; what needs poses is an error naming
// the key and the way out.
TEST(PipelineConfig, NoOdometryOnlyWithFullMode) {
  EXPECT_EQ(error_of({"odometry.source=none", "run.mode=full"}), "");
  EXPECT_EQ(error_of({"odometry.source=none", "run.mode=full", "run.method=seqslam"}), "");
  EXPECT_EQ(
      error_of({"odometry.source=none"}),
      "run.mode: 'gated' needs poses for the pose gate, and odometry.source is none (appearance only): use "
      "run.mode full (--mode full), or an odometry source");
  EXPECT_NE(
      error_of({"odometry.source=none", "run.mode=odometry"}).find("run.mode: 'odometry' estimates poses"),
      std::string::npos);
  EXPECT_NE(error_of({"odometry.source=none", "run.mode=full", "verify.enabled=true"})
                .find("verify.enabled: geometric verification triangulates with the odometry poses"),
            std::string::npos);
  EXPECT_NE(error_of({"odometry.source=nothing"})
                .find("odometry.source: 'nothing' is not one of "
                      "drift|file|ekf|none|auto"),
            std::string::npos);
  const auto shipped = load_config<PipelineConfig>(config_file("rtabmap-samples"));
  EXPECT_EQ(shipped.odometry.source, OdometrySourceKind::kNone);
  EXPECT_EQ(shipped.run.mode, RunMode::kFull);
  EXPECT_FALSE(shipped.eval.truth_pairs_file.empty());
}

// A bound error names where the key was set: the file and line, or the --set.
TEST(PipelineConfig, BoundErrorsNameWhereTheKeyWasSet) {
  const std::filesystem::path file = std::filesystem::temp_directory_path() / "loopgate-bound-origin.yaml";
  std::ofstream(file) << "eval:\n  truth_radius_m: 2\n  min_travel_m: -1\n";
  try {
    load_config<PipelineConfig>(file);
    FAIL() << "expected ConfigError";
  } catch (const ConfigError& e) {
    EXPECT_EQ(std::string(e.what()),
              "eval.min_travel_m: must be in [0, 1e+06] m (0 = no travel needed) (got -1) (" + file.string() +
                  ":3)");
  }
  std::filesystem::remove(file);
  EXPECT_EQ(error_of({"eval.min_travel_m=1e9"}),
            "eval.min_travel_m: must be in [0, 1e+06] m (0 = no travel needed) (got 1e+09) (--set "
            "eval.min_travel_m=1e9)");
}

// gate.feedback needs verified loops while the stream runs: verify.enabled, and not SeqSLAM; the
// error names the key and where it was set.
TEST(PipelineConfig, GateFeedbackNeedsVerificationAndAStreamingMethod) {
  EXPECT_EQ(error_of({"gate.feedback=true", "verify.enabled=true"}), "");
  EXPECT_EQ(error_of({"gate.feedback=true", "verify.enabled=true", "run.method=dird-seqslam"}), "");
  EXPECT_EQ(
      error_of({"gate.feedback=true"}),
      "gate.feedback: the gate is re-anchored on verified loop closures, and verify.enabled is false: set "
      "verify.enabled=true or gate.feedback=false (--set gate.feedback=true)");
  EXPECT_EQ(method_error_of({"gate.feedback=true", "verify.enabled=true", "run.method=dird-seqslam"}), "");
  EXPECT_NE(method_error_of({"gate.feedback=true", "verify.enabled=true", "run.method=seqslam"})
                .find("gate.feedback: run.method seqslam decides its loops at the end of the stream"),
            std::string::npos);
  const std::filesystem::path file = std::filesystem::temp_directory_path() / "loopgate-feedback-origin.yaml";
  std::ofstream(file) << "verify:\n  enabled: false\ngate:\n  beta_m: 4\n  feedback: true\n";
  try {
    load_config<PipelineConfig>(file);
    FAIL() << "expected ConfigError";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("gate.feedback: the gate is re-anchored"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("(" + file.string() + ":5)"), std::string::npos) << e.what();
  }
  std::filesystem::remove(file);
  EXPECT_FALSE(PipelineConfig{}.gate.feedback);  // off by default
}

TEST(PipelineConfig, EchoHasEverySection) {
  PipelineConfig config;
  const auto json = config_to_json(config);
  for (const char* section : {"run", "sync", "odometry", "output"})
    EXPECT_TRUE(json.contains(section)) << section;
  EXPECT_EQ(json["run"]["rate"].get<std::string>(), "max");
  EXPECT_EQ(json["odometry"]["seed"].get<std::int64_t>(), 1);
}

// A relative path in a YAML config is relative to that file's folder, whatever the working directory; one
// given on the command line (--set, --dataset) stays relative to the working directory. A path that names
// nothing is an error naming the key, the config file and line, and the resolved path.
TEST(PipelineConfig, PathsInAConfigAreRelativeToIt) {
  const std::filesystem::path dir = testing::make_temp_dir("config-paths");
  std::filesystem::create_directories(dir / "elsewhere" / "data" / "x");
  std::ofstream(dir / "elsewhere" / "data" / "pairs.csv") << "query_index0,match_index0\n";
  std::ofstream(dir / "elsewhere" / "mine.yaml") << "run:\n  dataset: data/x\neval:\n"
                                                    "  truth_pairs_file: data/pairs.csv\n";
  const auto config =
      load_config<PipelineConfig>(dir / "elsewhere" / "mine.yaml", {}, {}, ConfigPaths::kMustExist);
  EXPECT_EQ(config.run.dataset, (dir / "elsewhere" / "data" / "x").string());
  EXPECT_EQ(config.eval.truth_pairs_file, (dir / "elsewhere" / "data" / "pairs.csv").string());
  // The command line's paths are the working directory's.
  const auto flagged =
      load_config<PipelineConfig>(dir / "elsewhere" / "mine.yaml", {"eval.truth_pairs_file=p.csv"},
                                  {{"run.dataset", "data/y", "--dataset"}}, ConfigPaths::kMustExist);
  EXPECT_EQ(flagged.run.dataset, "data/y");
  EXPECT_EQ(flagged.eval.truth_pairs_file, "p.csv");

  std::ofstream(dir / "elsewhere" / "missing.yaml") << "# a comment\nrun:\n  dataset: data/absent\n";
  std::string error;
  try {
    load_config<PipelineConfig>(dir / "elsewhere" / "missing.yaml", {}, {}, ConfigPaths::kMustExist);
  } catch (const ConfigError& e) {
    error = e.what();
  }
  EXPECT_NE(error.find("run.dataset: 'data/absent'"), std::string::npos) << error;
  EXPECT_NE(error.find((dir / "elsewhere" / "missing.yaml").string() + ":3"), std::string::npos) << error;
  EXPECT_NE(error.find((dir / "elsewhere" / "data" / "absent").string()), std::string::npos) << error;
  // Read for its values only, the config loads with the path resolved.
  EXPECT_EQ(load_config<PipelineConfig>(dir / "elsewhere" / "missing.yaml").run.dataset,
            (dir / "elsewhere" / "data" / "absent").string());
}

// odometry.file is read only by odometry.source file: a config naming a trajectory that is absent here (a
// file of data the user does not have) still runs with another source, and is refused with the file source.
TEST(PipelineConfig, AnOdometryFileIsRequiredOnlyWhenItIsTheSource) {
  const std::filesystem::path dir = testing::make_temp_dir("config-odometry-file");
  std::ofstream(dir / "c.yaml") << "odometry:\n  source: file\n  file: absent/poses.txt\n";
  std::string error;
  try {
    load_config<PipelineConfig>(dir / "c.yaml", {}, {}, ConfigPaths::kMustExist);
  } catch (const ConfigError& e) {
    error = e.what();
  }
  EXPECT_NE(
      error.find("odometry.file: 'absent/poses.txt' (" + (dir / "c.yaml").string() + ":3) names nothing"),
      std::string::npos)
      << error;
  for (const char* source : {"ekf", "drift", "auto"}) {
    SCOPED_TRACE(source);
    const auto config = load_config<PipelineConfig>(
        dir / "c.yaml", {std::string("odometry.source=") + source}, {}, ConfigPaths::kMustExist);
    EXPECT_EQ(config.odometry.file, (dir / "absent" / "poses.txt").string());
  }
  std::ofstream(dir / "d.yaml") << "odometry:\n  file: absent/poses.txt\n";  // the default source, auto
  EXPECT_NO_THROW(load_config<PipelineConfig>(dir / "d.yaml", {}, {}, ConfigPaths::kMustExist));
}

}  // namespace
}  // namespace loopgate
