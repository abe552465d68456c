#include "pipeline/two_sequence.hpp"

#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>
#include <sys/resource.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <exception>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "core/error.hpp"
#include "eval/ground_truth.hpp"
#include "eval/precision_recall.hpp"
#include "io/config.hpp"
#include "io/dataset.hpp"
#include "io/writers.hpp"
#include "pipeline/run_metrics.hpp"
#include "pipeline/seqslam_batch.hpp"
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

// Frames [first, first + count) of a dataset through SeqSLAM step 1 into `batch` at seq offset + k;
// a frame that does not decode or preprocess takes part as an all-zero image (SeqSlamBatch::add_missing).
DescribedSequence preprocess_sequence(int threads, const Dataset& dataset, std::size_t first,
                                      std::size_t count, std::size_t offset, SeqSlamBatch& batch) {
  DescribedSequence out;
  out.valid.assign(count, 0);
  out.errors.resize(count);
  parallel_indices(threads, count, [&](std::size_t k) {
    try {
      batch.add(offset + k, dataset.load_image(first + k));
      out.valid[k] = 1;
    } catch (const DataError& e) {
      out.errors[k] = std::string("image: ") + e.what();
    } catch (const std::invalid_argument& e) {
      out.errors[k] =
          fmt::format("seqslam preprocessing of {}: {}", dataset.image_path(first + k).string(), e.what());
    }
    if (!out.valid[k]) batch.add_missing(offset + k);
  });
  out.described = static_cast<std::size_t>(std::count(out.valid.begin(), out.valid.end(), std::uint8_t{1}));
  return out;
}

// What both methods share: the two frame ranges and the aligned ground truth.
struct TwoSequenceSetup {
  const PipelineConfig& config;
  const Dataset& reference;
  const Dataset& query;
  AlignedSequences ranges;

  int tolerance() const { return config.eval.aligned_tolerance_frames; }
  bool aligned(std::size_t q, std::size_t r) const { return tolerance() >= 0 && ranges.aligned(q, r); }
};

nlohmann::json reference_errors_json(const DescribedSequence& ref) {
  constexpr std::size_t kMaxListed = 200;
  nlohmann::json errors = nlohmann::json::array();
  for (const std::string& e : ref.errors)
    if (!e.empty() && errors.size() < kMaxListed) errors.push_back(e);
  return errors;
}

// The evaluation block, and with a tolerance truth_loops.csv (dataset frame indices: i query, j reference).
nlohmann::json run_evaluation(const TwoSequenceSetup& setup, const std::vector<Detection>& loops,
                              const std::vector<Detection>& ranked, const std::string& score_order,
                              const std::filesystem::path& out_dir) {
  if (setup.tolerance() < 0) {
    return {{"available", false},
            {"why", "eval.aligned_tolerance_frames < 0: the sequences are not declared aligned"}};
  }
  CsvWriter truth_loops(out_dir / "truth_loops.csv", {"i", "j"});
  for (const auto& [q, r] : setup.ranges.pairs()) {
    truth_loops.write_row(
        {std::to_string(setup.ranges.query_first + q), std::to_string(setup.ranges.reference_first + r)});
  }
  truth_loops.close();
  return evaluate_aligned(setup.ranges, loops, ranked, score_order);
}

nlohmann::json sequences_json(const TwoSequenceSetup& setup) {
  return {{"reference",
           {{"root", setup.reference.root().string()},
            {"first_frame", setup.ranges.reference_first},
            {"last_frame", setup.ranges.reference_first + setup.ranges.reference_count}}},
          {"query",
           {{"root", setup.query.root().string()},
            {"first_frame", setup.ranges.query_first},
            {"last_frame", setup.ranges.query_first + setup.ranges.query_count}}}};
}

// DIRD (dird.md §5): describe both, S for every (reference, query) pair, the streaming matcher.
TwoSequenceResult run_dird(const TwoSequenceSetup& setup, const std::filesystem::path& out_dir,
                           Clock::time_point start) {
  const PipelineConfig& config = setup.config;
  const Dataset& reference = setup.reference;
  const Dataset& query = setup.query;
  const std::size_t ref_first = setup.ranges.reference_first, ref_count = setup.ranges.reference_count;
  const std::size_t query_first = setup.ranges.query_first, query_count = setup.ranges.query_count;
  const DirdExtractor extractor(config.dird);
  const DirdSimilarity similarity(config.dird);

  auto t0 = Clock::now();
  const DescribedSequence ref =
      describe_sequence(config.run.threads, reference, ref_first, ref_first + ref_count, extractor);
  const DescribedSequence qry =
      describe_sequence(config.run.threads, query, query_first, query_first + query_count, extractor);
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

  CsvWriter loops_csv(out_dir / "loops.csv", {"i", "j", "t_i", "t_j", "score"});
  std::size_t loops_aligned = 0;
  std::vector<Detection> detections;  // indices within the ranges, score = DP
  for (const LoopClosure& loop : output.loops) {
    const auto q = static_cast<std::size_t>(loop.i);
    const auto r = static_cast<std::size_t>(loop.j);
    const std::size_t qi = query_first + q;
    const std::size_t rj = ref_first + r;
    loops_csv.write_row({std::to_string(qi), std::to_string(rj),
                         format_fixed(ns_to_s(query.frame_t_ns(qi)), 9),
                         format_fixed(ns_to_s(reference.frame_t_ns(rj)), 9), format_fixed(loop.score, 6)});
    if (setup.aligned(q, r)) ++loops_aligned;
    detections.push_back(Detection{q, r, loop.score});
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
    if (has_best && setup.aligned(q, static_cast<std::size_t>(status.best_j))) ++best_aligned;
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
  const std::string score_order = "higher_is_better";
  nlohmann::json evaluation = run_evaluation(setup, detections, detections, score_order, out_dir);
  result.wall_s = seconds_since(start);
  result.summary = {
      {"mode", "two-sequence"},
      {"method", "dird"},
      {"score_order", score_order},
      {"config", config_to_json(config)},
      {"images_decoded", ref.described + qry.described},
      {"descriptors_computed", ref.described + qry.described},
      {"similarities_computed", similarities},
      {"loops", output.loops.size()},
      {"query_frames", query_count},
      {"query_frames_with_error", frame_errors},
      {"reference_errors", reference_errors_json(ref)},
      {"detection",
       {{"no_candidate", outcome_counts[static_cast<std::size_t>(FrameOutcome::kNoCandidate)]},
        {"below_threshold", outcome_counts[static_cast<std::size_t>(FrameOutcome::kBelowThreshold)]},
        {"suppressed", outcome_counts[static_cast<std::size_t>(FrameOutcome::kSuppressed)]},
        {"loop", outcome_counts[static_cast<std::size_t>(FrameOutcome::kLoop)]},
        {"nms_delay_frames", matcher.emission_delay()}}},
      {"evaluation", std::move(evaluation)},
      {"stages_s", {{"describe", describe_s}, {"similarity", similarity_s}, {"match", match_s}}},
      {"wall_s", result.wall_s},
      {"peak_rss_mb", peak_rss_mb()},
  };
  result.summary.update(sequences_json(setup));
  if (setup.tolerance() >= 0) {
    result.summary["aligned"] = {{"tolerance_frames", setup.tolerance()},
                                 {"loops_within_tolerance", loops_aligned},
                                 {"loops_beyond_tolerance", output.loops.size() - loops_aligned},
                                 {"best_match_within_tolerance", best_aligned}};
  }
  return result;
}

// SeqSLAM (seqslam.md) between two runs: step 1 on both sequences in parallel, then the difference matrix
// (reference rows x query columns), contrast enhancement and sequence search with exclusion "none".
TwoSequenceResult run_seqslam(const TwoSequenceSetup& setup, const std::filesystem::path& out_dir,
                              Clock::time_point start) {
  const PipelineConfig& config = setup.config;
  const Dataset& reference = setup.reference;
  const Dataset& query = setup.query;
  const std::size_t ref_first = setup.ranges.reference_first, ref_count = setup.ranges.reference_count;
  const std::size_t query_first = setup.ranges.query_first, query_count = setup.ranges.query_count;
  PipelineConfig effective = config;
  if (effective.seqslam.exclusion != "none") {
    spdlog::warn(
        "two-sequence mode: seqslam.exclusion '{}' ignored, using 'none' (reference and query are "
        "different runs, every pair may match)",
        effective.seqslam.exclusion);
    effective.seqslam.exclusion = "none";
  }
  const SeqSlamConfig& seqslam = effective.seqslam;
  SeqSlamBatch batch(seqslam, ref_count + query_count);

  auto t0 = Clock::now();
  const DescribedSequence ref =
      preprocess_sequence(config.run.threads, reference, ref_first, ref_count, 0, batch);
  const DescribedSequence qry =
      preprocess_sequence(config.run.threads, query, query_first, query_count, ref_count, batch);
  const double preprocess_s = seconds_since(t0);
  for (const auto& [dataset, described] : {std::pair{&reference, &ref}, std::pair{&query, &qry}}) {
    if (described->described == 0) {
      const auto first_error = std::find_if(described->errors.begin(), described->errors.end(),
                                            [](const std::string& e) { return !e.empty(); });
      throw DataError(dataset->root(), "SeqSLAM: no image of the sequence could be preprocessed (" +
                                           (first_error != described->errors.end() ? *first_error : "") +
                                           ")");
    }
  }

  t0 = Clock::now();
  std::vector<SeqSlamMatch> matches;
  tbb::task_arena arena(config.run.threads);
  arena.execute([&] { matches = batch.run_two_sequence(ref_count, query_count); });
  const double search_s = seconds_since(t0);

  const std::size_t half = static_cast<std::size_t>(seqslam.sequence_length_frames / 2);
  const double threshold = seqslam.ratio_threshold;
  CsvWriter loops_csv(out_dir / "loops.csv", {"i", "j", "t_i", "t_j", "score"});
  CsvWriter frames_csv(out_dir / "frames.csv",
                       {"frame", "t_ns", "t_s", "descriptor", "detection", "match_frame", "match_score",
                        "best_score", "second_score", "status", "reason"});
  std::vector<Detection> loops, ranked;  // indices within the ranges, score = ratio
  std::array<std::size_t, 4> outcome_counts{};
  std::size_t loops_aligned = 0, best_aligned = 0, frame_errors = 0;
  for (std::size_t q = 0; q < query_count; ++q) {
    const SeqSlamMatch& m = matches.at(q);
    const std::size_t frame = query_first + q;
    const bool has_match = m.has_match && m.reference < ref_count;
    FrameOutcome outcome = FrameOutcome::kNoCandidate;
    std::string detection, reason;
    if (!has_match) {
      detection = "no match";
      if (q < half || q + half >= query_count) {
        reason = fmt::format("within ds/2 = {} frames of an end of the query sequence", half);
      } else if (m.has_match) {
        reason = fmt::format("best sequence centred on reference {} beyond the last reference frame",
                             ref_first + m.reference);
      } else {
        reason = "no sequence with a finite score";
      }
    } else {
      const std::size_t rj = ref_first + m.reference;
      if (std::isfinite(m.ratio)) ranked.push_back(Detection{q, m.reference, m.ratio});
      if (setup.aligned(q, m.reference)) ++best_aligned;
      if (m.accepted) {
        detection = "loop";
        outcome = FrameOutcome::kLoop;
        reason = fmt::format("ratio {:.4f} <= {:.4f}", m.ratio, threshold);
        loops_csv.write_row({std::to_string(frame), std::to_string(rj),
                             format_fixed(ns_to_s(query.frame_t_ns(frame)), 9),
                             format_fixed(ns_to_s(reference.frame_t_ns(rj)), 9), format_fixed(m.ratio, 6)});
        loops.push_back(Detection{q, m.reference, m.ratio});
        if (setup.aligned(q, m.reference)) ++loops_aligned;
      } else {
        detection = "rejected";
        outcome = FrameOutcome::kBelowThreshold;
        reason = std::isfinite(m.ratio)
                     ? fmt::format("ratio {:.4f} > {:.4f}", m.ratio, threshold)
                     : fmt::format("no sequence outside best +- {} rows: no second best, no support",
                                   seqslam.second_best_window_rows / 2);
      }
    }
    ++outcome_counts[static_cast<std::size_t>(outcome)];
    const bool error = !qry.errors[q].empty();
    frame_errors += error ? 1 : 0;
    if (error) reason = qry.errors[q] + " (took part as an all-zero image); " + reason;
    frames_csv.write_row({std::to_string(frame), std::to_string(query.frame_t_ns(frame)),
                          format_fixed(ns_to_s(query.frame_t_ns(frame)), 9), qry.valid[q] ? "y" : "n",
                          detection, has_match ? std::to_string(ref_first + m.reference) : "",
                          has_match ? format_fixed(m.ratio, 6) : "",
                          has_match ? format_fixed(m.best_score, 6) : "",
                          has_match ? format_fixed(m.second_score, 6) : "", error ? "error" : "ok", reason});
  }
  loops_csv.close();
  frames_csv.close();

  TwoSequenceResult result;
  result.reference_frames = ref_count;
  result.query_frames = query_count;
  result.loops = loops.size();
  const std::string score_order = "lower_is_better";
  nlohmann::json evaluation = run_evaluation(setup, loops, ranked, score_order, out_dir);
  result.wall_s = seconds_since(start);
  result.summary = {
      {"mode", "two-sequence"},
      {"method", "seqslam"},
      {"score_order", score_order},
      {"config", config_to_json(effective)},
      {"images_decoded", ref.described + qry.described},
      {"descriptors_computed", ref.described + qry.described},  // preprocessed images
      {"similarities_computed", ref_count * query_count},       // difference matrix entries
      {"loops", loops.size()},
      {"query_frames", query_count},
      {"query_frames_with_error", frame_errors},
      {"reference_errors", reference_errors_json(ref)},
      {"detection",
       {{"no_candidate", outcome_counts[static_cast<std::size_t>(FrameOutcome::kNoCandidate)]},
        {"below_threshold", outcome_counts[static_cast<std::size_t>(FrameOutcome::kBelowThreshold)]},
        {"suppressed", 0},
        {"loop", outcome_counts[static_cast<std::size_t>(FrameOutcome::kLoop)]}}},
      {"evaluation", std::move(evaluation)},
      {"stages_s", {{"preprocess", preprocess_s}, {"search", search_s}}},
      {"wall_s", result.wall_s},
      {"peak_rss_mb", peak_rss_mb()},
  };
  result.summary.update(sequences_json(setup));
  if (setup.tolerance() >= 0) {
    result.summary["aligned"] = {{"tolerance_frames", setup.tolerance()},
                                 {"loops_within_tolerance", loops_aligned},
                                 {"loops_beyond_tolerance", loops.size() - loops_aligned},
                                 {"best_match_within_tolerance", best_aligned}};
  }
  return result;
}

}  // namespace

bool AlignedSequences::aligned(std::size_t q, std::size_t r) const {
  return tolerance_frames >= 0 && std::llabs(static_cast<long long>(query_first + q) -
                                             static_cast<long long>(reference_first + r)) <= tolerance_frames;
}

std::vector<std::pair<std::size_t, std::size_t>> AlignedSequences::pairs() const {
  std::vector<std::pair<std::size_t, std::size_t>> out;
  if (tolerance_frames < 0) return out;
  const auto tolerance = static_cast<std::size_t>(tolerance_frames);
  for (std::size_t q = 0; q < query_count; ++q) {
    const std::size_t frame = query_first + q;
    const std::size_t lo = std::max(reference_first, frame >= tolerance ? frame - tolerance : 0);
    const std::size_t hi = std::min(reference_first + reference_count, frame + tolerance + 1);
    for (std::size_t rj = lo; rj < hi; ++rj) out.emplace_back(q, rj - reference_first);
  }
  return out;
}

nlohmann::json evaluate_aligned(const AlignedSequences& sequences, const std::vector<Detection>& loops,
                                const std::vector<Detection>& ranked, const std::string& score_order) {
  const LoopGroundTruth truth = LoopGroundTruth::from_pairs(
      std::max(sequences.query_count, sequences.reference_count), sequences.pairs());
  nlohmann::json out = {
      {"available", true},
      {"truth",
       {{"aligned_tolerance_frames", sequences.tolerance_frames}, {"positives", truth.positive_count()}}}};
  out.update(loop_evaluation_json(loops, ranked, truth, score_order));
  return out;
}

TwoSequenceResult run_two_sequences(const PipelineConfig& config, const Dataset& reference,
                                    const Dataset& query, const std::filesystem::path& out_dir) {
  config.validate();
  for (const Dataset* dataset : {&reference, &query}) {
    if (dataset->frame_count() == 0) throw DataError(dataset->root(), "dataset has no frames");
    if (!dataset->has_images()) throw DataError(dataset->root(), "two-sequence mode needs images");
  }
  const auto [ref_first, ref_last] = config.run.frame_range(reference.frame_count());
  const auto [query_first, query_last] = config.run.frame_range(query.frame_count());
  const AlignedSequences ranges{ref_first, ref_last - ref_first, query_first, query_last - query_first,
                                config.eval.aligned_tolerance_frames};
  const TwoSequenceSetup setup{config, reference, query, ranges};
  spdlog::info("two-sequence run ({}): reference {} ({} frames) vs query {} ({} frames), {} threads",
               config.run.method, reference.root().string(), setup.ranges.reference_count,
               query.root().string(), setup.ranges.query_count, config.run.threads);
  const auto start = Clock::now();
  std::filesystem::create_directories(out_dir);
  TwoSequenceResult result =
      config.run.seqslam() ? run_seqslam(setup, out_dir, start) : run_dird(setup, out_dir, start);
  write_json_file(out_dir / "summary.json", result.summary);
  return result;
}

}  // namespace loopgate
