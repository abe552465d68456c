#include "stages/match/contrast_search.hpp"

#include <spdlog/fmt/fmt.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "core/validate.hpp"

namespace loopgate {

namespace {

constexpr float kUndefined = std::numeric_limits<float>::quiet_NaN();

std::string str(double v) {
  return fmt::format("{}", v);
}

// Checks a row and returns it sorted by j.
std::vector<DistanceEntry> sorted_row(std::int64_t i, std::span<const DistanceEntry> row,
                                      ContrastSequenceSearch::Mode mode, int margin) {
  std::vector<DistanceEntry> sorted(row.begin(), row.end());
  const auto by_j = [](const DistanceEntry& a, const DistanceEntry& b) { return a.j < b.j; };
  if (!std::is_sorted(sorted.begin(), sorted.end(), by_j)) std::sort(sorted.begin(), sorted.end(), by_j);
  for (std::size_t k = 0; k < sorted.size(); ++k) {
    const DistanceEntry& e = sorted[k];
    if (e.j < 0) throw std::invalid_argument(fmt::format("contrast search row {}: reference {} < 0", i, e.j));
    if (!(std::isfinite(e.distance) && e.distance >= 0.0)) {
      throw std::invalid_argument(fmt::format(
          "contrast search row {}: distance {} to {} is not finite and >= 0", i, e.distance, e.j));
    }
    if (k > 0 && sorted[k - 1].j == e.j) {
      throw std::invalid_argument(fmt::format("contrast search row {}: reference {} twice", i, e.j));
    }
    if (mode == ContrastSequenceSearch::Mode::kSingleSequence && e.j > i - margin) {
      throw std::invalid_argument(
          fmt::format("contrast search row {}: reference {} within the margin of {} frames", i, e.j, margin));
    }
  }
  return sorted;
}

}  // namespace

void ContrastSearchConfig::validate() const {
  const std::string s = "dird_seqslam.";
  require(contrast_half_window_frames >= 1 && contrast_half_window_frames <= 1000,
          s + "contrast_half_window_frames", "in [1, 1000] frames", str(contrast_half_window_frames));
  require(contrast_min_cells >= 2 && contrast_min_cells <= 2 * contrast_half_window_frames + 1,
          s + "contrast_min_cells", "in [2, 2 * contrast_half_window_frames + 1]", str(contrast_min_cells));
  require(std::isfinite(velocity_min) && velocity_min > 0.0 && velocity_min <= 10.0, s + "velocity_min",
          "in (0, 10] reference frames per query frame", str(velocity_min));
  require(std::isfinite(velocity_max) && velocity_max >= velocity_min && velocity_max <= 10.0,
          s + "velocity_max", "in [velocity_min, 10] reference frames per query frame", str(velocity_max));
  require(velocity_steps >= 1 && velocity_steps <= 64, s + "velocity_steps", "in [1, 64]",
          str(velocity_steps));
  require(velocity_steps > 1 || velocity_min == velocity_max, s + "velocity_steps",
          "> 1 when velocity_min < velocity_max", str(velocity_steps));
  // A line's score is a mean of z values, each within +-sqrt(2 w) <= 45 (the window's population stddev).
  require_in(s + "min_score", min_score, -100.0, 100.0, "(a mean z, in local standard deviations)");
}

std::vector<double> ContrastSearchConfig::velocities() const {
  std::vector<double> out;
  if (velocity_steps <= 1 || velocity_min == velocity_max) return {velocity_min};
  const double ratio = std::log(velocity_max / velocity_min);
  for (int k = 0; k < velocity_steps; ++k) {
    out.push_back(velocity_min * std::exp(ratio * k / (velocity_steps - 1)));
  }
  out.back() = velocity_max;
  return out;
}

std::vector<float> contrast_enhance_row(std::span<const DistanceEntry> row, int half_window, int min_cells) {
  const std::size_t n = row.size();
  std::vector<float> z(n, kUndefined);
  if (n == 0) return z;
  // Prefix sums of the distances shifted by the first one (keeps the sums of squares small).
  const double shift = row[0].distance;
  std::vector<double> p1(n + 1, 0.0), p2(n + 1, 0.0);
  for (std::size_t k = 0; k < n; ++k) {
    const double x = row[k].distance - shift;
    p1[k + 1] = p1[k] + x;
    p2[k + 1] = p2[k] + x * x;
  }
  std::size_t lo = 0, hi = 0;  // window [lo, hi) of entries with |j' - j| <= w
  for (std::size_t k = 0; k < n; ++k) {
    const std::int64_t j = row[k].j;
    while (row[lo].j < j - half_window) ++lo;
    if (hi < k + 1) hi = k + 1;
    while (hi < n && row[hi].j <= j + half_window) ++hi;
    const auto count = static_cast<double>(hi - lo);
    if (hi - lo < static_cast<std::size_t>(min_cells)) continue;
    const double mean = (p1[hi] - p1[lo]) / count;
    const double variance = (p2[hi] - p2[lo]) / count - mean * mean;
    if (!(variance > 0.0)) continue;
    const double stddev = std::sqrt(variance);
    // Equal distances in floating point can leave a variance of rounding noise: treat a spread below
    // 1e-9 of the distances' magnitude as none.
    if (stddev <= 1e-9 * (std::abs(mean + shift) + 1.0)) continue;
    z[k] = static_cast<float>((mean - (row[k].distance - shift)) / stddev);
  }
  return z;
}

const float* ContrastSequenceSearch::ZRow::at(std::int64_t j) const {
  const std::int64_t k = j - j_lo;
  if (k < 0 || k >= static_cast<std::int64_t>(z.size()) || !defined[static_cast<std::size_t>(k)])
    return nullptr;
  return &z[static_cast<std::size_t>(k)];
}

ContrastSequenceSearch::ContrastSequenceSearch(const ContrastSearchConfig& config, int sequence_length,
                                               Mode mode, int margin, std::int64_t first_frame)
    : config_(config),
      sequence_length_(sequence_length),
      mode_(mode),
      margin_(mode == Mode::kSingleSequence ? margin : 0),
      next_frame_(first_frame) {
  config_.validate();
  if (sequence_length < 1) throw std::invalid_argument("contrast search: sequence length must be >= 1");
  if (margin < 0) throw std::invalid_argument("contrast search: margin must be >= 0");
  velocities_ = config_.velocities();
  for (const double v : velocities_) {
    std::vector<std::int64_t> off(static_cast<std::size_t>(sequence_length));
    for (int k = 0; k < sequence_length; ++k) off[static_cast<std::size_t>(k)] = std::llround(v * k);
    offsets_.push_back(std::move(off));
  }
}

const ContrastSequenceSearch::ZRow* ContrastSequenceSearch::row_at(std::int64_t i) const {
  if (rows_.empty() || i < rows_.front().i || i > rows_.back().i) return nullptr;
  return &rows_[static_cast<std::size_t>(i - rows_.front().i)];
}

void ContrastSequenceSearch::push(std::int64_t i, std::span<const DistanceEntry> row, ContrastOutput& out) {
  if (i != next_frame_) {
    throw std::invalid_argument(fmt::format("contrast search: row {} pushed, expected {}", i, next_frame_));
  }
  const std::vector<DistanceEntry> sorted = sorted_row(i, row, mode_, margin_);
  const std::vector<float> z =
      contrast_enhance_row(sorted, config_.contrast_half_window_frames, config_.contrast_min_cells);

  ZRow zrow;
  zrow.i = i;
  std::size_t defined = 0;
  if (!sorted.empty()) {
    zrow.j_lo = sorted.front().j;
    const auto width = static_cast<std::size_t>(sorted.back().j - sorted.front().j + 1);
    zrow.z.assign(width, 0.0f);
    zrow.defined.assign(width, 0);
    for (std::size_t k = 0; k < sorted.size(); ++k) {
      if (std::isnan(z[k])) continue;
      const auto at = static_cast<std::size_t>(sorted[k].j - zrow.j_lo);
      zrow.z[at] = z[k];
      zrow.defined[at] = 1;
      ++defined;
    }
  }
  rows_.push_back(std::move(zrow));
  if (rows_.size() > static_cast<std::size_t>(sequence_length_)) rows_.pop_front();
  ContrastVerdict verdict;
  verdict.i = i;
  verdict.cells = sorted.size();
  verdict.defined = defined;
  pending_.push_back(verdict);
  ++next_frame_;

  // Lines ending in row i: per velocity, the best one (sum over k of z(i - k, j - off[k])). The endpoints
  // are taken in blocks small enough for the block's line sums and the rows' stretches to stay in cache
  // across the L rows and the velocities; per endpoint the sum runs over k in the same order as without
  // blocks, and the endpoints in ascending order, so the results are the same.
  const ZRow& current = rows_.back();
  const auto width = static_cast<std::int64_t>(current.z.size());
  const auto L = static_cast<std::size_t>(sequence_length_);
  const std::size_t V = velocities_.size();
  constexpr std::int64_t kBlock = 2048;
  std::vector<std::int64_t> best_e_v(V, -1);
  std::vector<double> best_sum_v(V, -std::numeric_limits<double>::infinity());
  line_sum_.resize(static_cast<std::size_t>(std::min(width, kBlock)));
  for (std::int64_t b0 = 0; defined > 0 && b0 < width; b0 += kBlock) {
    const std::int64_t b1 = std::min(width, b0 + kBlock);
    for (std::size_t v = 0; v < V; ++v) {
      const std::vector<std::int64_t>& off = offsets_[v];
      std::fill(line_sum_.begin(), line_sum_.begin() + (b1 - b0), 0.0);
      for (std::size_t k = 0; k < L; ++k) {
        const ZRow* r = row_at(i - static_cast<std::int64_t>(k));
        if (r == nullptr || r->z.empty()) continue;
        // endpoints j = current.j_lo + e read r at j - off[k]: e in [e0, e1)
        const std::int64_t shift = current.j_lo - off[k] - r->j_lo;  // index into r of endpoint e = e + shift
        const std::int64_t e0 = std::max<std::int64_t>(b0, -shift);
        const std::int64_t e1 = std::min<std::int64_t>(b1, static_cast<std::int64_t>(r->z.size()) - shift);
        if (e0 >= e1) continue;
        const float* src = r->z.data() + (shift + e0);
        double* sum = line_sum_.data() + (e0 - b0);
        for (std::int64_t n = 0; n < e1 - e0; ++n) sum[n] += src[n];
      }
      for (std::int64_t e = b0; e < b1; ++e) {
        if (!current.defined[static_cast<std::size_t>(e)]) continue;
        if (line_sum_[static_cast<std::size_t>(e - b0)] > best_sum_v[v]) {
          best_sum_v[v] = line_sum_[static_cast<std::size_t>(e - b0)];
          best_e_v[v] = e;
        }
      }
    }
  }
  for (std::size_t v = 0; v < V; ++v) {
    const std::vector<std::int64_t>& off = offsets_[v];
    const std::int64_t best_e = best_e_v[v];
    const double best = best_sum_v[v];
    if (best_e < 0) continue;
    const double score = best / static_cast<double>(L);
    const std::int64_t j_end = current.j_lo + best_e;
    // Cover: the queries this line crosses.
    for (std::size_t k = 0; k < L; ++k) {
      const std::int64_t q = i - static_cast<std::int64_t>(k);
      if (pending_.empty() || q < pending_.front().i) break;
      const ZRow* r = row_at(q);
      const std::int64_t j = j_end - off[k];
      if (r == nullptr || r->at(j) == nullptr) continue;
      ContrastVerdict& p = pending_[static_cast<std::size_t>(q - pending_.front().i)];
      if (p.best_j < 0 || score > p.score) {
        p.best_j = j;
        p.score = score;
        p.velocity = velocities_[v];
        p.line_end = i;
      }
    }
  }
  finalise(i - (sequence_length_ - 1), out);
}

void ContrastSequenceSearch::flush(ContrastOutput& out) {
  finalise(next_frame_ - 1, out);
}

void ContrastSequenceSearch::finalise(std::int64_t last_final, ContrastOutput& out) {
  while (!pending_.empty() && pending_.front().i <= last_final) {
    ContrastVerdict v = pending_.front();
    pending_.pop_front();
    if (v.best_j < 0) {
      v.outcome = FrameOutcome::kNoCandidate;
    } else if (v.score >= config_.min_score) {
      v.outcome = FrameOutcome::kLoop;
      out.loops.push_back(LoopClosure{v.i, v.best_j, v.score});
    } else {
      v.outcome = FrameOutcome::kBelowThreshold;
    }
    out.frames.push_back(v);
  }
}

ContrastOutput contrast_search_batch(std::span<const std::vector<DistanceEntry>> rows,
                                     const ContrastSearchConfig& config, int sequence_length,
                                     ContrastSequenceSearch::Mode mode, int margin) {
  const auto n = static_cast<std::int64_t>(rows.size());
  // z of every row as a map from j, for clarity.
  std::vector<std::vector<std::pair<std::int64_t, float>>> z(rows.size());
  for (std::int64_t i = 0; i < n; ++i) {
    std::vector<DistanceEntry> sorted = sorted_row(i, rows[static_cast<std::size_t>(i)], mode, margin);
    const std::vector<float> zi =
        contrast_enhance_row(sorted, config.contrast_half_window_frames, config.contrast_min_cells);
    for (std::size_t k = 0; k < sorted.size(); ++k)
      z[static_cast<std::size_t>(i)].push_back({sorted[k].j, zi[k]});
  }
  const auto z_at = [&](std::int64_t i, std::int64_t j) -> float {  // NaN: undefined or missing
    if (i < 0 || i >= n) return kUndefined;
    const auto& row = z[static_cast<std::size_t>(i)];
    const auto it =
        std::lower_bound(row.begin(), row.end(), j,
                         [](const std::pair<std::int64_t, float>& e, std::int64_t x) { return e.first < x; });
    return it != row.end() && it->first == j ? it->second : kUndefined;
  };
  std::vector<ContrastVerdict> verdicts(rows.size());
  for (std::int64_t i = 0; i < n; ++i) {
    verdicts[static_cast<std::size_t>(i)].i = i;
    verdicts[static_cast<std::size_t>(i)].cells = rows[static_cast<std::size_t>(i)].size();
    for (const auto& [j, value] : z[static_cast<std::size_t>(i)]) {
      if (!std::isnan(value)) ++verdicts[static_cast<std::size_t>(i)].defined;
    }
  }
  const std::vector<double> velocities = config.velocities();
  for (std::int64_t i = 0; i < n; ++i) {
    for (const double v : velocities) {
      double best = -std::numeric_limits<double>::infinity();
      std::int64_t best_j = -1;
      for (const auto& [j, value] : z[static_cast<std::size_t>(i)]) {
        if (std::isnan(value)) continue;
        double sum = 0.0;
        for (int k = 0; k < sequence_length; ++k) {
          const float x = z_at(i - k, j - std::llround(v * k));
          if (!std::isnan(x)) sum += x;
        }
        if (sum > best) {
          best = sum;
          best_j = j;
        }
      }
      if (best_j < 0) continue;
      const double score = best / sequence_length;
      for (int k = 0; k < sequence_length; ++k) {
        const std::int64_t q = i - k, j = best_j - std::llround(v * k);
        if (q < 0 || std::isnan(z_at(q, j))) continue;
        ContrastVerdict& p = verdicts[static_cast<std::size_t>(q)];
        if (p.best_j < 0 || score > p.score) {
          p.best_j = j;
          p.score = score;
          p.velocity = v;
          p.line_end = i;
        }
      }
    }
  }
  ContrastOutput out;
  for (ContrastVerdict& v : verdicts) {
    if (v.best_j < 0) {
      v.outcome = FrameOutcome::kNoCandidate;
    } else if (v.score >= config.min_score) {
      v.outcome = FrameOutcome::kLoop;
      out.loops.push_back(LoopClosure{v.i, v.best_j, v.score});
    } else {
      v.outcome = FrameOutcome::kBelowThreshold;
    }
    out.frames.push_back(v);
  }
  return out;
}

FrameDetection contrast_detection(const ContrastVerdict& verdict, const ContrastOutcomeContext& c) {
  FrameDetection d;
  d.outcome = verdict.outcome;
  d.label = to_string(verdict.outcome);
  if (verdict.best_j >= 0) {
    d.match = verdict.best_j;
    d.score = verdict.score;
  }
  switch (verdict.outcome) {
    case FrameOutcome::kNoCandidate:
      if (c.outside_areas) {
        d.reason = "outside every candidate area";
      } else if (!c.described) {
        d.reason = "no descriptor (image not decoded)";
      } else if (c.before_margin) {
        d.reason = fmt::format("no earlier frame beyond the margin of {}", c.margin_frames);
      } else if (verdict.cells == 0) {
        d.reason = "no distance computed";
      } else {
        d.reason = fmt::format("{} distances, {} with a defined contrast; no sequence crosses them",
                               verdict.cells, verdict.defined);
      }
      break;
    case FrameOutcome::kBelowThreshold:
      d.reason = fmt::format("best sequence mean z {:.3f} < {:.3f} (velocity {:.2f}, ends at query {})",
                             verdict.score, c.min_score, verdict.velocity, verdict.line_end);
      break;
    case FrameOutcome::kSuppressed:  // not produced by this search
    case FrameOutcome::kLoop:
      d.reason = fmt::format("sequence mean z {:.3f} >= {:.3f} (velocity {:.2f}, ends at query {})",
                             verdict.score, c.min_score, verdict.velocity, verdict.line_end);
      break;
  }
  return d;
}

}  // namespace loopgate
