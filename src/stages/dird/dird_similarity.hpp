// DIRD distances and the logistic similarity (docs/detection.md § The paper's matcher).
//
// L1 (default, the reference): sum of absolute byte differences over the 3456 bytes, SSE2 psadbw
// (baseline x86-64; a plain loop elsewhere). L2: Euclidean norm of the byte differences.
// sim(d) = 1 / (1 + exp((d - mu) / sigma)); the sparse similarity matrix keeps sim > tau1 only.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "stages/dird/dird_config.hpp"
#include "stages/dird/dird_extractor.hpp"

namespace loopgate {

// Sum of |a_k - b_k| over the 3456 bytes (at most 3456 * 255).
std::uint32_t l1_distance(const Descriptor& a, const Descriptor& b);
// Sum of (a_k - b_k)^2 and its square root.
std::uint32_t l2_squared_distance(const Descriptor& a, const Descriptor& b);
double l2_distance(const Descriptor& a, const Descriptor& b);

// 1 / (1 + exp((distance - mu) / sigma)).
double logistic_similarity(double distance, double mu, double sigma);
// The distance at which the logistic equals `similarity` (0 < similarity < 1):
// mu + sigma * ln(1 / similarity - 1). sim(d) > similarity exactly when d < this value.
double logistic_distance_at(double similarity, double mu, double sigma);

// One stored entry S(j, i) of the sparse similarity matrix, seen from the current (column) frame i:
// j is the earlier frame (or the reference frame in two-sequence mode).
struct SimilarityEntry {
  std::int64_t j = 0;
  double similarity = 0.0;
};

// Metric + logistic + sparsity threshold of one DirdConfig. Immutable, safe to share between threads.
class DirdSimilarity {
 public:
  explicit DirdSimilarity(const DirdConfig& config = {});

  // Distance in the configured metric (L1 as an integer-valued double, or L2).
  double distance(const Descriptor& a, const Descriptor& b) const;
  double similarity_from_distance(double distance) const;
  double similarity(const Descriptor& a, const Descriptor& b) const;
  // True when the entry belongs to the sparse matrix (sim > tau1).
  bool keeps(double similarity) const { return similarity > config_.tau1; }

  // Appends to `out` the entries {j, sim} with sim > tau1 for j in [0, count), comparing `current`
  // with earlier[j]; j is offset by `j_offset` in the output. The logistic is evaluated only for
  // distances near or below the tau1 cut-off.
  void sparse_row(const Descriptor& current, const Descriptor* earlier, std::size_t count,
                  std::int64_t j_offset, std::vector<SimilarityEntry>& out) const;

  // Single-sequence sparse similarity columns for current frames i in [i_begin, i_end): column i holds
  // the entries for j in [0, i - margin] (nothing when i < margin). `columns` must have i_end - i_begin
  // elements; each is cleared first. Current frames are processed in groups that share each loaded
  // earlier descriptor (cache blocking); the result equals sparse_row() per column, in ascending j.
  void sparse_columns(std::span<const Descriptor> descriptors, std::int64_t margin, std::size_t i_begin,
                      std::size_t i_end, std::span<std::vector<SimilarityEntry>> columns) const;

  const DirdConfig& config() const { return config_; }
  // Largest distance that can still give sim > tau1 (prefilter bound, slightly generous).
  double cutoff_distance() const { return cutoff_distance_; }

 private:
  DirdConfig config_;
  bool l2_metric_ = false;
  double cutoff_distance_ = 0.0;
};

}  // namespace loopgate
