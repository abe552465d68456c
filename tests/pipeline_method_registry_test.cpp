// The method registry: run.method naming a row sets the detector, mode and standardisation; the detector
// words keep meaning "this detector, in run.mode"; unknown names and a contradicting --mode are errors.
#include <gtest/gtest.h>

#include <set>
#include <string>

#include "core/error.hpp"
#include "io/config.hpp"
#include "pipeline/methods/method_registry.hpp"
#include "pipeline/pipeline_config.hpp"

namespace loopgate {
namespace {

PipelineConfig load(const std::string& yaml, const std::vector<FlagValue>& flags = {}) {
  RawConfig raw = RawConfig::from_yaml_string(yaml);
  for (const FlagValue& f : flags) {
    const std::size_t dot = f.key.find('.');
    raw.set(f.key.substr(0, dot), f.key.substr(dot + 1), f.value, f.flag);
  }
  expand_method_name(raw);
  PipelineConfig config;
  apply_config(raw, config);
  return config;
}

TEST(MethodRegistry, NamesAreUniqueAndEveryRowIsFoundByItsWords) {
  std::set<std::string> names;
  for (const MethodEntry& m : kMethods) {
    EXPECT_TRUE(names.insert(m.name).second) << m.name;
    EXPECT_EQ(find_method_entry(m.name), &m);
    // The words of a row find it, or the first row with the same words (a later row over the same
    // detector, mode and standardisation is reached by its name: run.method_row).
    const MethodEntry* by_words =
        find_method_entry(enum_name(m.detector), enum_name(m.mode), enum_name(m.standardize));
    ASSERT_NE(by_words, nullptr) << m.name;
    EXPECT_LE(by_words, &m) << m.name;
    EXPECT_EQ(by_words->detector, m.detector) << m.name;
    EXPECT_EQ(by_words->mode, m.mode) << m.name;
  }
}

TEST(MethodRegistry, TheRowRunMethodNamedWinsOverItsWords) {
  PipelineConfig c;  // dird, gated, standardize.mode off: the words of row "gated"
  EXPECT_EQ(method_entry(c)->name, std::string("gated"));
  c.run.method_row = "std-gated";
  EXPECT_EQ(method_entry(c)->name, std::string("std-gated"));
  c.run.mode = RunMode::kOdometry;
  EXPECT_EQ(method_entry(c), nullptr);
}

TEST(MethodRegistry, RunMethodNamesARow) {
  const PipelineConfig c = load("run:\n  method: dird-seqslam-gated\n  mode: full\n");
  EXPECT_EQ(c.run.method, Detector::kDirdSeqSlam);
  EXPECT_EQ(c.run.mode, RunMode::kGated);  // the row's mode wins over the file's
  const PipelineConfig s = load("run:\n  method: std-full\n");
  EXPECT_EQ(s.run.method, Detector::kDird);
  EXPECT_EQ(s.run.mode, RunMode::kFull);
  EXPECT_EQ(s.standardize.mode, StandardizeMode::kCausal);
  EXPECT_EQ(method_entry(s)->name, std::string("std-full"));
}

TEST(MethodRegistry, OldSpellingsStayAliases) {
  const PipelineConfig c = load("run:\n  method: seqslam\n  mode: gated\n");
  EXPECT_EQ(c.run.method, Detector::kSeqSlam);
  EXPECT_EQ(c.run.mode, RunMode::kGated);
  EXPECT_EQ(method_entry(c)->name, std::string("seqslam-gated"));
  const PipelineConfig d = load("run:\n  method: dird-seqslam\n", {{"run.mode", "full", "--mode"}});
  EXPECT_EQ(method_entry(d)->name, std::string("dird-seqslam"));
}

TEST(MethodRegistry, UnknownNameAndContradictingModeAreErrors) {
  EXPECT_THROW(load("run:\n  method: dird-gated-please\n"), ConfigError);
  EXPECT_THROW(load("run:\n  method: seqslam-gated\n", {{"run.mode", "full", "--mode"}}), ConfigError);
}

TEST(MethodRegistry, SeqSlamRowsRefuseGateFeedbackAndNameTheirMargin) {
  for (const MethodEntry& m : kMethods) {
    EXPECT_EQ(m.streams_loops, m.detector != Detector::kSeqSlam) << m.name;
    EXPECT_EQ(m.margin == MarginKey::kSeqSlamExclusion, m.detector == Detector::kSeqSlam) << m.name;
    EXPECT_EQ(m.two_sequence != nullptr, m.mode == RunMode::kFull) << m.name;
  }
}

}  // namespace
}  // namespace loopgate
