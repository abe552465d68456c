// Process-wide stop requests: the first signal asks to stop, a second one to abort long loops.
#include <gtest/gtest.h>

#include <csignal>

#include "core/stop_request.hpp"

namespace loopgate {
namespace {

TEST(CoreStopRequest, FirstSignalStopsSecondAborts) {
  stop_request::reset();
  EXPECT_FALSE(stop_request::stop());
  EXPECT_EQ(stop_request::exit_status(), 0);
  EXPECT_NO_THROW(stop_request::check_abort("loop"));
  stop_request::record(SIGTERM);
  EXPECT_TRUE(stop_request::stop());
  EXPECT_TRUE(stop_request::stop_flag().load());
  EXPECT_FALSE(stop_request::abort());
  EXPECT_NO_THROW(stop_request::check_abort("loop"));  // the first signal drains, it does not abort
  EXPECT_EQ(stop_request::exit_status(), 143);
  stop_request::record(SIGINT);
  EXPECT_TRUE(stop_request::abort());
  EXPECT_EQ(stop_request::signal_number(), SIGTERM);  // the first one decides the exit status
  try {
    stop_request::check_abort("SeqSLAM search");
    FAIL() << "no Interrupted";
  } catch (const Interrupted& e) {
    EXPECT_STREQ(e.what(), "SeqSLAM search: aborted by a second SIGTERM");
  }
  stop_request::reset();
  EXPECT_FALSE(stop_request::stop());
  EXPECT_FALSE(stop_request::abort());
  stop_request::record(SIGHUP);
  EXPECT_EQ(stop_request::exit_status(), 129);
  EXPECT_EQ(stop_request::signal_name(SIGINT), "SIGINT");
  stop_request::reset();
}

}  // namespace
}  // namespace loopgate
