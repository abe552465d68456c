// Compact codes of standardised DIRD descriptors (docs/codes.md): the int8 codes of dird_standardize.hpp
// reduced to one or two bits per dimension and compared by popcount.
//
// - sign: bit k = 1 when dimension k's z-score is positive (int8 code > 0). The distance is the Hamming
//   distance h over the 3456 dimensions as 2 h / 3456, which is 1 - cos of the +-1 vectors: the same scale as
//   the cosine distance of the int8 codes. 432 bytes per frame instead of 3456.
// - ternary: a "plus" bit where z >= +t and a "minus" bit where z <= -t (t = ternary_threshold_sigma), zero
//   in between. The dot product of two codes is popcount(plus_a & plus_b | minus_a & minus_b) -
//   popcount(plus_a & minus_b | minus_a & plus_b); the distance is 1 - dot / sqrt(nonzero_a * nonzero_b).
//   864 bytes per frame.
// - int2: two bits, a sign bit (z > 0) and a magnitude bit (|z| >= t, t = int2_threshold_sigma): the values
//   -3, -1, +1, +3 (a four-level quantiser whose outer level is three times the inner one, close to the
//   Lloyd-Max levels of a Gaussian). With d = sign_a ^ sign_b and m the magnitude planes, the dot product is
//   n + 2 |m_a| + 2 |m_b| + 4 |m_a & m_b| - 2 (|d| + 2 |d & m_a| + 2 |d & m_b| + 4 |d & m_a & m_b|) and the
//   squared norm n + 8 |m|; the distance is 1 - cos. 864 bytes per frame.
//
// Layout: a code is kCodePlaneWords 64-bit words per plane (3456 bits padded to 3584 with zeros so that an
// AVX2 or AVX-512 loop needs no tail); sign codes have one plane, ternary codes two (plus, then minus), int2
// codes two (sign, then magnitude). Distances are integer popcounts, so the AVX-512 kernel (vpopcntq), the
// AVX2 kernel (nibble-table popcount: pshufb on the low and high nibbles, summed with psadbw) and the
// portable kernel (std::popcount) give the same integers, and the same double after.
//
// Coding from the raw descriptor (CausalCompactCoder): a code bit is a comparison of the raw byte with a cut
// per dimension, because the int8 code of a raw byte is monotonic in it. A causal snapshot of the
// statistics is then kept as these cuts (one to three bytes per dimension: 3.5-10.4 KB instead of the
// 27.6 KB of a Standardization), and the codes are bit-identical with those made from the int8 codes.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "core/enum_names.hpp"
#include "stages/dird/dird_cut_snapshots.hpp"
#include "stages/dird/dird_extractor.hpp"
#include "stages/dird/dird_standardize.hpp"

namespace loopgate {

// The representation a standardised descriptor is matched in.
enum class DirdCode { kInt8, kSign, kTernary, kInt2 };
inline constexpr EnumName<DirdCode> kDirdCodeNames[] = {{DirdCode::kInt8, "int8"},
                                                        {DirdCode::kSign, "sign"},
                                                        {DirdCode::kTernary, "ternary"},
                                                        {DirdCode::kInt2, "int2"}};
constexpr std::span<const EnumName<DirdCode>> enum_names(DirdCode) {
  return kDirdCodeNames;
}

// Configuration of the code (fields of section dird_seqslam).
struct DirdCodeConfig {
  // int8: cosine of the int8 codes (3456 bytes per frame, the raw descriptor kept as well); sign, ternary or
  // int2: the compact codes above, the raw descriptor dropped once the frame is coded.
  DirdCode code = DirdCode::kInt8;
  double ternary_threshold_sigma = 0.5;  // ternary: |z| below this is coded 0, in standard deviations
  double int2_threshold_sigma = 1.0;     // int2: |z| at least this is coded +-3, below it +-1

  template <class Self, class V>
  static void fields(Self& self, V&& v) {
    v("code", self.code);
    v("ternary_threshold_sigma", self.ternary_threshold_sigma);
    v("int2_threshold_sigma", self.int2_threshold_sigma);
  }
  // Throws ConfigError naming "dird_seqslam.ternary_threshold_sigma" / "int2_threshold_sigma": in (0, 4].
  void validate() const;
  bool compact() const { return code != DirdCode::kInt8; }
};

constexpr std::size_t kCodePlaneWords = 56;  // 3584 bits >= kDirdBytes, a multiple of 512 bits
static_assert(kCodePlaneWords * 64 >= kDirdBytes && (kCodePlaneWords * 64) % 512 == 0);

// Words of one code of `code` (sign: one plane, ternary and int2: two); 0 for int8.
std::size_t code_words(DirdCode code);

// The threshold of `sigma` standard deviations in int8 code units (at least 1) under clamp_sigma.
int code_threshold(double sigma, double clamp_sigma);

// The compact code of int8 codes `standard` (stored offset by 128, dird_standardize.hpp) standardised with
// clamp_sigma; writes code_words() words to `out` (padding zero). Returns the code's count: sign kDirdBytes,
// ternary the nonzero dimensions, int2 the magnitude bits.
std::int32_t make_compact_code(const DirdCodeConfig& config, double clamp_sigma, const Descriptor& standard,
                               std::uint64_t* out);

// ---- kernels

// The popcount kernels: portable (std::popcount), AVX2 (nibble table) and AVX-512 (vpopcntq).
enum class PopcountKernel { kPortable, kAvx2, kAvx512 };
inline constexpr EnumName<PopcountKernel> kPopcountKernelNames[] = {{PopcountKernel::kPortable, "portable"},
                                                                    {PopcountKernel::kAvx2, "avx2"},
                                                                    {PopcountKernel::kAvx512, "avx512"}};
constexpr std::span<const EnumName<PopcountKernel>> enum_names(PopcountKernel) {
  return kPopcountKernelNames;
}
// The fastest kernel this CPU runs (what the plain names below use), and whether `kernel` runs here.
PopcountKernel best_popcount_kernel();
bool popcount_kernel_available(PopcountKernel kernel);
bool compact_codes_use_avx2();  // best_popcount_kernel() is not the portable one

// On `words` words (a multiple of 4). The plain names dispatch to best_popcount_kernel(); every kernel gives
// the same integers. Throws std::invalid_argument for a kernel this CPU does not run.
std::int32_t hamming_words(const std::uint64_t* a, const std::uint64_t* b, std::size_t words);
std::int32_t hamming_words(const std::uint64_t* a, const std::uint64_t* b, std::size_t words,
                           PopcountKernel kernel);
std::int32_t hamming_words_portable(const std::uint64_t* a, const std::uint64_t* b, std::size_t words);
// Ternary dot product of two codes of 2 x plane_words words (plus plane, then minus plane).
std::int32_t ternary_dot(const std::uint64_t* a, const std::uint64_t* b, std::size_t plane_words);
std::int32_t ternary_dot(const std::uint64_t* a, const std::uint64_t* b, std::size_t plane_words,
                         PopcountKernel kernel);
std::int32_t ternary_dot_portable(const std::uint64_t* a, const std::uint64_t* b, std::size_t plane_words);
// The pair term of the int2 dot product of two codes of 2 x plane_words words (sign plane, then magnitude):
// 4 |m_a & m_b| - 2 |d| - 4 |d & m_a| - 4 |d & m_b| - 8 |d & m_a & m_b|; the dot product is this plus
// n + 2 |m_a| + 2 |m_b| (int2_code_distance).
std::int32_t int2_pair_term(const std::uint64_t* a, const std::uint64_t* b, std::size_t plane_words,
                            PopcountKernel kernel);

// Distances on the scale of the int8 cosine distance (0 = the same, 1 = unrelated).
double sign_code_distance(const std::uint64_t* a, const std::uint64_t* b);
double ternary_code_distance(const std::uint64_t* a, std::int32_t nonzero_a, const std::uint64_t* b,
                             std::int32_t nonzero_b);
double int2_code_distance(const std::uint64_t* a, std::int32_t magnitude_a, const std::uint64_t* b,
                          std::int32_t magnitude_b);

// ---- coding from the raw descriptor

// Cut bytes per dimension a code needs (sign 1, ternary 2, int2 3; 0 for int8), in this order:
//   sign:    above_zero                   (sign bit: raw > above_zero, i.e. code >= 1)
//   ternary: above_t, below_t             (plus: raw > above_t, i.e. code >= t; minus: raw < below_t)
//   int2:    above_zero, above_t, below_t (magnitude: raw > above_t or raw < below_t)
// Each cut is kDirdBytes bytes, one per dimension. above cuts of 255 and below cuts of 0 never fire.
std::size_t code_cuts(DirdCode code);
// The cuts of `statistics` for `config`: code_cuts(config.code) x kDirdBytes bytes into `out`, such that
// code_from_cuts(config.code, out, raw) == make_compact_code(config, clamp, statistics.apply(raw)) for
// every raw descriptor (found by a search on Standardization::apply itself, so the same float operations).
void make_code_cuts(const Standardization& statistics, const DirdCodeConfig& config, std::uint8_t* out);
// The code of `raw` from its cuts: code_words(code) words into `out`; returns the count of
// make_compact_code. AVX2 and portable paths give the same bits.
std::int32_t code_from_cuts(DirdCode code, const std::uint8_t* cuts, const Descriptor& raw,
                            std::uint64_t* out);
std::int32_t code_from_cuts(DirdCode code, const std::uint8_t* cuts, const Descriptor& raw,
                            std::uint64_t* out, PopcountKernel kernel);

// The causal standardisation of CausalStandardizer (dird_standardize.hpp, the same rule, observations and
// snapshots), for a compact code: each snapshot kept as its cuts, each frame coded from its raw descriptor
// and the cuts of its own time. Not thread-safe: one serial owner.
class CausalCompactCoder {
 public:
  // `observations` as CausalStandardizer takes it (observations_config()); `codes` a compact code.
  CausalCompactCoder(const StandardizeConfig& observations, const DirdCodeConfig& codes);

  // As CausalStandardizer::observe.
  void observe(std::int64_t frame, const Descriptor& raw);
  bool ready() const { return schedule_.ready(); }
  // Codes frame p into code_words() words of `out`; moves the horizon to p. Returns the count of
  // make_compact_code. Throws std::logic_error when !ready().
  std::int32_t code(std::int64_t frame, const Descriptor& raw, std::uint64_t* out);

  std::int64_t observations() const { return moments_.added(); }
  std::size_t snapshots() const { return schedule_.snapshots(); }
  // Bytes the snapshots take (the cuts, kept as differences: dird_cut_snapshots.hpp).
  std::size_t snapshot_bytes() const { return cuts_.bytes(); }

 private:
  StandardizeConfig config_;
  DirdCodeConfig codes_;
  CausalSchedule schedule_;
  DescriptorMoments moments_;
  std::vector<std::uint8_t> scratch_;  // the cuts of the snapshot being made
  CutSnapshots cuts_;
};

// Compact codes of one run, in the order frames are coded: row r of a contiguous matrix (rows x code_words
// words) is the r-th frame set, and a table gives each sequence number its row. A gated run codes only the
// frames its candidate areas reach, late and out of sequence order; by sequence number the pages of the
// frames never coded between coded ones were committed too. The matrix is allocated uninitialised for
// `capacity` rows and filled from the front, so memory is committed only for the frames coded: code_words x 8
// bytes each, plus 4 bytes of row table per sequence number (and 4 bytes of count per coded frame, ternary
// and int2). One writer (set) and readers of codes already set; not synchronised itself.
class CompactCodeMatrix {
 public:
  CompactCodeMatrix(const DirdCodeConfig& config, double clamp_sigma, std::size_t capacity);

  // Codes frame `seq` from its int8 codes (a frame set again keeps its row).
  void set(std::size_t seq, const Descriptor& standard);
  // Codes frame `seq` from its raw descriptor with `coder` (frame p = `frame`).
  void set(std::size_t seq, CausalCompactCoder& coder, std::int64_t frame, const Descriptor& raw);
  // Whether frame `seq` was set (false beyond the capacity).
  bool has(std::size_t seq) const { return seq < capacity_ && row_of_[seq] != kNoRow; }
  // Frames set so far (rows in use).
  std::size_t rows() const { return rows_; }
  // Both frames must have been set (std::logic_error otherwise).
  double distance(std::size_t a, std::size_t b) const { return distance(a, *this, b); }
  // Frame a of this matrix against frame b of `other` (the same code; two-sequence runs).
  double distance(std::size_t a, const CompactCodeMatrix& other, std::size_t b) const;
  // The distances of frame a to frames [j_begin, j_end) into out[0 .. j_end - j_begin), one pass over their
  // rows; frames whose `coded` byte is 0 are skipped (out left as it is), the others must have been set.
  void distances(std::size_t a, std::size_t j_begin, std::size_t j_end, const std::uint8_t* coded,
                 double* out) const;
  std::size_t bytes_per_code() const { return words_ * sizeof(std::uint64_t); }

 private:
  static constexpr std::uint32_t kNoRow = 0xffffffffu;
  // The row of frame seq, made when `create` (std::out_of_range beyond the capacity; std::logic_error for a
  // frame not set when !create).
  std::size_t row_index(std::size_t seq, bool create);
  std::size_t row_index(std::size_t seq) const;
  const std::uint64_t* code(std::size_t seq) const { return bits_.get() + row_index(seq) * words_; }
  void store_count(std::size_t row, std::int32_t count);

  DirdCodeConfig config_;
  double clamp_sigma_;
  std::size_t capacity_, words_, rows_ = 0;
  PopcountKernel kernel_;
  std::unique_ptr<std::uint64_t[]> bits_;    // by row; default-initialised: pages committed as rows fill
  std::unique_ptr<std::int32_t[]> count_;    // by row; ternary: nonzero dimensions; int2: magnitude bits
  std::unique_ptr<std::uint32_t[]> row_of_;  // by sequence number; kNoRow until set
};

}  // namespace loopgate
