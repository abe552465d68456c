// Descriptor standardisation (Schubert, Neubert, Protzel, ICRA 2020): every one of the 3456 dimensions of a
// DIRD descriptor minus its mean, divided by its standard deviation, the statistics taken over descriptors
// of the same sequence / condition. Standardised descriptors are then compared by L1 or by cosine.
//
// Representation (the hot path): z-scores clamped to +-clamp_sigma and quantised to signed 8-bit codes
// c = round(127 * z / clamp_sigma) in -127..127, STORED OFFSET BY 128 in a `Descriptor` (byte = c + 128, in
// 1..255; 128 is z = 0). The byte difference of two codes is the code difference, so every L1 kernel of
// dird_similarity.hpp (l1_distance, DirdSimilarity::sparse_columns, SSE2/AVX2 psadbw) applies unchanged to
// standardised descriptors; only the logistic's mu/sigma change (standard_default_scale() or OnlineScale).
// Cosine uses the integer dot product of the signed codes (standard_dot()). A float form (unclamped z-scores)
// exists for measurements (bench/bench_dird_standardize.cpp, bench/bench_match_standardize_experiment.cpp);
// the int8 codes lose nothing measurable against it and take a quarter of the memory.
//
// Statistics (exact integer sums of bytes and squared bytes per dimension, so batch statistics do not depend
// on the order of the descriptors, and every result is bit-identical across builds):
// - batch: standardization_of(all descriptors of one sequence). Two-sequence mode: the reference and the
//   query each get their own.
// - causal (streaming, CausalStandardizer): statistics over the descriptors observed so far, in frame order,
//   optionally only the last `window` of them (illumination that changes continuously over a drive).
//
// The causal rule, in full:
//   Observations (frame f_m, descriptor) arrive with strictly increasing f_m. After observation m, when
//   m >= warm_up and (m - warm_up) is a multiple of refresh_every, a snapshot s_m of the statistics is kept
//   (the statistics of observations 1..m, or of the last `window` of them). Frame p, whenever it is
//   standardised and whether or not it was observed, uses the latest snapshot s_m with f_m <= p; when there
//   is none (p before the warm-up frame f_warm_up), the first snapshot s_warm_up.
// Consequences:
//   - A frame's codes are a function of its raw descriptor and of the observations of frames <= p (frames
//     <= f_warm_up during the warm-up): they do not depend on later frames nor on when, or in which order,
//     frames are standardised. A past frame described late (a gated run's reference column) gets the
//     statistics of its own time, which is what per-condition standardisation wants, and exactly the codes a
//     run that described it at its own time would have given it.
//   - Enforced: standardize(p) moves a horizon to p, and a later observe(f) needs f > horizon (otherwise a
//     frame already standardised could have changed). standardize() needs ready(): warm_up observations.
//   - Single-sequence mode with a safety margin >= the warm-up (margin 200, warm-up 50): the warm-up frames
//   are
//     only ever compared once the warm-up is over, so nothing is lost or delayed. Two-sequence streaming: the
//     first warm_up - 1 query frames wait for the warm-up.
//   - Gated runs: the statistics come from the frames observed (described at their own time), so gated and
//     full runs give the same codes only when they observe the same frames (e.g. every k-th frame is always
//     described for the statistics). Frames described late cannot be observed (frame order).
// Zero-variance dimensions: the standard deviation is floored at min_stddev (descriptor byte units; 1 byte
// is the quantum of DIRD bytes), so a dimension constant over the statistics gives code 0 for that constant
// and +-127/clamp_sigma per byte of difference otherwise (clamped), never a division by zero.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "core/enum_names.hpp"
#include "stages/dird/dird_extractor.hpp"

namespace loopgate {

// standardize.mode: "off" (raw bytes), "batch" (statistics of one whole sequence), "causal" (streaming).
enum class StandardizeMode { kOff, kBatch, kCausal };
inline constexpr EnumName<StandardizeMode> kStandardizeModeNames[] = {
    {StandardizeMode::kOff, "off"}, {StandardizeMode::kBatch, "batch"}, {StandardizeMode::kCausal, "causal"}};
constexpr std::span<const EnumName<StandardizeMode>> enum_names(StandardizeMode) {
  return kStandardizeModeNames;
}

// standardize.distance, on the codes: "cosine" (1 - cos of the codes) or "l1" (SAD, psadbw).
enum class StandardizeDistance { kCosine, kL1 };
inline constexpr EnumName<StandardizeDistance> kStandardizeDistanceNames[] = {
    {StandardizeDistance::kCosine, "cosine"}, {StandardizeDistance::kL1, "l1"}};
constexpr std::span<const EnumName<StandardizeDistance>> enum_names(StandardizeDistance) {
  return kStandardizeDistanceNames;
}

// Configuration section `standardize` (read by the integrator's config system through fields()). Defaults
// other than `mode` are the measured recommendation (docs/standardize.md): causal statistics over the last
// 100 observed frames, cosine on int8 codes; L1 on causally standardised codes is fragile (frames
// standardised with different statistics become hubs or outliers) and is kept for measurements.
struct StandardizeConfig {
  StandardizeMode mode = StandardizeMode::kOff;                 // off | batch | causal (StandardizeMode)
  StandardizeDistance distance = StandardizeDistance::kCosine;  // on the codes: cosine | l1
  double clamp_sigma = 4.0;         // z-scores clamped to +-clamp_sigma, mapped to codes +-127
  double min_stddev = 1.0;          // floor of every dimension's standard deviation, in descriptor bytes
  std::int64_t warm_up = 50;        // causal: observations before the statistics are used (>= 2)
  std::int64_t window = 100;        // causal: statistics of the last `window` observations; 0 = all of them
  std::int64_t refresh_every = 10;  // causal: a snapshot every N observations (all kept: 27.6 KB each for
                                    // int8 codes, the compact codes' cuts 3.5-10.4 KB)
  // causal, single sequence: the frames observed for the statistics are those with seq % observe_every == 0
  // (full and gated runs alike, so both give every frame the same codes); a gated run describes them at
  // their own time even outside the candidate areas. warm_up, window and refresh_every are then spans of
  // frames (observations_config() divides them by observe_every): the window covers the same stretch of
  // the drive whatever the stride (measured: the span matters, docs/standardize.md).
  std::int64_t observe_every = 2;

  template <class Self, class V>
  static void fields(Self& self, V&& v) {
    v("mode", self.mode);
    v("distance", self.distance);
    v("clamp_sigma", self.clamp_sigma);
    v("min_stddev", self.min_stddev);
    v("warm_up", self.warm_up);
    v("window", self.window);
    v("refresh_every", self.refresh_every);
    v("observe_every", self.observe_every);
  }
  // Throws ConfigError naming "standardize.<key>": clamp_sigma in [0.5, 127], min_stddev > 0, warm_up >= 2,
  // window == 0 or window >= warm_up, refresh_every >= 1, observe_every >= 1.
  void validate() const;

  bool enabled() const { return mode != StandardizeMode::kOff; }
  bool cosine() const { return distance == StandardizeDistance::kCosine; }
};

// The configuration in observations for a CausalStandardizer fed every observe_every-th frame: warm_up,
// window and refresh_every divided by observe_every (rounded up; warm_up at least 2, window 0 stays 0).
StandardizeConfig observations_config(const StandardizeConfig& config);

// Unclamped float z-scores of one descriptor (measurement path).
using StandardizedFloat = std::array<float, kDirdBytes>;

constexpr int kStandardCodeMax = 127;            // codes are -127..127
constexpr std::uint8_t kStandardCodeZero = 128;  // stored byte of code 0

// Per-dimension sums over raw descriptors: count, sum of bytes and of squared bytes (exact integers).
// With window > 0 only the last `window` added descriptors count (the others are subtracted again; the
// window's descriptors are kept, window x 3456 bytes).
class DescriptorMoments {
 public:
  explicit DescriptorMoments(std::int64_t window = 0);

  void add(const Descriptor& raw);
  // Descriptors currently counted (min(added, window) with a window).
  std::int64_t count() const { return count_; }
  std::int64_t added() const { return added_; }
  // Mean and population variance (sum of squared deviations / count) of dimension `dim`; 0 when empty.
  double mean(std::size_t dim) const;
  double variance(std::size_t dim) const;

 private:
  std::int64_t window_ = 0;
  std::int64_t count_ = 0;
  std::int64_t added_ = 0;
  std::vector<std::uint64_t> sum_;
  std::vector<std::uint64_t> sum_squares_;
  std::vector<Descriptor> ring_;  // the window (empty without one)
};

// Immutable per-dimension map raw byte -> z = (byte - mean) / max(stddev, min_stddev), with its codes.
// Cheap to share (copies share the tables).
class Standardization {
 public:
  Standardization() = default;  // empty(): apply(), mean(), stddev() throw std::logic_error
  // The statistics of `moments` (count >= 1) with the floor and clamp of `config`.
  Standardization(const DescriptorMoments& moments, const StandardizeConfig& config);

  bool empty() const { return table_ == nullptr; }
  // Codes stored offset by 128 (see the top of this file).
  void apply(const Descriptor& raw, Descriptor& codes) const;
  Descriptor apply(const Descriptor& raw) const;
  // The code byte of one dimension (scalar reference of apply(): the same bits).
  std::uint8_t apply_one(std::size_t dim, std::uint8_t raw) const;
  // Unclamped z-scores.
  void apply_float(const Descriptor& raw, StandardizedFloat& z) const;

  std::int64_t count() const;  // descriptors the statistics came from
  float mean(std::size_t dim) const;
  double stddev(std::size_t dim) const;  // after the min_stddev floor (from the stored scale)
  double clamp_sigma() const;

 private:
  // 2 x 3456 floats (27.6 KB): the z-score scale of apply_float() and stddev() derive from code_scale.
  struct Table {
    std::vector<float> mean;
    std::vector<float> code_scale;  // 127 / (clamp_sigma * stddev)
    std::int64_t count = 0;
    double clamp_sigma = 0.0;
  };
  std::shared_ptr<const Table> table_;
};

// Batch statistics of one sequence (or condition). Throws std::invalid_argument for an empty set.
Standardization standardization_of(std::span<const Descriptor> descriptors, const StandardizeConfig& config);
// standardization_of(descriptors) applied to each of them.
std::vector<Descriptor> standardize_batch(std::span<const Descriptor> descriptors,
                                          const StandardizeConfig& config);

// The bookkeeping of the causal rule (top of this file), whatever a snapshot holds: which observation
// completes a snapshot, which snapshot a frame is standardised with, and the order checks.
class CausalSchedule {
 public:
  explicit CausalSchedule(const StandardizeConfig& config);

  // Frame `frame` observed as observation number `observations` (1-based). Returns whether it completes a
  // snapshot (the caller keeps one). Throws std::invalid_argument unless frame > every frame observed or
  // standardised before.
  bool observe(std::int64_t frame, std::int64_t observations);
  bool ready() const { return !frames_.empty(); }
  // Index of the snapshot frame p is standardised with (not moving the horizon); throws std::logic_error
  // naming the observations made when !ready().
  std::size_t snapshot_for(std::int64_t frame, std::int64_t observations) const;
  // snapshot_for(), and the horizon moved to p.
  std::size_t standardize(std::int64_t frame, std::int64_t observations);
  std::size_t snapshots() const { return frames_.size(); }

 private:
  std::int64_t warm_up_, refresh_every_;
  std::vector<std::int64_t> frames_;  // frame that completed each snapshot, ascending
  std::int64_t last_observed_, horizon_;
};

// Streaming, causal statistics of one sequence (the rule at the top of this file). Not thread-safe: one
// serial owner (e.g. the pipeline's serial match node); the Standardization it hands out is immutable.
class CausalStandardizer {
 public:
  explicit CausalStandardizer(const StandardizeConfig& config);

  // Adds frame's raw descriptor to the statistics. Throws std::invalid_argument unless frame > every frame
  // observed or standardised before.
  void observe(std::int64_t frame, const Descriptor& raw);
  // warm_up observations made: standardize() may be called.
  bool ready() const { return schedule_.ready(); }
  // The statistics frame p is standardised with; throws std::logic_error when !ready().
  const Standardization& statistics_for(std::int64_t frame) const;
  // Codes of frame p (statistics_for(p)); moves the horizon to p. Throws std::logic_error when !ready().
  void standardize(std::int64_t frame, const Descriptor& raw, Descriptor& codes);
  Descriptor standardize(std::int64_t frame, const Descriptor& raw);

  std::int64_t observations() const { return moments_.added(); }
  std::size_t snapshots() const { return snapshots_.size(); }
  const StandardizeConfig& config() const { return config_; }

 private:
  StandardizeConfig config_;
  CausalSchedule schedule_;
  DescriptorMoments moments_;
  std::vector<Standardization> snapshots_;  // in the schedule's order
};

// Distances on codes. L1: l1_distance() of dird_similarity.hpp on the coded Descriptors (SAD).
// Dot product of the signed codes, sum over dims of (a - 128) * (b - 128) (|result| <= 3456 * 127^2).
std::int32_t standard_dot(const Descriptor& a, const Descriptor& b);
// Euclidean norm of the signed codes.
double standard_norm(const Descriptor& a);
// 1 - cos(a, b) of the signed codes, in [0, 2]; 1 when either is all zero (orthogonal by definition).
// The overload takes the two norms precomputed with standard_norm().
double standard_cosine_distance(const Descriptor& a, const Descriptor& b);
double standard_cosine_distance(const Descriptor& a, double norm_a, const Descriptor& b, double norm_b);

// Mean absolute z-score difference per dimension that one unit of SAD between codes stands for:
// clamp_sigma / (127 * 3456). Multiply a code SAD by it for a clamp-independent distance.
double standard_l1_unit(double clamp_sigma);

// Float z-scores: sum of |a - b| and dot product (SIMD, fixed summation order: deterministic), 1 - cos.
float float_l1_distance(const StandardizedFloat& a, const StandardizedFloat& b);
float float_dot(const StandardizedFloat& a, const StandardizedFloat& b);
double float_cosine_distance(const StandardizedFloat& a, const StandardizedFloat& b);

}  // namespace loopgate
