// Gated SeqSLAM as a detection method (run.method seqslam, run.mode gated; docs/seqslam-gated.md): SeqSLAM
// only inside the pose gate's candidate areas, next to full SeqSLAM (seqslam_method.cpp), full and gated
// DIRD. The algorithm and its invariant against full SeqSLAM are in stages/seqslam/seqslam_gated.hpp.
//   gate:     the pose gate and the candidate areas (PoseGatedCells); the cells this frame's update covered
//   go
//             to the search at once, and the frames the search will read for them are requested: the cells'
//             own frames (the tracker's requests) and their neighbours (the ds/2 query frames on each side,
//             the reference rows the sequences and the contrast windows reach, SeqSlamGatedSearch::
//             frames_for_cells); a neighbour after the current frame is requested when it arrives.
//   describe: SeqSLAM step 1 for exactly those frames (past ones read again), several in parallel, each once.
//   match:    nothing to decide yet.
//   finish:   steps 2-4 on the covered cells, in parallel over columns, then over queries. SeqSLAM stays a
//             batch method here too: a query's sequence reaches ds/2 frames ahead, a row can still gain cells
//             gate.row_horizon_frames later, and the minimum subtracted in step 3 is taken over every cell.
// Memory: the preprocessed images of the frames requested (2 KiB each, committed as written) and the
// difference / enhanced values of the cells the search reads, not the n x n matrix.
#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include <atomic>
#include <cmath>
#include <limits>
#include <mutex>
#include <stdexcept>

#include "parallel/parallel_handoff.hpp"
#include "pipeline/frame/frame_steps.hpp"
#include "pipeline/loops/loops_writer.hpp"
#include "pipeline/methods/detection_method.hpp"
#include "pipeline/methods/gated_cells.hpp"
#include "pipeline/methods/seqslam_batch.hpp"
#include "stages/seqslam/seqslam_gated.hpp"
#include "stages/seqslam/seqslam_outcome.hpp"

namespace loopgate {

namespace {

enum class Preprocessed : std::uint8_t { kNo, kYes, kZeroImage };

class SeqSlamGated final : public DetectionMethod {
 public:
  explicit SeqSlamGated(const MethodContext& context)
      : context_(context),
        cells_(context),
        batch_(context.config.seqslam, context.capacity),
        search_(context.config.seqslam),
        state_(context.capacity, Preprocessed::kNo),
        wanted_(context.capacity, 0) {
    const SeqSlamConfig& seqslam = context.config.seqslam;
    if (seqslam.exclusion == SeqSlamExclusionKind::kPast &&
        seqslam.exclusion_margin_frames != context.config.match.margin) {
      spdlog::warn(
          "gated SeqSLAM: the candidate areas hold the pairs i - j >= match.margin = {}, the search excludes "
          "those closer than seqslam.exclusion_margin_frames = {}: only pairs beyond both are searched",
          context.config.match.margin, seqslam.exclusion_margin_frames);
    }
  }

  std::string name() const override { return "seqslam"; }
  std::string mode() const override { return "gated"; }

  // The gate's cells go to the search now, and every frame they will read is requested (gate node, serial).
  void gate(FrameRecord& r) override {
    cells_.gate(r);
    const std::size_t seq = r.seq;
    for (const CellSpan& span : cells_.take_cells(seq)) {
      const auto i = static_cast<std::size_t>(span.i);
      const auto j0 = static_cast<std::size_t>(span.j0);
      const auto j1 = static_cast<std::size_t>(span.j1);
      search_.add_cells(i, j0, j1);
      needed_.clear();
      search_.frames_for_cells(i, j0, j1, needed_);
      for (const std::size_t k : needed_) {
        if (k <= seq) {
          cells_.request_descriptor(seq, static_cast<std::int64_t>(k));
        } else if (k < wanted_.size()) {
          wanted_[k] = 1;  // a later frame: requested when it arrives
        }
      }
    }
    if (wanted_[seq]) cells_.request_descriptor(seq, static_cast<std::int64_t>(seq));
    frames_requested_ += cells_.describe_list(seq).size();
  }

  // Step 1 for the frames requested at this frame (several in parallel); a frame that cannot be read or
  // preprocessed takes part as an all-zero image, as in full SeqSLAM.
  void describe(FrameRecord& r) override {
    std::mutex problems_mutex;
    std::vector<std::pair<bool, std::string>> problems;  // (own frame: error, else warning)
    describe_frames(r, cells_.describe_list(r.seq), context_, [&](std::size_t k, const cv::Mat* image) {
      if (image) {
        try {
          batch_.add(k, *image);
          state_[k] = Preprocessed::kYes;
          descriptors_computed_.fetch_add(1, std::memory_order_relaxed);
          return;
        } catch (const std::invalid_argument& e) {
          const std::lock_guard lock(problems_mutex);
          problems.emplace_back(
              k == r.seq, k == r.seq
                              ? std::string("seqslam preprocessing: ") + e.what()
                              : fmt::format("seqslam preprocessing of frame {}: {}",
                                            context_.seqs.frame(static_cast<std::int64_t>(k)), e.what()));
        }
      }
      batch_.add_missing(k);
      state_[k] = Preprocessed::kZeroImage;
    });
    for (auto& [own, message] : problems) add_message(own ? r.errors : r.warnings, std::move(message));
  }

  void match(FrameRecord& r) override { frames_ = r.seq + 1; }

  // Steps 2-4 on the covered cells (inside the run's task arena); loops.csv for the accepted matches.
  void finish() override {
    cells_.finish();
    const std::size_t n = frames_;
    search_.plan(n);
    const std::vector<std::size_t> read = search_.frames_read();
    frames_read_ = read.size();
    count_frames_of_cells(n);
    for (const std::size_t k : read) {
      if (state_[k] == Preprocessed::kNo) {
        throw std::logic_error(
            fmt::format("gated SeqSLAM reads frame seq {}, which was never preprocessed", k));
      }
    }
    const SeqSlamFrames frames{batch_.image(0), batch_.pixel_count()};
    const std::vector<std::size_t>& columns = search_.columns();
    std::vector<double> column_minimum(columns.size(), std::numeric_limits<double>::infinity());
    parallel_for_with_handoff(columns.size(), [&](std::size_t index) {
      column_minimum[index] = search_.compute_column(columns[index], frames);
    });
    double minimum = std::numeric_limits<double>::infinity();
    for (const double m : column_minimum) minimum = std::min(minimum, m);
    search_.subtract(minimum);
    matches_.assign(n, SeqSlamMatch{});
    for (std::size_t q = 0; q < n; ++q) matches_[q].query = q;
    const std::vector<std::size_t>& queries = search_.queries();
    parallel_for_with_handoff(queries.size(), [&](std::size_t index) {
      matches_[queries[index]] = search_.match_query(queries[index]);
    });
    searched_ = true;
    for (const SeqSlamMatch& m : matches_) {
      if (!m.has_match || !std::isfinite(m.ratio)) continue;
      const std::size_t frame_i = context_.seqs.frame(static_cast<std::int64_t>(m.query));
      const std::size_t frame_j = context_.seqs.frame(static_cast<std::int64_t>(m.reference));
      ranked_.push_back(Detection{frame_i, frame_j, m.ratio});
      if (!m.accepted) continue;
      context_.loops.write(frame_i, frame_j, context_.seqs.t_ns(static_cast<std::int64_t>(m.query)),
                           context_.seqs.t_ns(static_cast<std::int64_t>(m.reference)), m.ratio);
    }
  }

  void add_frame_cells(const FrameRecord& r, CsvRow& row) const override { cells_.add_frame_cells(r, row); }

  std::optional<FrameVerdict> detection(std::size_t seq) override {
    if (!searched_) return std::nullopt;
    SeqSlamOutcomeContext c;
    c.query_count = frames_;
    c.gated = true;
    c.outside_areas = cells_.row_empty(seq);
    return FrameVerdict{state_[seq] == Preprocessed::kYes,
                        seqslam_detection(matches_.at(seq), context_.config.seqslam, c)};
  }

  void write_files(const std::filesystem::path& out_dir) const override {
    cells_.write_files(out_dir, frames_, [this](std::int64_t k) {
      return state_[static_cast<std::size_t>(k)] == Preprocessed::kYes;
    });
  }

  ScoreOrder score_order() const override { return ScoreOrder::kLowerIsBetter; }
  // descriptors_computed: frames preprocessed; similarities_computed: difference-matrix entries computed.
  nlohmann::json summary() const override {
    nlohmann::json out = {{"descriptors_computed", descriptors_computed_.load()},
                          {"similarities_computed", search_.difference_entries()},
                          {"seqslam_gated",
                           {{"frames_requested", frames_requested_},
                            {"frames_of_cells", frames_of_cells_},
                            {"frames_neighbours_only", frames_requested_ - frames_of_cells_},
                            {"frames_read", frames_read_},
                            {"difference_entries", search_.difference_entries()},
                            {"enhanced_entries", search_.enhanced_entries()},
                            {"queries_searched", search_.queries().size()},
                            {"minimum_subtracted", search_.minimum()}}}};
    out.update(cells_.summary(frames_));
    return out;
  }

  // The PR sweep runs over every query's match, accepted or not (the ratio is the threshold), as full
  // SeqSLAM.
  MethodEvaluation evaluation() const override {
    MethodEvaluation e;
    e.ranked = ranked_;
    e.covers = [this](std::int64_t i, std::int64_t j) { return cells_.covers(i, j); };
    return e;
  }

 private:
  // The frames that are a row or a column of a covered cell (what gated DIRD would describe); every one was
  // requested. The other requested frames are only neighbours (sequence ends, contrast windows).
  void count_frames_of_cells(std::size_t n) {
    std::vector<std::uint8_t> of_cells(n, 0);
    for (std::size_t i = 0; i < n; ++i) {
      for (const RowColumns& span : cells_.tracker().covered_columns(static_cast<std::int64_t>(i))) {
        of_cells[i] = 1;
        for (std::int64_t j = span.j0; j <= span.j1; ++j) of_cells[static_cast<std::size_t>(j)] = 1;
      }
    }
    frames_of_cells_ = 0;
    for (const std::uint8_t c : of_cells) frames_of_cells_ += c;
  }

  const MethodContext context_;  // references to the run's objects (a copy: the struct is a temporary)
  PoseGatedCells cells_;
  SeqSlamBatch batch_;  // preprocessed images by seq (only the requested ones are written)
  SeqSlamGatedSearch search_;
  std::vector<Preprocessed> state_;   // per seq, written once by describe, read after the graph drained
  std::vector<std::uint8_t> wanted_;  // per seq: a neighbour requested before the frame arrived (gate node)
  std::vector<std::size_t> needed_;   // scratch of gate()
  std::size_t frames_requested_ = 0, frames_of_cells_ = 0, frames_read_ = 0;
  std::atomic<std::size_t> descriptors_computed_{0};
  std::size_t frames_ = 0;  // frames through match
  bool searched_ = false;
  std::vector<SeqSlamMatch> matches_;
  std::vector<Detection> ranked_;  // every query's finite match, dataset frame indices
};

}  // namespace

std::unique_ptr<DetectionMethod> make_seqslam_gated(const MethodContext& context) {
  return std::make_unique<SeqSlamGated>(context);
}

}  // namespace loopgate
