// The channel of gate.feedback (pipeline/gate_feedback.hpp): the gate gets exactly the verified loops of the
// query frames up to its limit, waits while one of them is still being verified, never waits for later ones,
// and refuses (logic error, never a wait) a limit beyond the detections known to be final.
#include <gtest/gtest.h>

#include <chrono>
#include <future>
#include <optional>
#include <stdexcept>

#include "pipeline/frame/gate_feedback.hpp"

namespace loopgate {
namespace {

FeedbackLoop loop(std::size_t query, std::size_t reference) {
  FeedbackLoop l;
  l.query = query;
  l.reference = reference;
  return l;
}

const auto kAny = [](const FeedbackLoop&) { return true; };

TEST(PipelineGateFeedback, LatestVerifiedLoopUpToTheLimit) {
  GateFeedback f;
  f.set_lag(10);
  f.final_through(100);
  for (const auto& [q, r] : {std::pair{20, 5}, {30, 6}, {30, 7}, {40, 8}, {50, 9}}) f.submitted(q);
  const FeedbackLoop l20 = loop(20, 5), l30a = loop(30, 6), l30b = loop(30, 7), l50 = loop(50, 9);
  f.done(20, &l20);
  f.done(30, &l30a);
  f.done(30, &l30b);
  f.done(40, nullptr);  // rejected
  f.done(50, &l50);
  EXPECT_FALSE(f.anchor_through(19, kAny));
  EXPECT_EQ(f.anchor_through(20, kAny)->reference, 5u);
  EXPECT_EQ(f.anchor_through(45, kAny)->reference, 7u);  // largest query, then the last submitted
  EXPECT_EQ(f.anchor_through(50, kAny)->reference, 9u);
  // Going back from the latest to the first one the gate can use.
  const auto not_9_or_7 = [](const FeedbackLoop& l) { return l.reference != 9 && l.reference != 7; };
  EXPECT_EQ(f.anchor_through(60, not_9_or_7)->reference, 6u);
  EXPECT_EQ(f.frames_waited(), 0u);
}

TEST(PipelineGateFeedback, WaitsOnlyForLoopsUpToTheLimit) {
  GateFeedback f;
  f.set_lag(10);
  f.final_through(100);
  f.submitted(80);  // pending, beyond the limit: no wait
  const FeedbackLoop early = loop(20, 3);
  f.submitted(20);
  f.done(20, &early);
  EXPECT_EQ(f.anchor_through(70, kAny)->query, 20u);

  f.submitted(60);  // pending, within the limit: the gate waits for it
  auto gate = std::async(std::launch::async, [&] { return f.anchor_through(70, kAny); });
  EXPECT_EQ(gate.wait_for(std::chrono::milliseconds(100)), std::future_status::timeout);
  const FeedbackLoop late = loop(60, 4);
  f.done(60, &late);
  ASSERT_EQ(gate.wait_for(std::chrono::seconds(10)), std::future_status::ready);
  EXPECT_EQ(gate.get()->query, 60u);
  EXPECT_EQ(f.frames_waited(), 1u);
}

TEST(PipelineGateFeedback, ALimitBeyondTheFinalDetectionsIsALogicError) {
  GateFeedback f;
  f.set_lag(10);
  EXPECT_THROW(f.anchor_through(0, kAny), std::logic_error);
  f.final_through(30);
  EXPECT_FALSE(f.anchor_through(30, kAny));
  EXPECT_THROW(f.anchor_through(31, kAny), std::logic_error);
  EXPECT_THROW(f.done(5, nullptr), std::logic_error);  // never submitted
}

}  // namespace
}  // namespace loopgate
