#include "pipeline/two_sequence.hpp"

#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <exception>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "core/error.hpp"
#include "core/stop_request.hpp"
#include "eval/run_evaluation.hpp"
#include "io/config.hpp"
#include "io/dataset.hpp"
#include "io/provenance.hpp"
#include "io/writers.hpp"
#include "pipeline/graph/run_resources.hpp"
#include "pipeline/loops/loops_writer.hpp"
#include "pipeline/methods/seqslam_batch.hpp"
#include "stages/dird/dird_codes.hpp"
#include "stages/dird/dird_extractor.hpp"
#include "stages/dird/dird_online_scale.hpp"
#include "stages/dird/dird_similarity.hpp"
#include "stages/dird/dird_standardize.hpp"
#include "stages/match/contrast_search.hpp"
#include "stages/match/match_outcome.hpp"
#include "stages/match/sequence_matcher.hpp"
#include "stages/seqslam/seqslam_outcome.hpp"

namespace loopgate {

namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// trace.json of a two-sequence run (output.trace): spans on the calling thread's track (0) and the workers'
// (1..threads-1), in microseconds since the run's start.
struct RunTrace {
  TraceWriter* writer = nullptr;  // null: no trace
  Clock::time_point origin;

  void span(std::string name, const char* category, Clock::time_point from, int track,
            std::string detail = {}) const {
    if (!writer) return;
    const auto us = [&](Clock::time_point t) {
      return std::chrono::duration<double, std::micro>(t - origin).count();
    };
    writer->add(TraceEvent{std::move(name), category, us(from), us(Clock::now()) - us(from), track, -1, -1,
                           'X', std::move(detail)});
  }
};

// The blocks of parallel_indices on trace.json: each one a span named `what` with its index range.
struct BlockTrace {
  const RunTrace* trace = nullptr;
  const char* what = "";
};

// Runs body(k) for k in [0, count) on `threads` threads (plain std::threads: thread start and join
// order everything the caller prepared and the bodies wrote, visibly for ThreadSanitizer too). Indices are
// handed out in small blocks; each body writes only its own outputs, so the result does not depend on
// the thread count. The first exception of a body is rethrown after the join.
// Stop requests: once `stop` is set no block is handed out; the blocks handed out are finished, so
// the indices done are a prefix [0, returned). A second stop signal aborts (stop_request::check_abort).
// With a BlockTrace, each block is a span on its thread's track.
template <class Body>
std::size_t parallel_indices(int threads, std::size_t count, const std::atomic<bool>* stop, Body body,
                             BlockTrace block_trace = {}) {
  constexpr std::size_t kBlock = 16;
  std::atomic<std::size_t> next{0};
  std::mutex handout_mutex;  // a block is handed out only while no stop is requested
  std::exception_ptr error;
  std::mutex error_mutex;
  const auto worker = [&](int track) {
    for (;;) {
      std::size_t begin = 0;
      {
        std::lock_guard lock(handout_mutex);
        if (stop && stop->load()) return;
        begin = next.fetch_add(kBlock, std::memory_order_relaxed);
      }
      if (begin >= count) return;
      try {
        // Inside the try: an abort thrown on a pool thread reaches the caller after the join; outside it,
        // the thread would end with an exception and the process with std::terminate.
        stop_request::check_abort("two-sequence run");
        const auto block_start = Clock::now();
        const std::size_t end = std::min(count, begin + kBlock);
        for (std::size_t k = begin; k < end; ++k) body(k);
        if (block_trace.trace)
          block_trace.trace->span(block_trace.what, "block", block_start, track,
                                  fmt::format("[{}, {})", begin, end));
      } catch (...) {
        std::lock_guard lock(error_mutex);
        if (!error) error = std::current_exception();
        next.store(count, std::memory_order_relaxed);
        return;
      }
    }
  };
  std::vector<std::thread> pool;
  for (int t = 1; t < threads; ++t) pool.emplace_back(worker, t);
  worker(0);
  for (auto& thread : pool) thread.join();
  if (error) std::rethrow_exception(error);
  return std::min(count, next.load());
}

struct DescribedSequence {
  std::vector<Descriptor> descriptors;
  std::vector<std::uint8_t> valid;
  std::vector<std::string> errors;  // per frame, empty when fine
  std::size_t described = 0;
  std::size_t taken = 0;  // frames [0, taken) were read: all of them unless a stop request came
};

DescribedSequence describe_sequence(int threads, const Dataset& dataset, std::size_t first, std::size_t last,
                                    const DirdExtractor& extractor, const std::atomic<bool>* stop,
                                    BlockTrace block_trace) {
  DescribedSequence out;
  const std::size_t count = last - first;
  out.descriptors.resize(count);
  out.valid.assign(count, 0);
  out.errors.resize(count);
  out.taken = parallel_indices(
      threads, count, stop,
      [&](std::size_t k) {
        try {
          const cv::Mat image = dataset.load_image(first + k);
          extractor.extract(image, out.descriptors[k]);
          out.valid[k] = 1;
        } catch (const DataError& e) {
          std::fill(out.descriptors[k].begin(), out.descriptors[k].end(), std::uint8_t{0});
          out.errors[k] = std::string("image: ") + e.what();
        }
      },
      block_trace);
  out.described = static_cast<std::size_t>(std::count(out.valid.begin(), out.valid.end(), std::uint8_t{1}));
  return out;
}

// The codes the distances are computed on (docs/standardize.md), each sequence with statistics of its own:
// standardize.mode off: the raw descriptors; batch: the statistics of the whole sequence; causal: the
// causal rule over the sequence's frames in order (every observe_every-th frame observed; frames before the
// warm-up take the first snapshot). A sequence too short for the causal warm-up takes its batch statistics
// (said in `note`). Frames without a descriptor stay uncoded.
struct CodedSequence {
  std::vector<Descriptor> codes;
  std::vector<double> norms;  // standard_norm of the codes (cosine)
  std::string statistics;     // "raw", "batch", "causal"
  std::string note;
};

CodedSequence code_sequence(const DescribedSequence& sequence, const StandardizeConfig& config) {
  CodedSequence out;
  const std::size_t n = sequence.descriptors.size();
  if (!config.enabled()) {
    out.codes = sequence.descriptors;
    out.statistics = "raw";
    return out;
  }
  std::vector<Descriptor> valid;
  for (std::size_t k = 0; k < n; ++k)
    if (sequence.valid[k]) valid.push_back(sequence.descriptors[k]);
  out.codes.resize(n);
  out.norms.assign(n, 0.0);
  if (valid.empty()) return out;
  std::optional<CausalStandardizer> causal;
  if (config.mode == "causal") {
    causal.emplace(observations_config(config));
    const auto every = static_cast<std::size_t>(config.observe_every);
    for (std::size_t k = 0; k < n; k += every) {
      if (sequence.valid[k]) causal->observe(static_cast<std::int64_t>(k), sequence.descriptors[k]);
    }
    if (!causal->ready()) {
      out.note = fmt::format(
          "{} observations are fewer than the causal warm-up of {}: the sequence's batch statistics are used",
          causal->observations(), observations_config(config).warm_up);
      causal.reset();
    }
  }
  const Standardization batch = causal ? Standardization{} : standardization_of(valid, config);
  out.statistics = causal ? "causal" : "batch";
  for (std::size_t k = 0; k < n; ++k) {
    if (!sequence.valid[k]) continue;
    const Standardization& statistics = causal ? causal->statistics_for(static_cast<std::int64_t>(k)) : batch;
    statistics.apply(sequence.descriptors[k], out.codes[k]);
    out.norms[k] = standard_norm(out.codes[k]);
  }
  return out;
}

// Distance of query frame q to reference frame r on their codes: raw L1 (or L2 with dird.metric l2),
// standardised cosine or L1 (standardize.distance).
double coded_distance(const DirdConfig& dird, const StandardizeConfig& standardize,
                      const CodedSequence& query, std::size_t q, const CodedSequence& reference,
                      std::size_t r) {
  if (!standardize.enabled()) {
    return dird.l2_metric() ? l2_distance(query.codes[q], reference.codes[r])
                            : static_cast<double>(l1_distance(query.codes[q], reference.codes[r]));
  }
  if (standardize.cosine()) {
    return standard_cosine_distance(query.codes[q], query.norms[q], reference.codes[r], reference.norms[r]);
  }
  return static_cast<double>(l1_distance(query.codes[q], reference.codes[r]));
}

nlohmann::json standardize_json(const StandardizeConfig& standardize, const CodedSequence& reference,
                                const CodedSequence& query) {
  nlohmann::json out = {{"mode", standardize.mode},
                        {"distance", standardize.distance},
                        {"reference_statistics", reference.statistics},
                        {"query_statistics", query.statistics}};
  nlohmann::json notes = nlohmann::json::array();
  if (!reference.note.empty()) notes.push_back("reference: " + reference.note);
  if (!query.note.empty()) notes.push_back("query: " + query.note);
  if (!notes.empty()) out["notes"] = notes;
  return out;
}

// Frames [first, first + count) of a dataset through SeqSLAM step 1 into `batch` at seq offset + k;
// a frame that does not decode or preprocess takes part as an all-zero image (SeqSlamBatch::add_missing).
DescribedSequence preprocess_sequence(int threads, const Dataset& dataset, std::size_t first,
                                      std::size_t count, std::size_t offset, SeqSlamBatch& batch,
                                      const std::atomic<bool>* stop, BlockTrace block_trace) {
  DescribedSequence out;
  out.valid.assign(count, 0);
  out.errors.resize(count);
  out.taken = parallel_indices(
      threads, count, stop,
      [&](std::size_t k) {
        try {
          batch.add(offset + k, dataset.load_image(first + k));
          out.valid[k] = 1;
        } catch (const DataError& e) {
          out.errors[k] = std::string("image: ") + e.what();
        } catch (const std::invalid_argument& e) {
          out.errors[k] = fmt::format("seqslam preprocessing of {}: {}",
                                      dataset.image_path(first + k).string(), e.what());
        }
        if (!out.valid[k]) batch.add_missing(offset + k);
      },
      block_trace);
  out.described = static_cast<std::size_t>(std::count(out.valid.begin(), out.valid.end(), std::uint8_t{1}));
  return out;
}

// What both methods share: the two frame ranges and the aligned ground truth.
struct TwoSequenceSetup {
  const PipelineConfig& config;
  const Dataset& reference;
  const Dataset& query;
  AlignedSequences ranges;
  const std::atomic<bool>* stop = nullptr;
  RunTrace trace;

  // A phase of the run, from `from` to now, on the calling thread's track of trace.json.
  void phase(const char* name, Clock::time_point from) const { trace.span(name, "phase", from, 0); }
  BlockTrace blocks(const char* what) const { return {trace.writer ? &trace : nullptr, what}; }

  // Frames in loops.csv by their numbers (Dataset::source_index): i query, j reference.
  LoopsWriter::Label query_label() const {
    return [&q = query](std::size_t frame) { return q.source_index(frame); };
  }
  LoopsWriter::Label reference_label() const {
    return [&r = reference](std::size_t frame) { return r.source_index(frame); };
  }
  // A stop request: the query range ends after the frames taken (none when the reference was incomplete).
  std::size_t query_taken(const DescribedSequence& ref, const DescribedSequence& qry) const {
    return ref.taken < ranges.reference_count ? 0 : qry.taken;
  }

  int tolerance() const { return config.eval.aligned_tolerance_frames; }
  bool aligned(std::size_t q, std::size_t r) const { return tolerance() >= 0 && ranges.aligned(q, r); }
};

// DIRD descriptors of the reference range, then of the query range (each in parallel, traced by blocks).
std::pair<DescribedSequence, DescribedSequence> describe_both(const TwoSequenceSetup& setup,
                                                              const DirdExtractor& extractor) {
  const AlignedSequences& r = setup.ranges;
  const int threads = setup.config.run.threads;
  DescribedSequence ref =
      describe_sequence(threads, setup.reference, r.reference_first, r.reference_first + r.reference_count,
                        extractor, setup.stop, setup.blocks("describe reference"));
  DescribedSequence qry =
      describe_sequence(threads, setup.query, r.query_first, r.query_first + r.query_count, extractor,
                        setup.stop, setup.blocks("describe query"));
  return {std::move(ref), std::move(qry)};
}

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
    truth_loops.write_row({std::to_string(setup.query.source_index(setup.ranges.query_first + q)),
                           std::to_string(setup.reference.source_index(setup.ranges.reference_first + r))});
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

// summary.json "aligned" (with a tolerance only): the loops within the tolerance of the aligned frame and the
// queries whose best match is.
void add_aligned_json(const TwoSequenceSetup& setup, std::size_t loops, std::size_t loops_aligned,
                      std::size_t best_aligned, nlohmann::json& summary) {
  if (setup.tolerance() < 0) return;
  summary["aligned"] = {{"tolerance_frames", setup.tolerance()},
                        {"loops_within_tolerance", loops_aligned},
                        {"loops_beyond_tolerance", loops - loops_aligned},
                        {"best_match_within_tolerance", best_aligned}};
}

// loops.csv of the accepted loops (indices within the ranges; the file gives dataset frame numbers: i query,
// j reference). Returns how many lie within the tolerance of the aligned frame.
std::size_t write_loops(const TwoSequenceSetup& setup, const std::vector<Detection>& loops,
                        const std::filesystem::path& out_dir) {
  LoopsWriter loops_csv;
  loops_csv.open(out_dir / "loops.csv", setup.query_label(), setup.reference_label());
  std::size_t aligned = 0;
  for (const Detection& loop : loops) {
    const std::size_t i = setup.ranges.query_first + loop.query;
    const std::size_t j = setup.ranges.reference_first + loop.reference;
    loops_csv.write(i, j, setup.query.frame_t_ns(i), setup.reference.frame_t_ns(j), loop.score);
    if (setup.aligned(loop.query, loop.reference)) ++aligned;
  }
  loops_csv.close();
  return aligned;
}

std::vector<Detection> as_detections(const std::vector<LoopClosure>& loops) {
  std::vector<Detection> out;
  out.reserve(loops.size());
  for (const LoopClosure& loop : loops)
    out.push_back(Detection{static_cast<std::size_t>(loop.i), static_cast<std::size_t>(loop.j), loop.score});
  return out;
}

// frames.csv of a two-sequence run, a row per query frame: the columns of every method (frame, t_ns, t_s,
// descriptor, detection, match_frame), the method's own (`method_columns`), then status and reason; and the
// counts summary.json gives of them.
class QueryFramesCsv {
 public:
  QueryFramesCsv(const TwoSequenceSetup& setup, const DescribedSequence& query_frames,
                 const std::filesystem::path& out_dir, const std::vector<std::string>& method_columns,
                 std::string error_note = {})
      : setup_(setup), qry_(query_frames), error_note_(std::move(error_note)) {
    std::vector<std::string> columns = {"frame", "t_ns", "t_s", "descriptor", "detection", "match_frame"};
    columns.insert(columns.end(), method_columns.begin(), method_columns.end());
    columns.insert(columns.end(), {"status", "reason"});
    csv_.open(out_dir / "frames.csv", columns);
  }

  // Query q (within the range): its detection, whose match is the best reference (within the range; -1:
  // none), and the method's cells. A frame whose image failed gives the error before the reason (with
  // error_note after it).
  void write(std::size_t q, const FrameDetection& detection, const std::vector<std::string>& method_cells) {
    const std::size_t frame = setup_.ranges.query_first + q;
    ++outcome_counts_[static_cast<std::size_t>(detection.outcome)];
    const bool has_best = detection.match >= 0;
    if (has_best && setup_.aligned(q, static_cast<std::size_t>(detection.match))) ++best_aligned_;
    const bool error = !qry_.errors[q].empty();
    frame_errors_ += error ? 1 : 0;
    const Dataset& query = setup_.query;
    std::vector<std::string> row = {
        std::to_string(query.source_index(frame)),
        std::to_string(query.frame_t_ns(frame)),
        format_fixed(ns_to_s(query.frame_t_ns(frame)), 9),
        qry_.valid[q] ? "y" : "n",
        detection.label,
        has_best ? std::to_string(setup_.reference.source_index(setup_.ranges.reference_first +
                                                                static_cast<std::size_t>(detection.match)))
                 : ""};
    row.insert(row.end(), method_cells.begin(), method_cells.end());
    row.push_back(error ? "error" : "ok");
    row.push_back(error ? qry_.errors[q] + error_note_ + "; " + detection.reason : detection.reason);
    csv_.write_row(row);
  }
  void close() { csv_.close(); }

  std::size_t best_aligned() const { return best_aligned_; }
  std::size_t frame_errors() const { return frame_errors_; }
  // summary.json "detection": the queries by outcome.
  nlohmann::json detection_json() const {
    const auto count = [this](FrameOutcome o) { return outcome_counts_[static_cast<std::size_t>(o)]; };
    return {{"no_candidate", count(FrameOutcome::kNoCandidate)},
            {"below_threshold", count(FrameOutcome::kBelowThreshold)},
            {"suppressed", count(FrameOutcome::kSuppressed)},
            {"loop", count(FrameOutcome::kLoop)}};
  }

 private:
  const TwoSequenceSetup& setup_;
  const DescribedSequence& qry_;
  std::string error_note_;
  CsvWriter csv_;
  std::array<std::size_t, 4> outcome_counts_{};
  std::size_t best_aligned_ = 0, frame_errors_ = 0;
};

// What every method's run gives: the evaluation (and truth_loops.csv) and summary.json's common fields;
// `summary` holds the method's own (stages_s, and more in "detection").
struct MethodRun {
  MethodRun(const char* method_name, std::string order, nlohmann::json effective_config,
            const DescribedSequence& reference, const DescribedSequence& query)
      : method(method_name),
        score_order(std::move(order)),
        config(std::move(effective_config)),
        ref(&reference),
        qry(&query) {}

  const char* method;
  std::string score_order;
  nlohmann::json config;  // the effective configuration
  const DescribedSequence* ref;
  const DescribedSequence* qry;
  std::size_t similarities = 0;
  const std::vector<Detection>* loops = nullptr;
  const std::vector<Detection>* ranked = nullptr;
  std::size_t loops_aligned = 0;
  nlohmann::json summary = nlohmann::json::object();
};

TwoSequenceResult finish_run(const TwoSequenceSetup& setup, MethodRun run, const QueryFramesCsv& frames,
                             const std::filesystem::path& out_dir, Clock::time_point start,
                             Clock::time_point outputs_start) {
  TwoSequenceResult result;
  result.reference_frames = setup.ranges.reference_count;
  result.query_frames = setup.ranges.query_count;
  result.loops = run.loops->size();
  nlohmann::json evaluation = run_evaluation(setup, *run.loops, *run.ranked, run.score_order, out_dir);
  setup.phase("outputs and evaluation", outputs_start);
  result.wall_s = seconds_since(start);
  nlohmann::json detection = frames.detection_json();
  if (run.summary.contains("detection")) detection.update(run.summary["detection"]);
  result.summary = std::move(run.summary);
  result.summary.update({
      {"mode", "two-sequence"},
      {"method", run.method},
      {"score_order", run.score_order},
      {"config", std::move(run.config)},
      {"images_decoded", run.ref->described + run.qry->described},
      {"descriptors_computed", run.ref->described + run.qry->described},  // SeqSLAM: preprocessed images
      {"similarities_computed", run.similarities},
      {"loops", run.loops->size()},
      {"query_frames", setup.ranges.query_count},
      {"query_frames_with_error", frames.frame_errors()},
      {"reference_errors", reference_errors_json(*run.ref)},
      {"detection", std::move(detection)},
      {"evaluation", std::move(evaluation)},
      {"wall_s", result.wall_s},
      {"peak_rss_mb", peak_rss_mb()},
  });
  result.summary.update(sequences_json(setup));
  add_aligned_json(setup, run.loops->size(), run.loops_aligned, frames.best_aligned(), result.summary);
  return result;
}

// DIRD (docs/detection.md § Two sequences): describe both, S for every (reference, query) pair, the streaming
// matcher.
TwoSequenceResult run_dird(TwoSequenceSetup setup, const std::filesystem::path& out_dir,
                           Clock::time_point start) {
  const PipelineConfig& config = setup.config;
  const std::size_t ref_count = setup.ranges.reference_count;
  std::size_t query_count = setup.ranges.query_count;
  const DirdExtractor extractor(config.dird);
  const DirdSimilarity similarity(config.dird);

  auto t0 = Clock::now();
  const auto [ref, qry] = describe_both(setup, extractor);
  const double describe_s = seconds_since(t0);
  setup.phase("describe (reference and query)", t0);
  query_count = setup.ranges.query_count = setup.query_taken(ref, qry);  // all, unless a stop request came

  // Similarity rows of every query against the whole reference (no margin), in parallel; frames
  // without a descriptor take part in no pair. Standardised: each sequence coded with its own statistics,
  // the logistic of standard_default_scale() on their distances; raw: dird.mu / dird.sigma. scale.mode
  // online: the logistic from the distances of every (reference, query) pair by the rule of OnlineScale
  // (dird_online_scale.hpp; the no-revisit rule of `loopgate calibrate`), a first pass over the pairs.
  t0 = Clock::now();
  const bool any_ref_missing = ref.described != ref_count;
  std::vector<std::vector<SimilarityEntry>> rows(query_count);
  std::optional<nlohmann::json> standardized;
  std::optional<CodedSequence> ref_codes, qry_codes;
  if (config.standardize.enabled()) {
    ref_codes = code_sequence(ref, config.standardize);
    qry_codes = code_sequence(qry, config.standardize);
    standardized = standardize_json(config.standardize, *ref_codes, *qry_codes);
  }
  const auto distance_of = [&](std::size_t q, std::size_t r) {
    return qry_codes ? coded_distance(config.dird, config.standardize, *qry_codes, q, *ref_codes, r)
                     : similarity.distance(qry.descriptors[q], ref.descriptors[r]);
  };
  LogisticScale scale =
      qry_codes ? standard_default_scale(config.standardize, config.dird.tau1)
                : LogisticScale{config.dird.mu, config.dird.sigma,
                                logistic_distance_at(config.dird.tau1, config.dird.mu, config.dird.sigma),
                                false, 0};
  std::int64_t scale_distances = 0;
  if (config.scale.online()) {
    OnlineScale online(config.scale, config.dird.tau1, scale);
    std::mutex online_mutex;
    parallel_indices(config.run.threads, query_count, nullptr, [&](std::size_t q) {
      if (!qry.valid[q]) return;
      std::vector<double> distances;
      distances.reserve(ref_count);
      for (std::size_t r = 0; r < ref_count; ++r) {
        if (ref.valid[r]) distances.push_back(distance_of(q, r));
      }
      const std::lock_guard lock(online_mutex);
      online.add(std::span<const double>(distances));
    });
    scale_distances = online.count();
    scale = online.scale();
    if (!scale.estimated) {
      spdlog::warn(
          "scale.mode online: {} pair distances are too few for an estimate (scale.min_distances {}): "
          "the configured scale is used",
          online.count(), config.scale.min_distances);
    }
    spdlog::info("scale: mu {:.6g}, sigma {:.6g}, cut-off {:.6g} ({} from {} pair distances)", scale.mu,
                 scale.sigma, scale.cutoff_distance, scale.estimated ? "estimated" : "prior", online.count());
  }
  if (qry_codes || config.scale.online()) {
    parallel_indices(config.run.threads, query_count, nullptr, [&](std::size_t q) {
      if (!qry.valid[q]) return;
      for (std::size_t r = 0; r < ref_count; ++r) {
        if (!ref.valid[r]) continue;
        const double d = distance_of(q, r);
        if (d >= scale.cutoff_distance) continue;
        const double sim = logistic_similarity(d, scale.mu, scale.sigma);
        if (sim > config.dird.tau1) rows[q].push_back({static_cast<std::int64_t>(r), sim});
      }
    });
  } else {
    parallel_indices(config.run.threads, query_count, nullptr, [&](std::size_t q) {
      if (!qry.valid[q]) return;
      similarity.sparse_row(qry.descriptors[q], ref.descriptors.data(), ref_count, 0, rows[q]);
      if (any_ref_missing) {
        std::erase_if(rows[q],
                      [&](const SimilarityEntry& e) { return !ref.valid[static_cast<std::size_t>(e.j)]; });
      }
    });
  }
  const double similarity_s = seconds_since(t0);
  setup.phase("similarities", t0);
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
  setup.phase("match (sequence matcher)", t0);

  const auto outputs_start = Clock::now();
  const std::vector<Detection> detections = as_detections(output.loops);  // within the ranges, score = DP
  MethodRun run("dird", "higher_is_better", config_to_json(config), ref, qry);
  run.loops_aligned = write_loops(setup, detections, out_dir);
  QueryFramesCsv frames(setup, qry, out_dir, {"match_score", "best_similarity", "candidates"});
  for (const FrameMatchStatus& status : output.frames) {
    MatchOutcomeContext context;
    context.two_sequence = true;
    context.described = qry.valid[static_cast<std::size_t>(status.i)] != 0;
    context.tau1 = config.dird.tau1;
    context.dp_threshold = config.match.dp_threshold();
    const bool has_best = status.best_j >= 0;
    frames.write(static_cast<std::size_t>(status.i), match_detection(status, context),
                 {has_best ? format_fixed(status.best_score, 6) : "", format_fixed(status.best_similarity, 6),
                  std::to_string(status.candidates)});
  }
  frames.close();

  run.similarities = similarities;
  run.loops = run.ranked = &detections;
  run.summary = {
      {"detection", {{"nms_delay_frames", matcher.emission_delay()}}},
      {"stages_s", {{"describe", describe_s}, {"similarity", similarity_s}, {"match", match_s}}},
      {"scale",
       {{"mode", config.scale.mode},
        {"mu", scale.mu},
        {"sigma", scale.sigma},
        {"cutoff_distance", scale.cutoff_distance},
        {"estimated", scale.estimated},
        {"distances", scale_distances}}},
  };
  if (standardized) run.summary["standardize"] = *standardized;
  return finish_run(setup, std::move(run), frames, out_dir, start, outputs_start);
}

// dird-seqslam (docs/illumination.md): describe both, code each with its own statistics, the distance of
// every (query, reference) pair, then the contrast-enhanced sequence search query by query (two-sequence
// mode: no margin). frames.csv gives every query's best line, accepted or not; loops.csv the accepted ones
// (score = mean z, higher is better); the PR sweep runs over every query's best line.
TwoSequenceResult run_dird_seqslam(TwoSequenceSetup setup, const std::filesystem::path& out_dir,
                                   Clock::time_point start) {
  const PipelineConfig& config = setup.config;
  const Dataset& query = setup.query;
  const std::size_t ref_count = setup.ranges.reference_count;
  const std::size_t query_first = setup.ranges.query_first;
  std::size_t query_count = setup.ranges.query_count;
  const DirdConfig dird = config.dird_seqslam.descriptor(config.dird);
  const StandardizeConfig standardize = config.dird_seqslam.standardization(config.standardize);
  const DirdExtractor extractor(dird);

  auto t0 = Clock::now();
  const auto [ref, qry] = describe_both(setup, extractor);
  query_count = setup.ranges.query_count = setup.query_taken(ref, qry);  // all, unless a stop request came
  const CodedSequence ref_codes = code_sequence(ref, standardize);
  const CodedSequence qry_codes = code_sequence(qry, standardize);
  // Compact codes (dird_seqslam.code sign or ternary) of both sequences, from their int8 codes.
  std::optional<CompactCodeMatrix> ref_compact, qry_compact;
  if (config.dird_seqslam.codes.compact()) {
    const auto compact = [&](const CodedSequence& coded, const DescribedSequence& described) {
      CompactCodeMatrix m(config.dird_seqslam.codes, standardize.clamp_sigma,
                          std::max<std::size_t>(1, coded.codes.size()));
      for (std::size_t k = 0; k < coded.codes.size(); ++k)
        if (described.valid[k]) m.set(k, coded.codes[k]);
      return m;
    };
    ref_compact.emplace(compact(ref_codes, ref));
    qry_compact.emplace(compact(qry_codes, qry));
  }
  const auto distance_of = [&](std::size_t q, std::size_t r) {
    return qry_compact ? qry_compact->distance(q, *ref_compact, r)
                       : coded_distance(dird, standardize, qry_codes, q, ref_codes, r);
  };
  const double describe_s = seconds_since(t0);
  setup.phase("describe and code (reference and query)", t0);

  // Distances in blocks of queries (in parallel), each block then searched in query order: memory for
  // one block of rows, not the whole matrix.
  constexpr std::size_t kBlock = 256;
  double distance_s = 0.0, search_s = 0.0;
  ContrastSequenceSearch search(config.dird_seqslam.search, config.match.sequence_length,
                                ContrastSequenceSearch::Mode::kTwoSequence, 0, 0);
  ContrastOutput output;
  std::vector<std::vector<DistanceEntry>> rows(std::min(kBlock, query_count));
  for (std::size_t first = 0; first < query_count; first += kBlock) {
    const std::size_t count = std::min(kBlock, query_count - first);
    t0 = Clock::now();
    parallel_indices(
        config.run.threads, count, nullptr,
        [&](std::size_t k) {
          const std::size_t q = first + k;
          rows[k].clear();
          if (!qry.valid[q]) return;
          rows[k].reserve(ref_count);
          for (std::size_t r = 0; r < ref_count; ++r) {
            if (ref.valid[r]) rows[k].push_back({static_cast<std::int64_t>(r), distance_of(q, r)});
          }
        },
        setup.blocks("distances"));
    distance_s += seconds_since(t0);
    setup.phase("distances (query block)", t0);
    t0 = Clock::now();
    stop_request::check_abort("two-sequence run");  // a second stop signal aborts the search
    for (std::size_t k = 0; k < count; ++k)
      search.push(static_cast<std::int64_t>(first + k), rows[k], output);
    search_s += seconds_since(t0);
    setup.phase("search (query block)", t0);
  }
  t0 = Clock::now();
  search.flush(output);
  search_s += seconds_since(t0);
  setup.phase("search flush", t0);

  const auto outputs_start = Clock::now();
  const std::vector<Detection> loops = as_detections(output.loops);  // within the ranges, score = mean z
  MethodRun run("dird-seqslam", "higher_is_better", config_to_json(config), ref, qry);
  run.loops_aligned = write_loops(setup, loops, out_dir);
  QueryFramesCsv frames(setup, qry, out_dir, {"match_score", "velocity", "line_end_frame"});
  std::vector<Detection> ranked;
  for (const ContrastVerdict& verdict : output.frames) {
    const auto q = static_cast<std::size_t>(verdict.i);
    ContrastOutcomeContext context;
    context.two_sequence = true;
    context.described = qry.valid[q] != 0;
    context.min_score = config.dird_seqslam.search.min_score;
    const bool has_best = verdict.best_j >= 0;
    if (has_best) ranked.push_back(Detection{q, static_cast<std::size_t>(verdict.best_j), verdict.score});
    frames.write(
        q, contrast_detection(verdict, context),
        {has_best ? format_fixed(verdict.score, 6) : "", has_best ? format_fixed(verdict.velocity, 4) : "",
         has_best
             ? std::to_string(query.source_index(query_first + static_cast<std::size_t>(verdict.line_end)))
             : ""});
  }
  frames.close();

  run.similarities = ref.described * qry.described;  // distances
  run.loops = &loops;
  run.ranked = &ranked;
  run.summary = {
      {"detection", {{"delay_frames", search.emission_delay()}}},
      {"dird_seqslam",
       {{"normalization", dird.normalization},
        {"resize", dird.resize},
        {"velocities", config.dird_seqslam.search.velocities()},
        {"sequence_length", search.sequence_length()}}},
      {"stages_s", {{"describe", describe_s}, {"distances", distance_s}, {"search", search_s}}},
  };
  if (standardize.enabled()) run.summary["standardize"] = standardize_json(standardize, ref_codes, qry_codes);
  return finish_run(setup, std::move(run), frames, out_dir, start, outputs_start);
}

// SeqSLAM (docs/detection.md § SeqSLAM) between two runs: step 1 on both sequences in parallel, then the
// difference matrix (reference rows x query columns), contrast enhancement and sequence search with exclusion
// "none".
TwoSequenceResult run_seqslam(TwoSequenceSetup setup, const std::filesystem::path& out_dir,
                              Clock::time_point start) {
  const PipelineConfig& config = setup.config;
  const Dataset& reference = setup.reference;
  const Dataset& query = setup.query;
  const std::size_t ref_first = setup.ranges.reference_first, ref_count = setup.ranges.reference_count;
  const std::size_t query_first = setup.ranges.query_first;
  std::size_t query_count = setup.ranges.query_count;
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
  const DescribedSequence ref = preprocess_sequence(config.run.threads, reference, ref_first, ref_count, 0,
                                                    batch, setup.stop, setup.blocks("preprocess reference"));
  const DescribedSequence qry =
      preprocess_sequence(config.run.threads, query, query_first, query_count, ref_count, batch, setup.stop,
                          setup.blocks("preprocess query"));
  const double preprocess_s = seconds_since(t0);
  setup.phase("preprocess (reference and query)", t0);
  query_count = setup.ranges.query_count = setup.query_taken(ref, qry);  // all, unless a stop request came
  for (const auto& [dataset, described] : {std::pair{&reference, &ref}, std::pair{&query, &qry}}) {
    if (described->described == 0 && query_count > 0) {
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
  if (query_count > 0) arena.execute([&] { matches = batch.run_two_sequence(ref_count, query_count); });
  const double search_s = seconds_since(t0);
  setup.phase("search (SeqSLAM)", t0);

  const auto outputs_start = Clock::now();
  QueryFramesCsv frames(setup, qry, out_dir, {"match_score", "best_score", "second_score"},
                        " (took part as an all-zero image)");
  std::vector<Detection> loops, ranked;  // indices within the ranges, score = ratio
  SeqSlamOutcomeContext context;
  context.two_sequence = true;
  context.query_count = query_count;
  context.reference_count = ref_count;
  context.reference_first = ref_first;
  for (std::size_t q = 0; q < query_count; ++q) {
    const SeqSlamMatch& m = matches.at(q);
    const FrameDetection detection = seqslam_detection(m, seqslam, context);
    const bool has_match = detection.match >= 0;
    if (has_match) {
      if (std::isfinite(m.ratio)) ranked.push_back(Detection{q, m.reference, m.ratio});
      if (detection.outcome == FrameOutcome::kLoop) loops.push_back(Detection{q, m.reference, m.ratio});
    }
    frames.write(q, detection,
                 {has_match ? format_fixed(m.ratio, 6) : "", has_match ? format_fixed(m.best_score, 6) : "",
                  has_match ? format_fixed(m.second_score, 6) : ""});
  }
  frames.close();

  MethodRun run("seqslam", "lower_is_better", config_to_json(effective), ref, qry);
  run.loops_aligned = write_loops(setup, loops, out_dir);
  run.similarities = ref_count * query_count;  // difference matrix entries
  run.loops = &loops;
  run.ranked = &ranked;
  run.summary = {{"stages_s", {{"preprocess", preprocess_s}, {"search", search_s}}}};
  return finish_run(setup, std::move(run), frames, out_dir, start, outputs_start);
}

}  // namespace

TwoSequenceResult run_two_sequences(const PipelineConfig& config, const Dataset& reference,
                                    const Dataset& query, const std::filesystem::path& out_dir,
                                    const std::atomic<bool>* stop) {
  if (!config.eval.truth_pairs_file.empty()) {
    throw ConfigError(
        "eval.truth_pairs_file: pairs of frame numbers within one sequence (single-sequence runs); two "
        "sequences are evaluated with eval.aligned_tolerance_frames");
  }
  for (const Dataset* dataset : {&reference, &query}) {
    if (dataset->frame_count() == 0) throw DataError(dataset->root(), "dataset has no frames");
    if (!dataset->has_images()) throw DataError(dataset->root(), "two-sequence mode needs images");
  }
  const auto [ref_first, ref_last] = config.run.frame_range(reference.frame_count());
  const auto [query_first, query_last] = config.run.frame_range(query.frame_count());
  const AlignedSequences ranges{ref_first, ref_last - ref_first, query_first, query_last - query_first,
                                config.eval.aligned_tolerance_frames};
  // One frame on a side leaves no match to rank (measured: a query of one frame against copies of itself
  // gives no loop with any method), so such a run fails before it writes anything, as a single-sequence run
  // with no pair to compare does.
  if (ranges.reference_count < 2 || ranges.query_count < 2) {
    throw DataError(
        ranges.reference_count < 2 ? reference.root() : query.root(),
        fmt::format("no detection possible: the reference has {} frame(s) and the query {} in the "
                    "range run; a two-sequence run needs at least 2 frames on each side (a longer "
                    "--frames range or sequence)",
                    ranges.reference_count, ranges.query_count));
  }
  TraceWriter trace;
  TwoSequenceSetup setup{config, reference, query, ranges, stop, RunTrace{}};
  spdlog::info("two-sequence run ({}): reference {} ({} frames) vs query {} ({} frames), {} threads",
               enum_name(config.run.method), reference.root().string(), setup.ranges.reference_count,
               query.root().string(), setup.ranges.query_count, config.run.threads);
  const auto start = Clock::now();
  if (config.output.trace) setup.trace = RunTrace{&trace, start};
  std::filesystem::create_directories(out_dir);
  TwoSequenceResult result = config.run.seqslam()        ? run_seqslam(setup, out_dir, start)
                             : config.run.dird_seqslam() ? run_dird_seqslam(setup, out_dir, start)
                                                         : run_dird(setup, out_dir, start);
  result.interrupted = stop && stop->load();
  result.summary["interrupted"] = result.interrupted;
  result.summary["provenance"] = provenance_json(result.summary.value("config", nlohmann::json::object()));
  if (config.output.trace) {
    trace.name_process(fmt::format("loopgate run: two sequences, {} ({} vs {})", enum_name(config.run.method),
                                   reference.root().string(), query.root().string()));
    trace.name_thread(0, "main");
    for (int t = 1; t < config.run.threads; ++t) trace.name_thread(t, fmt::format("worker {}", t));
    trace.write(out_dir / "trace.json");
  }
  write_json_file(out_dir / "summary.json", result.summary);
  return result;
}

}  // namespace loopgate
