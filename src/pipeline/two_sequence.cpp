// The wiring of a two-sequence run: the checks, the run clock, the trace, the parallel loop, the description
// of both sequences through the method's two-sequence form (methods/two_sequence/two_sequence_method.hpp),
// its matches, and the outputs (outputs/two_sequence_outputs.hpp). Nothing here depends on which method runs.
#include "pipeline/two_sequence.hpp"

#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include "core/error.hpp"
#include "core/stop_request.hpp"
#include "io/dataset.hpp"
#include "io/provenance.hpp"
#include "io/writers.hpp"
#include "parallel/parallel_handoff.hpp"
#include "pipeline/frame/run_clock.hpp"
#include "pipeline/graph/run_resources.hpp"
#include "pipeline/methods/two_sequence/two_sequence_method.hpp"
#include "pipeline/outputs/two_sequence_outputs.hpp"

namespace loopgate {

namespace {

// The run's services to its method: the clock (RunClock, as in a single-sequence run), trace.json (phases on
// the calling thread's track 0, blocks on the track of the worker that ran them, in microseconds since the
// start) and the parallel loop.
class TwoSequenceWiring final : public TwoSequenceRun {
 public:
  TwoSequenceWiring(const PipelineConfig& config, const std::atomic<bool>* stop)
      : config_(config), stop_(stop), trace_on_(config.output.trace) {}

  std::int64_t now_ns() const override { return clock_.now_ns(); }
  void phase(const char* name, std::int64_t from_ns) override { span(name, "phase", from_ns, 0); }
  void parallel(std::size_t count, const std::function<void(std::size_t)>& body,
                const char* blocks) override {
    handout(count, nullptr, body, blocks);
  }

  // Runs body(k) for k in [0, count): run.threads workers on the run's parallel loop
  // (parallel_for_with_handoff) take blocks of indices in turn. Once `stop` is set no block is handed out;
  // the blocks handed out are finished, so the indices done are a prefix [0, returned). A second stop signal
  // aborts (stop_request::check_abort); the first exception of a body is rethrown once every worker returned.
  std::size_t handout(std::size_t count, const std::atomic<bool>* stop,
                      const std::function<void(std::size_t)>& body, const char* blocks) {
    constexpr std::size_t kBlock = 16;
    std::atomic<std::size_t> next{0};
    std::mutex handout_mutex;  // a block is handed out only while no stop is requested
    const auto worker = [&](std::size_t track) {
      for (;;) {
        std::size_t begin = 0;
        {
          std::lock_guard lock(handout_mutex);
          if (stop && stop->load()) return;
          begin = next.fetch_add(kBlock, std::memory_order_relaxed);
        }
        if (begin >= count) return;
        try {
          stop_request::check_abort("two-sequence run");
          const std::int64_t block_start = now_ns();
          const std::size_t end = std::min(count, begin + kBlock);
          for (std::size_t k = begin; k < end; ++k) body(k);
          if (blocks)
            span(blocks, "block", block_start, static_cast<int>(track), fmt::format("[{}, {})", begin, end));
        } catch (...) {
          next.store(count, std::memory_order_relaxed);  // the other workers take no further block
          throw;
        }
      }
    };
    parallel_for_with_handoff(static_cast<std::size_t>(config_.run.threads), worker);
    return std::min(count, next.load());
  }

  // Frames [first, first + count) of `dataset` through the method's describe(), traced as "STEP SIDE" blocks.
  DescribedFrames describe(TwoSequenceMethod& method, SequenceSide side, const Dataset& dataset,
                           std::size_t first, std::size_t count) {
    DescribedFrames out;
    out.valid.assign(count, 0);
    out.errors.resize(count);
    const std::string blocks = fmt::format("{} {}", method.describe_step(),
                                           side == SequenceSide::kReference ? "reference" : "query");
    out.taken = handout(
        count, stop_,
        [&](std::size_t k) {
          bool valid = false;
          try {
            const cv::Mat image = dataset.load_image(first + k);
            valid = method.describe(side, k, &image, dataset, first + k, out.errors[k]);
          } catch (const DataError& e) {
            out.errors[k] = std::string("image: ") + e.what();
            method.describe(side, k, nullptr, dataset, first + k, out.errors[k]);
          }
          out.valid[k] = valid ? 1 : 0;
        },
        blocks.c_str());
    out.described = static_cast<std::size_t>(std::count(out.valid.begin(), out.valid.end(), std::uint8_t{1}));
    return out;
  }
  void write_trace(const std::filesystem::path& file, const Dataset& reference, const Dataset& query) {
    trace_.name_process(fmt::format("loopgate run: two sequences, {} ({} vs {})",
                                    enum_name(config_.run.method), reference.root().string(),
                                    query.root().string()));
    trace_.name_thread(0, "main");
    for (int t = 1; t < config_.run.threads; ++t) trace_.name_thread(t, fmt::format("worker {}", t));
    trace_.write(file);
  }

 private:
  void span(std::string name, const char* category, std::int64_t from_ns, int track,
            std::string detail = {}) {
    if (!trace_on_) return;
    const double from_us = 1e-3 * static_cast<double>(from_ns);
    trace_.add(TraceEvent{std::move(name), category, from_us, 1e-3 * static_cast<double>(now_ns()) - from_us,
                          track, -1, -1, 'X', std::move(detail)});
  }

  const PipelineConfig& config_;
  const std::atomic<bool>* stop_;
  RunClock clock_;
  TraceWriter trace_;
  bool trace_on_ = false;
};

// The frame ranges run, after the checks that need no image. Throws ConfigError / DataError.
AlignedSequences checked_ranges(const PipelineConfig& config, const Dataset& reference,
                                const Dataset& query) {
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
  return ranges;
}

}  // namespace

TwoSequenceResult run_two_sequences(const PipelineConfig& config, const Dataset& reference,
                                    const Dataset& query, const std::filesystem::path& out_dir,
                                    const std::atomic<bool>* stop) {
  AlignedSequences ranges = checked_ranges(config, reference, query);
  const std::unique_ptr<TwoSequenceMethod> method = make_two_sequence_method(config);
  spdlog::info("two-sequence run ({}): reference {} ({} frames) vs query {} ({} frames), {} threads",
               enum_name(config.run.method), reference.root().string(), ranges.reference_count,
               query.root().string(), ranges.query_count, config.run.threads);
  TwoSequenceWiring run(config, stop);
  std::filesystem::create_directories(out_dir);
  method->begin(ranges.reference_count, ranges.query_count);

  tbb::task_arena arena(config.run.threads);
  DescribedFrames ref, qry;
  TwoSequenceMatches matches;
  const auto t0 = run.now_ns();
  arena.execute([&] {
    ref = run.describe(*method, SequenceSide::kReference, reference, ranges.reference_first,
                       ranges.reference_count);
    qry = run.describe(*method, SequenceSide::kQuery, query, ranges.query_first, ranges.query_count);
  });
  const double describe_s = seconds_between(t0, run.now_ns());
  run.phase(fmt::format("{} (reference and query)", method->describe_step()).c_str(), t0);
  // A stop request: the query range ends after the frames taken (none when the reference was incomplete).
  ranges.query_count = ref.taken < ranges.reference_count ? 0 : qry.taken;
  const TwoSequenceInput input{ref,       qry,   ranges.reference_count, ranges.query_count,
                               reference, query, ranges.reference_first, ranges.query_first};
  arena.execute([&] { matches = method->match(run, input); });
  matches.summary["stages_s"][method->describe_step()] = describe_s;

  const auto outputs_start = run.now_ns();
  TwoSequenceResult result;
  result.summary = write_two_sequence_outputs(*method, matches, input, ranges, out_dir);
  run.phase("outputs and evaluation", outputs_start);
  result.reference_frames = ranges.reference_count;
  result.query_frames = ranges.query_count;
  result.loops = matches.loops.size();
  result.wall_s = seconds_between(0, run.now_ns());
  result.interrupted = stop && stop->load();
  result.summary["wall_s"] = result.wall_s;
  result.summary["peak_rss_mb"] = peak_rss_mb();
  result.summary["interrupted"] = result.interrupted;
  result.summary["provenance"] = provenance_json(result.summary.value("config", nlohmann::json::object()));
  if (config.output.trace) run.write_trace(out_dir / "trace.json", reference, query);
  write_json_file(out_dir / "summary.json", result.summary);
  return result;
}

}  // namespace loopgate
