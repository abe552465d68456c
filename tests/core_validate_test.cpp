// The validate() helpers of core/validate.hpp: the messages name the key, the value and what is allowed.
#include <gtest/gtest.h>

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

}  // namespace
}  // namespace loopgate
