#include "stages/match/sequence_matcher.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <stdexcept>
#include <string>

namespace loopgate {

namespace {

constexpr std::int64_t kNoRow = std::numeric_limits<std::int64_t>::max();

using SparseColumn = std::vector<std::pair<std::int64_t, double>>;

// out(r) = s(r) + max_{t in [r - max_step, r]} prev(t) for every row r where either side is non-zero
// (missing = 0). Rows of `prev` and `s` ascending; the output rows ascending.
void shift_max_add(const SparseColumn& prev, const SparseColumn& s, std::int64_t max_step,
                   SparseColumn& out) {
  out.clear();
  std::size_t lo = 0, hi = 0, gen = 0, is = 0;
  std::int64_t cursor = 0;  // next row that may be emitted
  for (;;) {
    while (gen < prev.size() && prev[gen].first + max_step < cursor) ++gen;
    const std::int64_t from_prev = gen < prev.size() ? std::max(cursor, prev[gen].first) : kNoRow;
    const std::int64_t from_s = is < s.size() ? s[is].first : kNoRow;
    const std::int64_t r = std::min(from_prev, from_s);
    if (r == kNoRow) break;
    cursor = r + 1;
    while (hi < prev.size() && prev[hi].first <= r) ++hi;
    while (lo < hi && prev[lo].first < r - max_step) ++lo;
    double best = 0.0;
    for (std::size_t t = lo; t < hi; ++t) best = std::max(best, prev[t].second);
    double s_value = 0.0;
    if (from_s == r) s_value = s[is++].second;
    out.emplace_back(r, s_value + best);
  }
}

// Second largest of the window values (ties counted; missing cells are 0) and the suppression.
struct TopTwo {
  double first = 0.0;
  double second = 0.0;
  void add(double v) {
    if (v > first) {
      second = first;
      first = v;
    } else if (v > second) {
      second = v;
    }
  }
};

}  // namespace

SequenceMatcher::SequenceMatcher(const MatchConfig& config, Mode mode, std::int64_t first_frame)
    : config_(config), mode_(mode), next_frame_(first_frame), next_visit_(first_frame) {
  config_.validate();
  const std::size_t history = static_cast<std::size_t>(config_.sequence_length - 1);
  h_prev_.resize(history);
  h_next_.resize(history);
}

MatchOutput SequenceMatcher::push(std::int64_t i, std::span<const SimilarityEntry> entries) {
  MatchOutput out;
  push(i, entries, out);
  return out;
}

void SequenceMatcher::push(std::int64_t i, std::span<const SimilarityEntry> entries, MatchOutput& out) {
  if (i != next_frame_) {
    throw std::invalid_argument("SequenceMatcher: frame " + std::to_string(i) + " pushed, expected frame " +
                                std::to_string(next_frame_));
  }
  s_column_.clear();
  s_column_.reserve(entries.size());
  for (const SimilarityEntry& e : entries) {
    if (e.j < 0 || !std::isfinite(e.similarity) || e.similarity < 0.0) {
      throw std::invalid_argument("SequenceMatcher: frame " + std::to_string(i) + ": bad entry j=" +
                                  std::to_string(e.j) + " similarity=" + std::to_string(e.similarity));
    }
    if (mode_ == Mode::kSingleSequence && i - e.j < config_.margin) {
      throw std::invalid_argument("SequenceMatcher: frame " + std::to_string(i) +
                                  ": entry j=" + std::to_string(e.j) + " is within the safety margin " +
                                  std::to_string(config_.margin));
    }
    s_column_.emplace_back(e.j, e.similarity);
  }
  std::sort(s_column_.begin(), s_column_.end());
  for (std::size_t k = 1; k < s_column_.size(); ++k) {
    if (s_column_[k].first == s_column_[k - 1].first) {
      throw std::invalid_argument("SequenceMatcher: frame " + std::to_string(i) +
                                  ": duplicate entry j=" + std::to_string(s_column_[k].first));
    }
  }

  Column column;
  column.i = i;
  column.status.i = i;
  column.status.candidates = s_column_.size();
  for (const auto& [j, sim] : s_column_)
    column.status.best_similarity = std::max(column.status.best_similarity, sim);

  // DP = H_L at the stored rows: S + window max over H_{L-1} of the previous column.
  const int length = config_.sequence_length;
  const std::int64_t max_step = config_.max_step;
  const double threshold = config_.dp_threshold();
  if (!s_column_.empty()) {
    const SparseColumn empty;
    const SparseColumn& prev = length >= 2 ? h_prev_[static_cast<std::size_t>(length - 2)] : empty;
    std::size_t lo = 0, hi = 0;
    for (const auto& [r, s_value] : s_column_) {
      while (hi < prev.size() && prev[hi].first <= r) ++hi;
      while (lo < hi && prev[lo].first < r - max_step) ++lo;
      double best = 0.0;
      for (std::size_t t = lo; t < hi; ++t) best = std::max(best, prev[t].second);
      const double dp = s_value + best;
      if (column.status.best_j < 0 || dp > column.status.best_score) {
        column.status.best_score = dp;
        column.status.best_j = r;
      }
      if (dp > threshold) column.entries.push_back({r, dp, dp});
    }
  }
  column.status.above_threshold = column.entries.size();
  // Advance H_1..H_{L-1} to this column.
  if (length >= 2) {
    h_next_[0] = s_column_;
    for (std::size_t k = 1; k < h_next_.size(); ++k)
      shift_max_add(h_prev_[k - 1], s_column_, max_step, h_next_[k]);
    std::swap(h_prev_, h_next_);
  }
  columns_.push_back(std::move(column));
  ++next_frame_;

  const std::int64_t half_window = config_.nms_half_window;
  while (next_visit_ + half_window <= i) {
    visit_column(static_cast<std::size_t>(next_visit_ - columns_.front().i));
    ++next_visit_;
  }
  while (!columns_.empty() && columns_.front().i + half_window < next_visit_) finalise_front(out);
}

MatchOutput SequenceMatcher::flush() {
  MatchOutput out;
  flush(out);
  return out;
}

void SequenceMatcher::flush(MatchOutput& out) {
  while (next_visit_ < next_frame_) {
    visit_column(static_cast<std::size_t>(next_visit_ - columns_.front().i));
    ++next_visit_;
  }
  while (!columns_.empty()) finalise_front(out);
}

double* SequenceMatcher::find_current(std::int64_t i, std::int64_t j) {
  if (columns_.empty() || j < 0 || i < columns_.front().i || i > columns_.back().i) return nullptr;
  auto& entries = columns_[static_cast<std::size_t>(i - columns_.front().i)].entries;
  auto it = std::lower_bound(entries.begin(), entries.end(), j,
                             [](const DpEntry& e, std::int64_t row) { return e.j < row; });
  if (it == entries.end() || it->j != j) return nullptr;
  return &it->current;
}

void SequenceMatcher::visit_column(std::size_t index) {
  const std::int64_t c = columns_[index].i;
  const std::int64_t half_window = config_.nms_half_window;
  std::vector<double*>& window = window_scratch_;
  for (std::size_t e = 0; e < columns_[index].entries.size(); ++e) {
    const std::int64_t diagonal = columns_[index].entries[e].j + c;
    window.clear();
    TopTwo top;
    for (std::int64_t col = c - half_window; col <= c + half_window; ++col) {
      double* value = find_current(col, diagonal - col);
      if (value == nullptr) continue;  // missing = 0
      window.push_back(value);
      top.add(*value);
    }
    for (double* value : window) {
      if (*value != 0.0 && *value < top.second) *value = 0.0;
    }
  }
}

void SequenceMatcher::finalise_front(MatchOutput& out) {
  Column& column = columns_.front();
  for (const DpEntry& e : column.entries) {
    if (e.current != 0.0) {
      out.loops.push_back({column.i, e.j, e.score});
      ++column.status.loops;
    }
  }
  FrameMatchStatus& status = column.status;
  if (status.candidates == 0) {
    status.outcome = FrameOutcome::kNoCandidate;
  } else if (status.above_threshold == 0) {
    status.outcome = FrameOutcome::kBelowThreshold;
  } else if (status.loops == 0) {
    status.outcome = FrameOutcome::kSuppressed;
  } else {
    status.outcome = FrameOutcome::kLoop;
  }
  out.frames.push_back(status);
  columns_.pop_front();
}

std::vector<LoopClosure> sequence_dp_batch(std::span<const std::vector<SimilarityEntry>> columns,
                                           const MatchConfig& config) {
  config.validate();
  std::int64_t rows = 0;
  for (const auto& column : columns) {
    for (const SimilarityEntry& e : column) {
      if (e.j < 0) throw std::invalid_argument("sequence_dp_batch: negative row");
      rows = std::max(rows, e.j + 1);
    }
  }
  const std::size_t n_rows = static_cast<std::size_t>(rows);
  const std::size_t length = static_cast<std::size_t>(config.sequence_length);
  // prev[k][r] = H_{k+1}(r, c - 1), cur[k][r] = H_{k+1}(r, c).
  std::vector<std::vector<double>> prev(length, std::vector<double>(n_rows, 0.0));
  std::vector<std::vector<double>> cur = prev;
  std::vector<double> s(n_rows, 0.0);
  std::vector<LoopClosure> dp;
  for (std::size_t c = 0; c < columns.size(); ++c) {
    std::fill(s.begin(), s.end(), 0.0);
    for (const SimilarityEntry& e : columns[c]) s[static_cast<std::size_t>(e.j)] = e.similarity;
    cur[0] = s;
    for (std::size_t k = 1; k < length; ++k) {
      for (std::size_t r = 0; r < n_rows; ++r) {
        double best = 0.0;
        for (std::int64_t step = 0; step <= config.max_step; ++step) {
          const std::int64_t row = static_cast<std::int64_t>(r) - step;
          if (row < 0) break;
          best = std::max(best, prev[k - 1][static_cast<std::size_t>(row)]);
        }
        cur[k][r] = s[r] + best;
      }
    }
    std::vector<std::int64_t> stored;
    for (const SimilarityEntry& e : columns[c]) stored.push_back(e.j);
    std::sort(stored.begin(), stored.end());
    for (std::int64_t j : stored) {
      const double value = cur[length - 1][static_cast<std::size_t>(j)];
      if (value > config.dp_threshold()) dp.push_back({static_cast<std::int64_t>(c), j, value});
    }
    std::swap(prev, cur);
  }
  return dp;
}

std::vector<LoopClosure> nms_batch(std::span<const LoopClosure> dp, int nms_half_window) {
  std::map<std::pair<std::int64_t, std::int64_t>, double> m;  // (i, j) -> M value
  for (const LoopClosure& e : dp) {
    if (!m.emplace(std::make_pair(e.i, e.j), e.score).second) {
      throw std::invalid_argument("nms_batch: duplicate entry");
    }
  }
  std::vector<std::pair<std::int64_t, std::int64_t>> order;
  for (const auto& [key, value] : m) order.push_back(key);  // ascending (i, j)
  const std::int64_t w = nms_half_window;
  for (const auto& [i, j] : order) {
    std::vector<double*> window;
    TopTwo top;
    for (std::int64_t k = -w; k <= w; ++k) {
      auto it = m.find({i + k, j - k});
      if (it == m.end()) continue;
      window.push_back(&it->second);
      top.add(it->second);
    }
    for (double* value : window) {
      if (*value != 0.0 && *value < top.second) *value = 0.0;
    }
  }
  std::vector<LoopClosure> survivors;
  for (const LoopClosure& e : dp) {
    if (m.at({e.i, e.j}) != 0.0) survivors.push_back(e);
  }
  std::sort(survivors.begin(), survivors.end(),
            [](const LoopClosure& a, const LoopClosure& b) { return a.i != b.i ? a.i < b.i : a.j < b.j; });
  return survivors;
}

std::vector<LoopClosure> match_batch(std::span<const std::vector<SimilarityEntry>> columns,
                                     const MatchConfig& config) {
  const std::vector<LoopClosure> dp = sequence_dp_batch(columns, config);
  return nms_batch(dp, config.nms_half_window);
}

std::vector<LoopClosure> match_two_sequences(std::span<const Descriptor> reference,
                                             std::span<const Descriptor> query,
                                             const DirdSimilarity& similarity, const MatchConfig& config,
                                             std::vector<FrameMatchStatus>* statuses) {
  SequenceMatcher matcher(config, SequenceMatcher::Mode::kTwoSequence);
  MatchOutput out;
  std::vector<SimilarityEntry> entries;
  for (std::size_t q = 0; q < query.size(); ++q) {
    entries.clear();
    similarity.sparse_row(query[q], reference.data(), reference.size(), 0, entries);
    matcher.push(static_cast<std::int64_t>(q), entries, out);
  }
  matcher.flush(out);
  if (statuses != nullptr) *statuses = std::move(out.frames);
  return out.loops;
}

}  // namespace loopgate
