// SeqSLAM steps 2-5 (docs/detection.md § SeqSLAM): difference matrix, local contrast enhancement,
// velocity-constrained sequence search with the ratio test. Plain functions over blocks of rows or
// columns so a caller can split the work across threads; SeqSlam::run does everything in order.
#pragma once

#include <cstddef>
#include <cstdint>
#include <limits>
#include <opencv2/core/mat.hpp>
#include <vector>

#include "stages/seqslam/seqslam_config.hpp"

namespace loopgate {

// A set of preprocessed images of equal size, stored contiguously (image i at i * pixel_count()).
class SeqSlamImages {
 public:
  explicit SeqSlamImages(std::size_t pixel_count = 0) : pixel_count_(pixel_count) {}

  std::size_t pixel_count() const { return pixel_count_; }
  std::size_t size() const { return pixel_count_ == 0 ? 0 : bytes_.size() / pixel_count_; }
  const std::uint8_t* image(std::size_t i) const { return bytes_.data() + i * pixel_count_; }
  // Appends one image; throws std::invalid_argument when its size differs from pixel_count().
  // (The first image fixes pixel_count() when it was 0.)
  void add(const std::vector<std::uint8_t>& image);
  // Appends an 8-bit single-channel image already preprocessed (e.g. the KITTI thumbnails).
  void add(const cv::Mat& grey);
  void reserve(std::size_t images) { bytes_.reserve(images * pixel_count_); }

 private:
  std::size_t pixel_count_ = 0;
  std::vector<std::uint8_t> bytes_;
};

// Dense matrix with rows = reference frames and columns = query frames, stored column by column
// (query-major): column(q)[r] == at(r, q). Excluded entries hold +infinity.
class SeqSlamMatrix {
 public:
  SeqSlamMatrix() = default;
  SeqSlamMatrix(std::size_t reference_count, std::size_t query_count, double fill = 0.0)
      : rows_(reference_count), cols_(query_count), data_(reference_count * query_count, fill) {}

  std::size_t reference_count() const { return rows_; }
  std::size_t query_count() const { return cols_; }
  double& at(std::size_t r, std::size_t q) { return data_[q * rows_ + r]; }
  double at(std::size_t r, std::size_t q) const { return data_[q * rows_ + r]; }
  double* column(std::size_t q) { return data_.data() + q * rows_; }
  const double* column(std::size_t q) const { return data_.data() + q * rows_; }

 private:
  std::size_t rows_ = 0;
  std::size_t cols_ = 0;
  std::vector<double> data_;
};

// Sum of absolute differences of two byte arrays (SSE2 psadbw when available).
std::uint32_t seqslam_sad(const std::uint8_t* a, const std::uint8_t* b, std::size_t n);

// Step 2 on a block: D(r, q) = mean absolute difference of reference r and query q for
// r in [r_begin, r_end), q in [q_begin, q_end); excluded entries are set to +infinity without being
// computed. Returns the entries computed (the block minus its excluded entries). Blocks may be computed
// concurrently (they write disjoint entries).
std::size_t seqslam_difference_block(const SeqSlamImages& reference, const SeqSlamImages& query,
                                     const SeqSlamExclusion& exclusion, std::size_t r_begin,
                                     std::size_t r_end, std::size_t q_begin, std::size_t q_end,
                                     SeqSlamMatrix& D);

// Step 3 on columns [q_begin, q_end), in place: for each row r, over the finite entries of rows
// max(0, r - R/2) .. min(n - 1, r + R/2) of the same column, E = (D - mean) / sample std (0 when
// the std is 0 or only one entry is finite); infinite entries stay infinite. Returns the minimum
// finite E of these columns (+infinity if none). The caller then subtracts the global minimum with
// seqslam_subtract(); columns are independent, so blocks may run concurrently.
double seqslam_enhance_contrast(SeqSlamMatrix& M, int window_rows, std::size_t q_begin, std::size_t q_end);
void seqslam_subtract(SeqSlamMatrix& M, double value, std::size_t q_begin, std::size_t q_end);

// Step 3 for one entry, the arithmetic seqslam_enhance_contrast uses: E of row r of a column with
// `reference_count` rows whose D values of rows [first, ...) are at `d` (d[k - first] = D(k); the window
// max(0, r - R/2) .. min(reference_count - 1, r + R/2) must lie at or after `first` and be readable).
// +infinity when D(r) is not finite. A caller holding only some rows of a column (gated SeqSLAM) gets the
// values of the whole column, bit for bit.
double seqslam_enhanced_entry(const double* d, std::size_t first, std::size_t reference_count,
                              int window_rows, std::size_t r);

// The result for one query column.
struct SeqSlamMatch {
  std::size_t query = 0;
  bool has_match = false;     // false within ds/2 of either end, or when every sequence is excluded
  std::size_t reference = 0;  // best start row + ds/2
  double best_score = std::numeric_limits<double>::quiet_NaN();
  double second_score =
      std::numeric_limits<double>::quiet_NaN();  // +inf when nothing lies outside the window
  // best / second (lower is better); 1 when both are 0; +inf when there is no finite second best
  // (the match then has no support and is never accepted); NaN without a match.
  double ratio = std::numeric_limits<double>::quiet_NaN();
  bool accepted = false;  // has_match && ratio <= ratio_threshold
};

// Step 4 for query column `query` of the enhanced matrix E (after the global minimum was
// subtracted). Sequence score of start row s and move v: sum over t = 0..ds of
// E(s + floor(t * v / ds), query - ds/2 + t), +infinity when a row is beyond the last reference row
// or the entry is excluded; score(s) = min over moves; best = first argmin; second = min of score
// outside [best - Rwindow/2, best + Rwindow/2].
SeqSlamMatch seqslam_match_query(const SeqSlamMatrix& E, std::size_t query, const SeqSlamConfig& config);

// The per-start-row scores of step 4 (size = reference count), exposed for tests and plots.
std::vector<double> seqslam_sequence_scores(const SeqSlamMatrix& E, std::size_t query,
                                            const SeqSlamConfig& config);

// The best / second / ratio part of step 4 for query `query` from its sequence scores: scores[k] is the
// score of start row first_start + k (+infinity: no sequence). best = first argmin, second = min outside
// best +- Rwindow/2 (both over the rows given); no match when every score is infinite.
SeqSlamMatch seqslam_match_from_scores(std::size_t query, const double* scores, std::size_t count,
                                       std::size_t first_start, const SeqSlamConfig& config);

// Steps 2-4 end to end on preprocessed images, single thread.
class SeqSlam {
 public:
  explicit SeqSlam(const SeqSlamConfig& config);  // validates

  const SeqSlamConfig& config() const { return config_; }
  std::vector<std::uint8_t> preprocess(const cv::Mat& image) const;

  // One match per query frame (query.size() entries, in order).
  std::vector<SeqSlamMatch> run(const SeqSlamImages& reference, const SeqSlamImages& query) const;
  // Single-sequence loop closure: reference = query = `images` (use exclusion "past" or "band").
  std::vector<SeqSlamMatch> run(const SeqSlamImages& images) const { return run(images, images); }

 private:
  SeqSlamConfig config_;
};

}  // namespace loopgate
