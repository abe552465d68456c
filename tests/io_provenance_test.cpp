// Provenance of a run's outputs (src/io/provenance.hpp, issue 14): version, command line, start time, host
// and the hash of the effective configuration.
#include <gtest/gtest.h>

#include <regex>
#include <string>

#include "io/provenance.hpp"

namespace loopgate {
namespace {

TEST(Provenance, RecordsTheCommandLineQuotedAndTheStartTime) {
  const char* argv[] = {"loopgate", "run", "--out", "my out", "--set", "x='y'"};
  record_invocation(6, argv);
  const nlohmann::json p = provenance_json(nlohmann::json{{"run", {{"mode", "gated"}}}});
  EXPECT_EQ(p.at("command_line").get<std::string>(), R"(loopgate run --out 'my out' --set 'x='\''y'\''')");
  EXPECT_TRUE(std::regex_match(p.at("start_time_utc").get<std::string>(),
                               std::regex(R"(\d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ)")))
      << p.dump();
  EXPECT_FALSE(p.at("host").get<std::string>().empty());
  // The project version first, then git describe (or why there is none) in parentheses.
  EXPECT_TRUE(std::regex_match(p.at("version").get<std::string>(), std::regex(R"(\d+\.\d+\.\d+ \(.+\))")))
      << p.dump();
}

TEST(Provenance, ConfigHashFollowsTheEffectiveConfiguration) {
  const nlohmann::json a = {{"run", {{"mode", "gated"}, {"threads", 2}}}};
  nlohmann::json b = a;
  b["run"]["threads"] = 1;
  const std::string hash_a = provenance_json(a).at("config_hash").get<std::string>();
  EXPECT_EQ(hash_a.size(), 16u);
  EXPECT_EQ(hash_a, provenance_json(a).at("config_hash").get<std::string>());
  EXPECT_NE(hash_a, provenance_json(b).at("config_hash").get<std::string>());
  // FNV-1a 64 reference values.
  EXPECT_EQ(fnv1a_hex(""), "cbf29ce484222325");
  EXPECT_EQ(fnv1a_hex("a"), "af63dc4c8601ec8c");
}

}  // namespace
}  // namespace loopgate
