#include "stages/seqslam/seqslam.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <stdexcept>
#include <string>

#include "core/stop_request.hpp"
#include "stages/seqslam/seqslam_preprocess.hpp"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace loopgate {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
// Difference-matrix tiling: a tile of reference and query images stays in L2 while its SADs are taken.
constexpr std::size_t kTileReferences = 64;
constexpr std::size_t kTileQueries = 32;
constexpr std::size_t kQueriesPerPass = 4;  // queries compared with one reference per pass (one load of it)
constexpr std::size_t kSimdBytes = 16;

#if defined(__SSE2__)
__m128i load16(const std::uint8_t* p) {
  return _mm_loadu_si128(reinterpret_cast<const __m128i*>(p));
}
std::uint32_t horizontal_sum(__m128i v) {
  return static_cast<std::uint32_t>(_mm_cvtsi128_si32(v)) +
         static_cast<std::uint32_t>(_mm_cvtsi128_si32(_mm_srli_si128(v, 8)));
}
#endif

std::uint32_t scalar_sad(const std::uint8_t* a, const std::uint8_t* b, std::size_t begin, std::size_t n) {
  std::uint32_t total = 0;
  for (std::size_t i = begin; i < n; ++i)
    total += static_cast<std::uint32_t>(std::abs(int{a[i]} - int{b[i]}));
  return total;
}

// SADs of one reference image against four query images.
void sad_1x4(const std::uint8_t* r, const std::array<const std::uint8_t*, kQueriesPerPass>& q, std::size_t n,
             std::array<std::uint32_t, kQueriesPerPass>& out) {
  std::size_t i = 0;
#if defined(__SSE2__)
  __m128i acc0 = _mm_setzero_si128(), acc1 = _mm_setzero_si128();
  __m128i acc2 = _mm_setzero_si128(), acc3 = _mm_setzero_si128();
  for (; i + kSimdBytes <= n; i += kSimdBytes) {
    const __m128i vr = load16(r + i);
    acc0 = _mm_add_epi64(acc0, _mm_sad_epu8(vr, load16(q[0] + i)));
    acc1 = _mm_add_epi64(acc1, _mm_sad_epu8(vr, load16(q[1] + i)));
    acc2 = _mm_add_epi64(acc2, _mm_sad_epu8(vr, load16(q[2] + i)));
    acc3 = _mm_add_epi64(acc3, _mm_sad_epu8(vr, load16(q[3] + i)));
  }
  out = {horizontal_sum(acc0), horizontal_sum(acc1), horizontal_sum(acc2), horizontal_sum(acc3)};
#else
  out = {0, 0, 0, 0};
#endif
  for (std::size_t k = 0; k < kQueriesPerPass; ++k) out[k] += scalar_sad(r, q[k], i, n);
}

}  // namespace

void SeqSlamImages::add(const std::vector<std::uint8_t>& image) {
  if (pixel_count_ == 0) pixel_count_ = image.size();
  if (image.size() != pixel_count_ || image.empty()) {
    throw std::invalid_argument("SeqSlamImages: image of " + std::to_string(image.size()) +
                                " pixels, expected " + std::to_string(pixel_count_));
  }
  bytes_.insert(bytes_.end(), image.begin(), image.end());
}

void SeqSlamImages::add(const cv::Mat& grey) {
  if (grey.type() != CV_8UC1) throw std::invalid_argument("SeqSlamImages: expected an 8-bit grey image");
  std::vector<std::uint8_t> bytes;
  bytes.reserve(grey.total());
  for (int y = 0; y < grey.rows; ++y)
    bytes.insert(bytes.end(), grey.ptr<std::uint8_t>(y), grey.ptr<std::uint8_t>(y) + grey.cols);
  add(bytes);
}

std::uint32_t seqslam_sad(const std::uint8_t* a, const std::uint8_t* b, std::size_t n) {
  std::size_t i = 0;
  std::uint32_t total = 0;
#if defined(__SSE2__)
  __m128i acc = _mm_setzero_si128();
  for (; i + kSimdBytes <= n; i += kSimdBytes)
    acc = _mm_add_epi64(acc, _mm_sad_epu8(load16(a + i), load16(b + i)));
  total = horizontal_sum(acc);
#endif
  return total + scalar_sad(a, b, i, n);
}

std::size_t seqslam_difference_block(const SeqSlamImages& reference, const SeqSlamImages& query,
                                     const SeqSlamExclusion& exclusion, std::size_t r_begin,
                                     std::size_t r_end, std::size_t q_begin, std::size_t q_end,
                                     SeqSlamMatrix& D) {
  if (reference.pixel_count() != query.pixel_count()) {
    throw std::invalid_argument("SeqSLAM: reference and query images differ in size");
  }
  if (r_end > D.reference_count() || q_end > D.query_count() || r_end > reference.size() ||
      q_end > query.size()) {
    throw std::out_of_range("seqslam_difference_block: block outside the matrix");
  }
  const std::size_t n = reference.pixel_count();
  const double pixels = static_cast<double>(n);
  std::size_t computed = 0;
  std::array<const std::uint8_t*, kQueriesPerPass> q_images{};
  std::array<std::uint32_t, kQueriesPerPass> sads{};
  for (std::size_t qt = q_begin; qt < q_end; qt += kTileQueries) {
    stop_request::check_abort("SeqSLAM difference matrix");  // O(n^2): a second stop signal aborts it
    const std::size_t qt_end = std::min(q_end, qt + kTileQueries);
    for (std::size_t rt = r_begin; rt < r_end; rt += kTileReferences) {
      const std::size_t rt_end = std::min(r_end, rt + kTileReferences);
      for (std::size_t r = rt; r < rt_end; ++r) {
        const std::uint8_t* r_image = reference.image(r);
        std::size_t q = qt;
        for (; q + kQueriesPerPass <= qt_end; q += kQueriesPerPass) {
          bool any = false;
          for (std::size_t k = 0; k < kQueriesPerPass; ++k) any = any || !exclusion.excluded(r, q + k);
          if (!any) {
            for (std::size_t k = 0; k < kQueriesPerPass; ++k) D.at(r, q + k) = kInf;
            continue;
          }
          for (std::size_t k = 0; k < kQueriesPerPass; ++k) q_images[k] = query.image(q + k);
          sad_1x4(r_image, q_images, n, sads);
          for (std::size_t k = 0; k < kQueriesPerPass; ++k) {
            const bool excluded = exclusion.excluded(r, q + k);
            D.at(r, q + k) = excluded ? kInf : static_cast<double>(sads[k]) / pixels;
            computed += excluded ? 0 : 1;
          }
        }
        for (; q < qt_end; ++q) {
          const bool excluded = exclusion.excluded(r, q);
          D.at(r, q) =
              excluded ? kInf : static_cast<double>(seqslam_sad(r_image, query.image(q), n)) / pixels;
          computed += excluded ? 0 : 1;
        }
      }
    }
  }
  return computed;
}

double seqslam_enhanced_entry(const double* d, std::size_t first, std::size_t reference_count,
                              int window_rows, std::size_t r) {
  const double value = d[r - first];
  if (!std::isfinite(value)) return kInf;
  const auto half = static_cast<std::size_t>(window_rows / 2);
  const std::size_t a = r >= half ? r - half : 0;
  const std::size_t b = std::min(reference_count - 1, r + half);
  double sum = 0.0;
  std::size_t count = 0;
  for (std::size_t k = a; k <= b; ++k) {
    if (std::isfinite(d[k - first])) {
      sum += d[k - first];
      ++count;
    }
  }
  const double mean = sum / static_cast<double>(count);
  double ss = 0.0;
  for (std::size_t k = a; k <= b; ++k) {
    if (std::isfinite(d[k - first])) ss += (d[k - first] - mean) * (d[k - first] - mean);
  }
  const double sd = count > 1 ? std::sqrt(ss / static_cast<double>(count - 1)) : 0.0;
  return sd == 0.0 ? 0.0 : (value - mean) / sd;
}

double seqslam_enhance_contrast(SeqSlamMatrix& M, int window_rows, std::size_t q_begin, std::size_t q_end) {
  const std::size_t n = M.reference_count();
  std::vector<double> original(n);
  double minimum = kInf;
  for (std::size_t q = q_begin; q < q_end; ++q) {
    double* col = M.column(q);
    std::copy(col, col + n, original.begin());
    for (std::size_t r = 0; r < n; ++r) {
      col[r] = seqslam_enhanced_entry(original.data(), 0, n, window_rows, r);
      if (std::isfinite(col[r])) minimum = std::min(minimum, col[r]);
    }
  }
  return minimum;
}

void seqslam_subtract(SeqSlamMatrix& M, double value, std::size_t q_begin, std::size_t q_end) {
  const std::size_t n = M.reference_count();
  for (std::size_t q = q_begin; q < q_end; ++q) {
    double* col = M.column(q);
    for (std::size_t r = 0; r < n; ++r) col[r] -= value;  // +inf stays +inf
  }
}

std::vector<double> seqslam_sequence_scores(const SeqSlamMatrix& E, std::size_t query,
                                            const SeqSlamConfig& config) {
  const std::size_t n = E.reference_count();
  const auto ds = static_cast<std::size_t>(config.sequence_length_frames);
  const std::size_t half = ds / 2;
  std::vector<double> scores(n, kInf);
  if (query < half || query + half >= E.query_count()) return scores;
  std::vector<double> acc(n);
  for (const int move : config.moves()) {
    std::fill(acc.begin(), acc.end(), 0.0);
    for (std::size_t t = 0; t <= ds; ++t) {
      const std::size_t offset = t * static_cast<std::size_t>(move) / ds;  // floor(t * move / ds)
      const double* col = E.column(query - half + t);
      const std::size_t inside = n > offset ? n - offset : 0;  // start rows whose row stays in range
      for (std::size_t s = 0; s < inside; ++s) acc[s] += col[s + offset];
      for (std::size_t s = inside; s < n; ++s) acc[s] = kInf;  // beyond the last reference row
    }
    for (std::size_t s = 0; s < n; ++s) scores[s] = std::min(scores[s], acc[s]);
  }
  return scores;
}

SeqSlamMatch seqslam_match_from_scores(std::size_t query, const double* scores, std::size_t count,
                                       std::size_t first_start, const SeqSlamConfig& config) {
  SeqSlamMatch match;
  match.query = query;
  if (count == 0) return match;
  const double* best_it = std::min_element(scores, scores + count);  // first on ties
  if (!std::isfinite(*best_it)) return match;
  const std::size_t best = first_start + static_cast<std::size_t>(best_it - scores);
  const auto half_window = static_cast<std::size_t>(config.second_best_window_rows / 2);
  const std::size_t lo = best >= half_window ? best - half_window : 0;
  const std::size_t hi = best + half_window;
  double second = kInf;
  for (std::size_t k = 0; k < count; ++k) {
    const std::size_t s = first_start + k;
    if (s < lo || s > hi) second = std::min(second, scores[k]);
  }
  match.has_match = true;
  match.reference = best + static_cast<std::size_t>(config.sequence_length_frames / 2);
  match.best_score = *best_it;
  match.second_score = second;
  if (!std::isfinite(second)) {
    match.ratio = kInf;
  } else if (second == 0.0) {
    match.ratio = 1.0;
  } else {
    match.ratio = match.best_score / second;
  }
  match.accepted = match.ratio <= config.ratio_threshold;
  return match;
}

SeqSlamMatch seqslam_match_query(const SeqSlamMatrix& E, std::size_t query, const SeqSlamConfig& config) {
  stop_request::check_abort("SeqSLAM sequence search");
  const std::vector<double> scores = seqslam_sequence_scores(E, query, config);
  return seqslam_match_from_scores(query, scores.data(), scores.size(), 0, config);
}

SeqSlam::SeqSlam(const SeqSlamConfig& config) : config_(config) {
  config_.validate();
}

std::vector<std::uint8_t> SeqSlam::preprocess(const cv::Mat& image) const {
  return seqslam_preprocess(image, config_);
}

std::vector<SeqSlamMatch> SeqSlam::run(const SeqSlamImages& reference, const SeqSlamImages& query) const {
  const std::size_t n = reference.size();
  const std::size_t m = query.size();
  std::vector<SeqSlamMatch> matches(m);
  for (std::size_t q = 0; q < m; ++q) matches[q].query = q;
  if (n == 0 || m == 0) return matches;
  SeqSlamMatrix M(n, m);
  seqslam_difference_block(reference, query, SeqSlamExclusion::from_config(config_), 0, n, 0, m, M);
  const double minimum = seqslam_enhance_contrast(M, config_.contrast_window_rows, 0, m);
  if (std::isfinite(minimum)) seqslam_subtract(M, minimum, 0, m);
  for (std::size_t q = 0; q < m; ++q) matches[q] = seqslam_match_query(M, q, config_);
  return matches;
}

}  // namespace loopgate
