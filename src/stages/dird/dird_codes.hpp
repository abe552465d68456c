// Compact codes of standardised DIRD descriptors (docs/detection.md § Compact codes): the int8 codes of
// dird_standardize.hpp reduced to one or two bits per dimension and compared by popcount.
//
// - sign: bit k = 1 when dimension k's z-score is positive (int8 code > 0). The distance is the Hamming
//   distance h over the 3456 dimensions as 2 h / 3456, which is 1 - cos of the +-1 vectors: the same scale as
//   the cosine distance of the int8 codes. 432 bytes per frame instead of 3456.
// - ternary: a "plus" bit where z >= +t and a "minus" bit where z <= -t (t = ternary_threshold_sigma), zero
//   in between. The dot product of two codes is popcount(plus_a & plus_b | minus_a & minus_b) -
//   popcount(plus_a & minus_b | minus_a & plus_b); the distance is 1 - dot / sqrt(nonzero_a * nonzero_b).
//   864 bytes per frame.
//
// Layout: a code is kCodePlaneWords 64-bit words per plane (3456 bits padded to 3584 with zeros so that an
// AVX2 loop needs no tail); sign codes have one plane, ternary codes two (plus, then minus). Distances are
// integer popcounts, so the AVX2 kernel (nibble-table popcount: pshufb on the low and high nibbles, summed
// with psadbw) and the portable kernel (std::popcount) give the same integers, and the same double after.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>

#include "core/enum_names.hpp"
#include "stages/dird/dird_extractor.hpp"

namespace loopgate {

// The representation a standardised descriptor is matched in.
enum class DirdCode { kInt8, kSign, kTernary };
inline constexpr EnumName<DirdCode> kDirdCodeNames[] = {
    {DirdCode::kInt8, "int8"}, {DirdCode::kSign, "sign"}, {DirdCode::kTernary, "ternary"}};
constexpr std::span<const EnumName<DirdCode>> enum_names(DirdCode) {
  return kDirdCodeNames;
}

// Configuration of the code (fields of section dird_seqslam).
struct DirdCodeConfig {
  // int8: cosine of the int8 codes (3456 bytes per frame, the raw descriptor kept as well); sign or ternary:
  // the compact codes above, the raw descriptor dropped once the frame is coded.
  DirdCode code = DirdCode::kInt8;
  double ternary_threshold_sigma = 0.5;  // ternary: |z| below this is coded 0, in standard deviations

  template <class Self, class V>
  static void fields(Self& self, V&& v) {
    v("code", self.code);
    v("ternary_threshold_sigma", self.ternary_threshold_sigma);
  }
  // Throws ConfigError naming "dird_seqslam.ternary_threshold_sigma": in (0, 4].
  void validate() const;
  bool compact() const { return code != DirdCode::kInt8; }
};

constexpr std::size_t kCodePlaneWords = 56;  // 3584 bits >= kDirdBytes, a multiple of 256 bits
static_assert(kCodePlaneWords * 64 >= kDirdBytes && (kCodePlaneWords * 64) % 256 == 0);

// Words of one code of `code` (sign: one plane, ternary: two); 0 for int8.
std::size_t code_words(DirdCode code);

// The compact code of int8 codes `standard` (stored offset by 128, dird_standardize.hpp) standardised with
// clamp_sigma; writes code_words() words to `out` (padding zero). Returns the number of nonzero dimensions
// (sign: kDirdBytes).
std::int32_t make_compact_code(const DirdCodeConfig& config, double clamp_sigma, const Descriptor& standard,
                               std::uint64_t* out);

// Popcount kernels on `words` words (a multiple of 4). Portable and AVX2 give the same integers;
// the plain names dispatch to AVX2 when the CPU has it.
std::int32_t hamming_words(const std::uint64_t* a, const std::uint64_t* b, std::size_t words);
std::int32_t hamming_words_portable(const std::uint64_t* a, const std::uint64_t* b, std::size_t words);
// Ternary dot product of two codes of 2 x plane_words words (plus plane, then minus plane).
std::int32_t ternary_dot(const std::uint64_t* a, const std::uint64_t* b, std::size_t plane_words);
std::int32_t ternary_dot_portable(const std::uint64_t* a, const std::uint64_t* b, std::size_t plane_words);
// Whether the AVX2 kernels are used on this CPU.
bool compact_codes_use_avx2();

// Distances on the scale of the int8 cosine distance (0 = the same, 1 = unrelated).
double sign_code_distance(const std::uint64_t* a, const std::uint64_t* b);
double ternary_code_distance(const std::uint64_t* a, std::int32_t nonzero_a, const std::uint64_t* b,
                             std::int32_t nonzero_b);

// Compact codes of one run, by sequence number: a contiguous matrix (capacity x code_words words),
// allocated uninitialised so memory is committed only as frames are coded, and each code's nonzero count.
// One writer (set) and readers of codes already set; not synchronised itself.
class CompactCodeMatrix {
 public:
  CompactCodeMatrix(const DirdCodeConfig& config, double clamp_sigma, std::size_t capacity);

  // Codes frame `seq` from its int8 codes.
  void set(std::size_t seq, const Descriptor& standard);
  double distance(std::size_t a, std::size_t b) const { return distance(a, *this, b); }
  // Frame a of this matrix against frame b of `other` (the same code; two-sequence runs).
  double distance(std::size_t a, const CompactCodeMatrix& other, std::size_t b) const;
  std::size_t bytes_per_code() const { return words_ * sizeof(std::uint64_t); }

 private:
  DirdCodeConfig config_;
  double clamp_sigma_;
  std::size_t capacity_, words_;
  std::unique_ptr<std::uint64_t[]> bits_;    // default-initialised: pages committed when written
  std::unique_ptr<std::int32_t[]> nonzero_;  // ternary only
};

}  // namespace loopgate
