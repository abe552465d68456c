// Provenance of a run's outputs (src/io/provenance.hpp): version, command line, start time, host
// and the hash of the effective configuration.
#include <gtest/gtest.h>

#include <cctype>
#include <string>

#include "io/provenance.hpp"

namespace loopgate {
namespace {

// `text` matches `pattern`, where '9' stands for one digit and every other character for itself (no
// std::regex: GCC 12 reports -Wmaybe-uninitialized inside <regex> under the asan preset's -O2).
bool matches_digits(const std::string& text, const std::string& pattern) {
  if (text.size() != pattern.size()) return false;
  for (std::size_t k = 0; k < text.size(); ++k) {
    const bool digit = std::isdigit(static_cast<unsigned char>(text[k])) != 0;
    if (pattern[k] == '9' ? !digit : text[k] != pattern[k]) return false;
  }
  return true;
}

// "MAJOR.MINOR.PATCH (...)": the project version, then git describe (or why there is none) in parentheses.
bool is_version(const std::string& text) {
  std::size_t k = 0;
  for (int part = 0; part < 3; ++part) {
    const std::size_t start = k;
    while (k < text.size() && std::isdigit(static_cast<unsigned char>(text[k])) != 0) ++k;
    if (k == start) return false;
    if (part < 2 && (k >= text.size() || text[k++] != '.')) return false;
  }
  return text.size() > k + 3 && text.compare(k, 2, " (") == 0 && text.back() == ')';
}

TEST(Provenance, RecordsTheCommandLineQuotedAndTheStartTime) {
  const char* argv[] = {"loopgate", "run", "--out", "my out", "--set", "x='y'"};
  record_invocation(6, argv);
  const nlohmann::json p = provenance_json(nlohmann::json{{"run", {{"mode", "gated"}}}});
  EXPECT_EQ(p.at("command_line").get<std::string>(), R"(loopgate run --out 'my out' --set 'x='\''y'\''')");
  EXPECT_TRUE(matches_digits(p.at("start_time_utc").get<std::string>(), "9999-99-99T99:99:99Z")) << p.dump();
  EXPECT_FALSE(p.at("host").get<std::string>().empty());
  // The project version first, then git describe (or why there is none) in parentheses.
  EXPECT_TRUE(is_version(p.at("version").get<std::string>())) << p.dump();
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
