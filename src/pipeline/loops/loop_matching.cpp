#include "pipeline/loops/loop_matching.hpp"

#include <spdlog/fmt/fmt.h>

#include <stdexcept>

#include "pipeline/loops/loops_writer.hpp"
#include "stages/match/match_outcome.hpp"

namespace loopgate {

LoopMatching::LoopMatching(const MethodContext& context)
    : context_(context), matcher_(context.config.match, SequenceMatcher::Mode::kSingleSequence, 0) {}

void LoopMatching::push(std::size_t seq, const std::vector<SimilarityEntry>& row) {
  MatchOutput output;
  matcher_.push(static_cast<std::int64_t>(seq), row, output);
  handle(output);
}

void LoopMatching::flush() {
  MatchOutput output;
  matcher_.flush(output);
  handle(output);
}

void LoopMatching::handle(const MatchOutput& output) {
  LoopsWriter& loops = context_.loops;
  for (const LoopClosure& loop : output.loops) {
    if (!first_loop_seq_) first_loop_seq_ = loop.i;
    loops.write(context_.seqs.frame(loop.i), context_.seqs.frame(loop.j), context_.seqs.t_ns(loop.i),
                context_.seqs.t_ns(loop.j), loop.score);
  }
  if (!output.loops.empty()) loops.flush();
  if (output.frames.empty()) return;
  std::lock_guard lock(finished_mutex_);
  for (const FrameMatchStatus& status : output.frames) finished_.push_back(status);
}

std::optional<FrameVerdict> LoopMatching::detection(std::size_t seq, bool described, bool outside_areas) {
  std::lock_guard lock(finished_mutex_);
  while (!finished_.empty() && static_cast<std::size_t>(finished_.front().i) < seq) finished_.pop_front();
  if (finished_.empty()) return std::nullopt;
  const FrameMatchStatus status = finished_.front();
  if (static_cast<std::size_t>(status.i) != seq) {
    throw std::logic_error(fmt::format("match status of seq {} while seq {} waits", status.i, seq));
  }
  finished_.pop_front();
  const MatchConfig& match = context_.config.match;
  MatchOutcomeContext c;
  c.described = described;
  c.outside_areas = outside_areas;
  c.before_margin = seq < static_cast<std::size_t>(match.margin);
  c.margin_frames = match.margin;
  c.tau1 = context_.config.dird.tau1;
  c.dp_threshold = match.dp_threshold();
  return FrameVerdict{c.described, match_detection(status, c)};
}

nlohmann::json LoopMatching::summary() const {
  return {{"detection", {{"nms_delay_frames", matcher_.emission_delay()}}}};
}

}  // namespace loopgate
