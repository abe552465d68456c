#include "pipeline/methods/seqslam_batch.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <string>

#include "parallel/parallel_handoff.hpp"

namespace loopgate {

namespace {
constexpr std::size_t kQueryBlock = 64;  // query columns per parallel task
}

SeqSlamBatch::SeqSlamBatch(const SeqSlamConfig& config, std::size_t capacity)
    : seqslam_(config),
      capacity_(capacity),
      pixel_count_(static_cast<std::size_t>(config.image_width_px) *
                   static_cast<std::size_t>(config.image_height_px)),
      bytes_(new std::uint8_t[capacity * pixel_count_]) {}

void SeqSlamBatch::add(std::size_t seq, const cv::Mat& image) {
  if (seq >= capacity_)
    throw std::out_of_range("SeqSlamBatch: seq " + std::to_string(seq) + " beyond capacity");
  const std::vector<std::uint8_t> pixels = seqslam_.preprocess(image);
  if (pixels.size() != pixel_count_) {
    throw std::invalid_argument("SeqSLAM preprocessing gave " + std::to_string(pixels.size()) +
                                " pixels, expected " + std::to_string(pixel_count_));
  }
  std::memcpy(bytes_.get() + seq * pixel_count_, pixels.data(), pixel_count_);
}

void SeqSlamBatch::add_missing(std::size_t seq) {
  if (seq >= capacity_)
    throw std::out_of_range("SeqSlamBatch: seq " + std::to_string(seq) + " beyond capacity");
  std::memset(bytes_.get() + seq * pixel_count_, 0, pixel_count_);
}

std::vector<SeqSlamMatch> SeqSlamBatch::run(std::size_t count, std::size_t* differences_computed) const {
  if (count > capacity_)
    throw std::out_of_range("SeqSlamBatch: " + std::to_string(count) + " frames beyond capacity");
  const SeqSlamImages all = images(0, count);
  return search(all, all, differences_computed);
}

std::vector<SeqSlamMatch> SeqSlamBatch::run_two_sequence(std::size_t reference_count,
                                                         std::size_t query_count) const {
  if (reference_count + query_count > capacity_) {
    throw std::out_of_range("SeqSlamBatch: " + std::to_string(reference_count) + " + " +
                            std::to_string(query_count) + " frames beyond capacity");
  }
  return search(images(0, reference_count), images(reference_count, query_count));
}

SeqSlamImages SeqSlamBatch::images(std::size_t first, std::size_t count) const {
  SeqSlamImages out(pixel_count_);
  out.reserve(count);
  std::vector<std::uint8_t> one(pixel_count_);
  for (std::size_t k = first; k < first + count; ++k) {
    std::memcpy(one.data(), bytes_.get() + k * pixel_count_, pixel_count_);
    out.add(one);
  }
  return out;
}

std::vector<SeqSlamMatch> SeqSlamBatch::search(const SeqSlamImages& reference, const SeqSlamImages& query,
                                               std::size_t* differences_computed) const {
  const std::size_t rows = reference.size();
  const std::size_t count = query.size();
  std::vector<SeqSlamMatch> matches(count);
  for (std::size_t q = 0; q < count; ++q) matches[q].query = q;
  if (differences_computed) *differences_computed = 0;
  if (count == 0 || rows == 0) return matches;
  const SeqSlamConfig& config = seqslam_.config();
  const SeqSlamExclusion exclusion = SeqSlamExclusion::from_config(config);
  SeqSlamMatrix M(rows, count);
  const std::size_t blocks = (count + kQueryBlock - 1) / kQueryBlock;
  const auto block_range = [&](std::size_t b) {
    return std::pair{b * kQueryBlock, std::min(count, (b + 1) * kQueryBlock)};
  };
  // Step 2 and step 3 (per column) in parallel blocks of query columns, each block's minimum kept; then the
  // global minimum is subtracted, then step 4 per query column. parallel_for_with_handoff makes the
  // hand-overs visible to ThreadSanitizer.
  std::vector<double> block_minimum(blocks, std::numeric_limits<double>::infinity());
  std::vector<std::size_t> block_differences(blocks, 0);
  parallel_for_with_handoff(blocks, [&](std::size_t b) {
    const auto [q0, q1] = block_range(b);
    block_differences[b] = seqslam_difference_block(reference, query, exclusion, 0, rows, q0, q1, M);
    block_minimum[b] = seqslam_enhance_contrast(M, config.contrast_window_rows, q0, q1);
  });
  if (differences_computed) {
    for (const std::size_t d : block_differences) *differences_computed += d;
  }
  const double minimum = *std::min_element(block_minimum.begin(), block_minimum.end());
  if (std::isfinite(minimum)) {
    parallel_for_with_handoff(blocks, [&](std::size_t b) {
      const auto [q0, q1] = block_range(b);
      seqslam_subtract(M, minimum, q0, q1);
    });
  }
  parallel_for_with_handoff(count, [&](std::size_t q) { matches[q] = seqslam_match_query(M, q, config); });
  return matches;
}

}  // namespace loopgate
