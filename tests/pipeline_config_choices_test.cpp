// The closed word choices of `run` and `compare` (enums with a name table, core/enum_names.hpp): every word
// of every such key loads from YAML and is printed back as written (the config echo and the printed lines); a
// word outside the table is an error naming the key, the file and line, and the allowed words.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "core/error.hpp"
#include "io/config.hpp"
#include "pipeline/pipeline_config.hpp"
#include "test_support.hpp"

namespace loopgate {
namespace {

// section, key, the allowed words in the order of the table.
struct Choice {
  std::string section;
  std::string key;
  std::vector<std::string> words;
};

const std::vector<Choice>& choices() {
  static const std::vector<Choice> table = {
      {"gate", "sigma_norm", {"max_eigen", "trace"}},
      {"dird", "normalization", {"libdird", "l2"}},
      {"dird", "resize", {"nearest", "area"}},
      {"dird", "metric", {"l1", "l2"}},
      {"standardize", "mode", {"off", "batch", "causal"}},
      {"standardize", "distance", {"cosine", "l1"}},
      {"scale", "mode", {"off", "online"}},
      {"seqslam", "resize_method", {"lanczos3", "area"}},
      {"seqslam", "exclusion", {"none", "band", "past"}},
      {"dird_seqslam", "normalization", {"libdird", "l2"}},
      {"dird_seqslam", "resize", {"nearest", "area"}},
      {"dird_seqslam", "standardize", {"off", "batch", "causal"}},
      {"output", "progress", {"auto", "on", "off"}},
      {"posegraph", "odometry_cov", {"model", "odometry"}},
      {"posegraph", "loss", {"cauchy", "huber", "none"}},
      {"posegraph", "sparse_library", {"eigen", "suite_sparse"}},
      {"odometry", "source", {"drift", "file", "ekf", "none", "auto"}},
      {"odometry", "heading_axis", {"auto", "x", "y", "z"}},
      {"odometry", "ekf_up_axis", {"auto", "x", "-x", "y", "-y", "z", "-z"}},
  };
  return table;
}

std::string join(const std::vector<std::string>& words) {
  std::string out;
  for (const std::string& w : words) out += (out.empty() ? "" : "|") + w;
  return out;
}

// The section's fields, loaded from `yaml` (no cross-section validation: only the word is under test).
nlohmann::json loaded_section(const std::string& section, const std::string& yaml) {
  PipelineConfig config;
  const RawConfig raw = RawConfig::from_yaml_string(yaml, "choices.yaml");
  for (const auto& [name, values] : raw.sections()) {
    PipelineConfig::sections(config, [&](std::string_view s, auto& fields) {
      if (s == name) apply_section(name, values, fields);
    });
  }
  return config_to_json(config).at(section);
}

TEST(ConfigChoices, EveryWordLoadsAndIsEchoedAsWritten) {
  for (const Choice& c : choices()) {
    for (const std::string& word : c.words) {
      SCOPED_TRACE(c.section + "." + c.key + " = " + word);
      const nlohmann::json echo = loaded_section(c.section, c.section + ":\n  " + c.key + ": " + word + "\n");
      EXPECT_EQ(echo.at(c.key), word);
    }
  }
  // The printed lines show the default word of each key (no quotes: a word, not free text).
  const PipelineConfig defaults;
  const std::vector<std::string> lines = config_to_lines(defaults);
  for (const char* expected :
       {"gate.sigma_norm = max_eigen", "dird.normalization = libdird", "standardize.mode = off",
        "dird_seqslam.standardize = causal", "output.progress = auto"}) {
    EXPECT_NE(std::find(lines.begin(), lines.end(), expected), lines.end()) << expected;
  }
}

TEST(ConfigChoices, AWordOutsideTheTableNamesKeyFileLineAndTheWords) {
  const std::filesystem::path file = testing::make_temp_dir("config_choices") / "bad.yaml";
  for (const Choice& c : choices()) {
    SCOPED_TRACE(c.section + "." + c.key);
    {
      std::ofstream out(file);
      out << "# a bad word on line 3\n" << c.section << ":\n  " << c.key << ": bogus\n";
    }
    try {
      load_config<PipelineConfig>(file);
      ADD_FAILURE() << "accepted 'bogus'";
    } catch (const ConfigError& e) {
      EXPECT_EQ(std::string(e.what()), c.section + "." + c.key + ": 'bogus' is not one of " + join(c.words) +
                                           " (" + file.string() + ":3)");
    }
  }
  // From the command line the origin is the --set.
  try {
    load_config<PipelineConfig>({}, {"standardize.mode=streaming"});
    ADD_FAILURE() << "accepted 'streaming'";
  } catch (const ConfigError& e) {
    EXPECT_EQ(
        std::string(e.what()),
        "standardize.mode: 'streaming' is not one of off|batch|causal (--set standardize.mode=streaming)");
  }
}

}  // namespace
}  // namespace loopgate
