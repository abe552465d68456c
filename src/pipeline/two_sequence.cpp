#include "pipeline/two_sequence.hpp"

#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>
#include <sys/resource.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdlib>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

#include "core/error.hpp"
#include "io/config.hpp"
#include "io/dataset.hpp"
#include "io/writers.hpp"
#include "stages/dird/dird_extractor.hpp"
#include "stages/dird/dird_similarity.hpp"
#include "stages/match/sequence_matcher.hpp"

namespace loopgate {

namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

double peak_rss_mb() {
  rusage usage{};
  ::getrusage(RUSAGE_SELF, &usage);
  return static_cast<double>(usage.ru_maxrss) / 1024.0;
}

// Runs body(k) for k in [0, count) on `threads` threads (plain std::threads: thread start and join
// order everything the caller prepared and the bodies wrote, visibly for ThreadSanitizer too). Indices are
// handed out in small blocks; each body writes only its own outputs, so the result does not depend on
// the thread count. The first exception of a body is rethrown after the join.
template <class Body>
void parallel_indices(int threads, std::size_t count, Body body) {
  constexpr std::size_t kBlock = 16;
  std::atomic<std::size_t> next{0};
  std::exception_ptr error;
  std::mutex error_mutex;
  const auto worker = [&] {
    for (;;) {
      const std::size_t begin = next.fetch_add(kBlock, std::memory_order_relaxed);
      if (begin >= count) return;
      try {
        for (std::size_t k = begin; k < std::min(count, begin + kBlock); ++k) body(k);
      } catch (...) {
        std::lock_guard lock(error_mutex);
        if (!error) error = std::current_exception();
        next.store(count, std::memory_order_relaxed);
        return;
      }
    }
  };
  std::vector<std::thread> pool;
  for (int t = 1; t < threads; ++t) pool.emplace_back(worker);
  worker();
  for (auto& thread : pool) thread.join();
  if (error) std::rethrow_exception(error);
}

struct DescribedSequence {
  std::vector<Descriptor> descriptors;
  std::vector<std::uint8_t> valid;
  std::vector<std::string> errors;  // per frame, empty when fine
  std::size_t described = 0;
};

DescribedSequence describe_sequence(int threads, const Dataset& dataset, std::size_t first, std::size_t last,
                                    const DirdExtractor& extractor) {
  DescribedSequence out;
  const std::size_t count = last - first;
  out.descriptors.resize(count);
  out.valid.assign(count, 0);
  out.errors.resize(count);
  parallel_indices(threads, count, [&](std::size_t k) {
    try {
      const cv::Mat image = dataset.load_image(first + k);
      extractor.extract(image, out.descriptors[k]);
      out.valid[k] = 1;
    } catch (const DataError& e) {
      std::fill(out.descriptors[k].begin(), out.descriptors[k].end(), std::uint8_t{0});
      out.errors[k] = std::string("image: ") + e.what();
    }
  });
  out.described = static_cast<std::size_t>(std::count(out.valid.begin(), out.valid.end(), std::uint8_t{1}));
  return out;
}

}  // namespace

TwoSequenceResult run_two_sequences(const PipelineConfig& config, const Dataset& reference,
                                    const Dataset& query, const std::filesystem::path& out_dir) {
  config.validate();
  for (const Dataset* dataset : {&reference, &query}) {
    if (dataset->frame_count() == 0) throw DataError(dataset->root(), "dataset has no frames");
    if (!dataset->has_images()) throw DataError(dataset->root(), "two-sequence mode needs images");
  }
  const auto [ref_first, ref_last] = config.run.frame_range(reference.frame_count());
  const auto [query_first, query_last] = config.run.frame_range(query.frame_count());
  const std::size_t ref_count = ref_last - ref_first;
  const std::size_t query_count = query_last - query_first;
  spdlog::info("two-sequence run: reference {} ({} frames) vs query {} ({} frames), {} threads",
               reference.root().string(), ref_count, query.root().string(), query_count, config.run.threads);

  const auto start = Clock::now();
  const DirdExtractor extractor(config.dird);
  const DirdSimilarity similarity(config.dird);

  auto t0 = Clock::now();
  const DescribedSequence ref =
      describe_sequence(config.run.threads, reference, ref_first, ref_last, extractor);
  const DescribedSequence qry =
      describe_sequence(config.run.threads, query, query_first, query_last, extractor);
  const double describe_s = seconds_since(t0);

  // Similarity rows of every query against the whole reference (no margin), in parallel; frames
  // without a descriptor take part in no pair.
  t0 = Clock::now();
  const bool any_ref_missing = ref.described != ref_count;
  std::vector<std::vector<SimilarityEntry>> rows(query_count);
  parallel_indices(config.run.threads, query_count, [&](std::size_t q) {
    if (!qry.valid[q]) return;
    similarity.sparse_row(qry.descriptors[q], ref.descriptors.data(), ref_count, 0, rows[q]);
    if (any_ref_missing) {
      std::erase_if(rows[q],
                    [&](const SimilarityEntry& e) { return !ref.valid[static_cast<std::size_t>(e.j)]; });
    }
  });
  const double similarity_s = seconds_since(t0);
  const std::size_t similarities = qry.described * ref.described;

  // The streaming matcher, query by query.
  t0 = Clock::now();
  SequenceMatcher matcher(config.match, SequenceMatcher::Mode::kTwoSequence, 0);
  MatchOutput output;
  for (std::size_t q = 0; q < query_count; ++q) {
    matcher.push(static_cast<std::int64_t>(q), rows[q], output);
    rows[q] = {};
  }
  matcher.flush(output);
  const double match_s = seconds_since(t0);

  std::filesystem::create_directories(out_dir);
  const int tolerance = config.eval.aligned_tolerance_frames;
  const auto aligned = [&](std::int64_t q, std::int64_t r) {
    return tolerance >= 0 && std::llabs(static_cast<long long>(query_first) + q -
                                        static_cast<long long>(ref_first) - r) <= tolerance;
  };
  CsvWriter loops_csv(out_dir / "loops.csv", {"i", "j", "t_i", "t_j", "score"});
  std::size_t loops_aligned = 0;
  for (const LoopClosure& loop : output.loops) {
    const std::size_t qi = query_first + static_cast<std::size_t>(loop.i);
    const std::size_t rj = ref_first + static_cast<std::size_t>(loop.j);
    loops_csv.write_row({std::to_string(qi), std::to_string(rj),
                         format_fixed(ns_to_s(query.frame_t_ns(qi)), 9),
                         format_fixed(ns_to_s(reference.frame_t_ns(rj)), 9), format_fixed(loop.score, 6)});
    if (aligned(loop.i, loop.j)) ++loops_aligned;
  }
  loops_csv.close();

  CsvWriter frames_csv(out_dir / "frames.csv",
                       {"frame", "t_ns", "t_s", "descriptor", "detection", "match_frame", "match_score",
                        "best_similarity", "candidates", "status", "reason"});
  std::array<std::size_t, 4> outcome_counts{};
  std::size_t best_aligned = 0, frame_errors = 0;
  const double threshold = config.match.dp_threshold();
  for (const FrameMatchStatus& status : output.frames) {
    const auto q = static_cast<std::size_t>(status.i);
    const std::size_t frame = query_first + q;
    ++outcome_counts[static_cast<std::size_t>(status.outcome)];
    std::string reason;
    switch (status.outcome) {
      case FrameOutcome::kNoCandidate:
        reason = qry.valid[q] ? fmt::format("no similarity above tau1 = {}", config.dird.tau1)
                              : "no descriptor (image not decoded)";
        break;
      case FrameOutcome::kBelowThreshold:
        reason = fmt::format("best DP {:.4f} <= {:.4f}", status.best_score, threshold);
        break;
      case FrameOutcome::kSuppressed:
        reason = fmt::format("{} DP values above {:.4f}, all suppressed by NMS", status.above_threshold,
                             threshold);
        break;
      case FrameOutcome::kLoop: reason = fmt::format("{} loop closure(s)", status.loops); break;
    }
    const bool has_best = status.best_j >= 0;
    if (has_best && aligned(status.i, status.best_j)) ++best_aligned;
    const bool error = !qry.errors[q].empty();
    frame_errors += error ? 1 : 0;
    frames_csv.write_row({std::to_string(frame), std::to_string(query.frame_t_ns(frame)),
                          format_fixed(ns_to_s(query.frame_t_ns(frame)), 9), qry.valid[q] ? "y" : "n",
                          to_string(status.outcome),
                          has_best ? std::to_string(ref_first + static_cast<std::size_t>(status.best_j)) : "",
                          has_best ? format_fixed(status.best_score, 6) : "",
                          format_fixed(status.best_similarity, 6), std::to_string(status.candidates),
                          error ? "error" : "ok", error ? qry.errors[q] + "; " + reason : reason});
  }
  frames_csv.close();

  TwoSequenceResult result;
  result.reference_frames = ref_count;
  result.query_frames = query_count;
  result.loops = output.loops.size();
  result.wall_s = seconds_since(start);
  PipelineConfig echo = config;
  nlohmann::json reference_errors = nlohmann::json::array();
  for (std::size_t k = 0; k < ref_count; ++k)
    if (!ref.errors[k].empty() && reference_errors.size() < 200) reference_errors.push_back(ref.errors[k]);
  result.summary = {
      {"mode", "two-sequence"},
      {"config", config_to_json(echo)},
      {"reference",
       {{"root", reference.root().string()}, {"first_frame", ref_first}, {"last_frame", ref_last}}},
      {"query", {{"root", query.root().string()}, {"first_frame", query_first}, {"last_frame", query_last}}},
      {"images_decoded", ref.described + qry.described},
      {"descriptors_computed", ref.described + qry.described},
      {"similarities_computed", similarities},
      {"loops", output.loops.size()},
      {"query_frames", query_count},
      {"query_frames_with_error", frame_errors},
      {"reference_errors", reference_errors},
      {"detection",
       {{"no_candidate", outcome_counts[static_cast<std::size_t>(FrameOutcome::kNoCandidate)]},
        {"below_threshold", outcome_counts[static_cast<std::size_t>(FrameOutcome::kBelowThreshold)]},
        {"suppressed", outcome_counts[static_cast<std::size_t>(FrameOutcome::kSuppressed)]},
        {"loop", outcome_counts[static_cast<std::size_t>(FrameOutcome::kLoop)]},
        {"nms_delay_frames", matcher.emission_delay()}}},
      {"stages_s", {{"describe", describe_s}, {"similarity", similarity_s}, {"match", match_s}}},
      {"wall_s", result.wall_s},
      {"peak_rss_mb", peak_rss_mb()},
  };
  if (tolerance >= 0) {
    result.summary["aligned"] = {{"tolerance_frames", tolerance},
                                 {"loops_within_tolerance", loops_aligned},
                                 {"loops_beyond_tolerance", output.loops.size() - loops_aligned},
                                 {"best_match_within_tolerance", best_aligned}};
  }
  write_json_file(out_dir / "summary.json", result.summary);
  return result;
}

}  // namespace loopgate
