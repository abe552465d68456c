// The validate() helpers of core/validate.hpp: the messages name the key, the value and what is allowed.
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "core/error.hpp"
#include "core/validate.hpp"

namespace loopgate {
namespace {

std::string message_of(const auto& call) {
  try {
    call();
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "(no ConfigError)";
}

TEST(CoreValidate, RequireOneOfNamesKeyValueAndChoices) {
  EXPECT_NO_THROW(require_one_of("odometry.source", "file", {"drift", "file"}));
  EXPECT_EQ(message_of([] {
              require_one_of("odometry.source", "vio", {"drift", "file", "ekf"});
            }),
            "odometry.source: 'vio' is not one of drift|file|ekf");
}

TEST(CoreValidate, RequireNamesKeyMessageAndValue) {
  EXPECT_NO_THROW(require(true, "odometry.seed", ">= 0", "1"));
  EXPECT_EQ(message_of([] { require(false, "odometry.file_max_gap_s", "> 0", "0"); }),
            "odometry.file_max_gap_s: must be > 0 (got 0)");
}

// Every parameter is bounded, and the error says the bound.
TEST(CoreValidate, RequireInSaysTheBound) {
  EXPECT_NO_THROW(require_in("match.nms_half_window", 59, 0, 1000, "frames"));
  EXPECT_EQ(message_of([] { require_in("match.nms_half_window", 2000000000, 0, 1000, "frames"); }),
            "match.nms_half_window: must be in [0, 1000] frames (got 2000000000)");
  EXPECT_EQ(message_of([] { require_in("run.deadline_ms", 1e300, 0.0, 3.6e6, "ms"); }),
            "run.deadline_ms: must be in [0, 3600000] ms (got 1e+300)");
  EXPECT_NE(message_of([] { require_in("gate.beta_m", std::nan(""), 0.0, 1e5); }), "(no ConfigError)");
}

// A 20 MB field quoted into an error (and so into summary.json) is capped.
TEST(CoreValidate, QuotedFieldsAreCapped) {
  EXPECT_EQ(quote_excerpt("0.5"), "'0.5'");
  EXPECT_EQ(quote_excerpt("a\tb"), "'a?b'");
  const std::string huge(20'000'000, '7');
  const std::string quoted = quote_excerpt(huge);
  EXPECT_LT(quoted.size(), 100u);
  EXPECT_NE(quoted.find("...' (20000000 bytes)"), std::string::npos) << quoted;
}

}  // namespace
}  // namespace loopgate
