// The closed word choices of `simulate` (enums with a name table, core/enum_names.hpp): every word loads from
// YAML and is echoed as written; a word outside the table is an error naming the key, the file and line, and
// the allowed words.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "core/error.hpp"
#include "io/config.hpp"
#include "sim/simulator.hpp"
#include "test_support.hpp"

namespace loopgate::sim {
namespace {

struct Choice {
  std::string section;
  std::string key;
  std::vector<std::string> words;
};

const std::vector<Choice>& choices() {
  static const std::vector<Choice> table = {
      {"simulation", "trajectory_format", {"procedural", "kitti", "euroc", "tum"}},
      {"simulation", "imu_source", {"synthesised", "file"}},
      {"camera", "distortion_model", {"none", "radtan"}},
      {"illumination", "kind", {"constant", "day-to-night", "jump"}},
      {"illumination", "night_model", {"ambient_noise", "lamps"}},
      {"route", "shape", {"circuit", "waypoints"}},
      {"world", "kind", {"street", "hall"}},
  };
  return table;
}

std::string join(const std::vector<std::string>& words) {
  std::string out;
  for (const std::string& w : words) out += (out.empty() ? "" : "|") + w;
  return out;
}

TEST(SimConfigChoices, EveryWordLoadsAndIsEchoedAsWritten) {
  for (const Choice& c : choices()) {
    for (const std::string& word : c.words) {
      SCOPED_TRACE(c.section + "." + c.key + " = " + word);
      SimulationConfig config;
      const RawConfig raw =
          RawConfig::from_yaml_string(c.section + ":\n  " + c.key + ": " + word + "\n", "choices.yaml");
      const auto& values = raw.sections().at(c.section);
      SimulationConfig::sections(config, [&](std::string_view s, auto& fields) {
        if (s == c.section) apply_section(c.section, values, fields);
      });
      EXPECT_EQ(config_to_json(config).at(c.section).at(c.key), word);
    }
  }
}

TEST(SimConfigChoices, AWordOutsideTheTableNamesKeyFileLineAndTheWords) {
  const std::filesystem::path file = loopgate::testing::make_temp_dir("sim_config_choices") / "bad.yaml";
  for (const Choice& c : choices()) {
    SCOPED_TRACE(c.section + "." + c.key);
    {
      std::ofstream out(file);
      out << c.section << ":\n  " << c.key << ": bogus\n";
    }
    try {
      load_config<SimulationConfig>(file);
      ADD_FAILURE() << "accepted 'bogus'";
    } catch (const ConfigError& e) {
      EXPECT_EQ(std::string(e.what()), c.section + "." + c.key + ": 'bogus' is not one of " + join(c.words) +
                                           " (" + file.string() + ":2)");
    }
  }
}

}  // namespace
}  // namespace loopgate::sim
