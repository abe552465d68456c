#include "stages/seqslam/seqslam_gated.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace loopgate {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// Sorts and merges intervals, adjacent ones included (so that a contiguous range inside their union lies
// inside one of them).
void merge(std::vector<SeqSlamSpan>& spans) {
  if (spans.empty()) return;
  std::sort(spans.begin(), spans.end(),
            [](const SeqSlamSpan& a, const SeqSlamSpan& b) { return a.first < b.first; });
  std::vector<SeqSlamSpan> out;
  out.reserve(spans.size());
  for (const SeqSlamSpan& s : spans) {
    if (!out.empty() && s.first <= out.back().last + 1) {
      out.back().last = std::max(out.back().last, s.last);
    } else {
      out.push_back(s);
    }
  }
  spans = std::move(out);
}

}  // namespace

SeqSlamGatedSearch::SeqSlamGatedSearch(const SeqSlamConfig& config)
    : config_(config), exclusion_(SeqSlamExclusion::from_config(config)) {
  config_.validate();
  half_sequence_ = static_cast<std::size_t>(config_.sequence_length_frames / 2);
  half_window_ = static_cast<std::size_t>(config_.contrast_window_rows / 2);
  const std::vector<int> moves = config_.moves();
  move_min_ = static_cast<std::size_t>(moves.front());
  move_max_ = static_cast<std::size_t>(moves.back());
}

void SeqSlamGatedSearch::frames_for_cells(std::size_t i, std::size_t j0, std::size_t j1,
                                          std::vector<std::size_t>& out) const {
  const std::size_t h = half_sequence_;
  const std::size_t first_out = out.size();
  for (std::size_t t = 0; t <= 2 * h; ++t) {
    if (i + t >= h) out.push_back(i + t - h);
  }
  if (j1 >= h && j1 >= j0) {
    const std::size_t a = std::max(j0, h) - h;
    const std::size_t b = j1 - h;
    const std::size_t lo = a >= half_window_ ? a - half_window_ : 0;
    const std::size_t hi = b + move_max_ + half_window_;
    const std::size_t q_lo = i >= h ? i - h : 0;
    for (std::size_t r = lo; r <= hi; ++r) {
      for (std::size_t q = q_lo; q <= i + h; ++q) {
        if (!exclusion_.excluded(r, q)) {
          out.push_back(r);
          break;
        }
      }
    }
  }
  std::sort(out.begin() + static_cast<std::ptrdiff_t>(first_out), out.end());
  out.erase(std::unique(out.begin() + static_cast<std::ptrdiff_t>(first_out), out.end()), out.end());
}

void SeqSlamGatedSearch::add_cells(std::size_t i, std::size_t j0, std::size_t j1) {
  if (planned_) throw std::logic_error("SeqSlamGatedSearch: cells added after plan()");
  if (j1 < j0) return;
  if (covered_.size() <= i) covered_.resize(i + 1);
  covered_[i].push_back({j0, j1});
}

std::vector<SeqSlamSpan> SeqSlamGatedSearch::start_rows(std::size_t query) const {
  std::vector<SeqSlamSpan> starts;
  const std::size_t h = half_sequence_;
  const std::size_t n = frame_count_;
  if (query < h || query + h >= n || query >= covered_.size()) return starts;
  for (const SeqSlamSpan& span : covered_[query]) {
    if (span.last < h) continue;
    const std::size_t first = std::max(span.first, h) - h;
    const std::size_t last = std::min(span.last - h, n - 1);
    if (first <= last) starts.push_back({first, last});
  }
  return starts;  // covered_ rows are merged, so these are too
}

void SeqSlamGatedSearch::plan(std::size_t frame_count) {
  if (planned_) throw std::logic_error("SeqSlamGatedSearch: plan() called twice");
  planned_ = true;
  frame_count_ = frame_count;
  for (std::vector<SeqSlamSpan>& row : covered_) merge(row);
  columns_.assign(frame_count, Column{});
  const std::size_t h = half_sequence_;
  const std::size_t ds = 2 * h;
  const std::size_t n = frame_count;
  for (std::size_t query = h; query + h < n && query < covered_.size(); ++query) {
    const std::vector<SeqSlamSpan> starts = start_rows(query);
    if (starts.empty()) continue;
    queries_.push_back(query);
    for (const SeqSlamSpan& s : starts) {
      for (std::size_t t = 0; t <= ds; ++t) {
        const std::size_t lo = s.first + t * move_min_ / ds;
        if (lo >= n) continue;
        const std::size_t hi = std::min(n - 1, s.last + t * move_max_ / ds);
        columns_[query - h + t].e_rows.push_back({lo, hi});
      }
    }
  }
  for (std::size_t q = 0; q < n; ++q) {
    Column& c = columns_[q];
    if (c.e_rows.empty()) continue;
    merge(c.e_rows);
    for (const SeqSlamSpan& e : c.e_rows) {
      c.d_rows.push_back(
          {e.first >= half_window_ ? e.first - half_window_ : 0, std::min(n - 1, e.last + half_window_)});
    }
    merge(c.d_rows);
    work_columns_.push_back(q);
  }
}

std::vector<std::size_t> SeqSlamGatedSearch::frames_read() const {
  std::vector<bool> used(frame_count_, false);
  for (const std::size_t q : work_columns_) {
    used[q] = true;
    for (const SeqSlamSpan& d : columns_[q].d_rows) {
      for (std::size_t r = d.first; r <= d.last; ++r) used[r] = used[r] || !exclusion_.excluded(r, q);
    }
  }
  std::vector<std::size_t> out;
  for (std::size_t k = 0; k < frame_count_; ++k) {
    if (used[k]) out.push_back(k);
  }
  return out;
}

double SeqSlamGatedSearch::compute_column(std::size_t q, const SeqSlamFrames& frames) {
  if (!planned_ || q >= frame_count_) throw std::logic_error("SeqSlamGatedSearch: column outside the plan");
  Column& c = columns_[q];
  c.e.assign(c.e_rows.size(), {});
  c.differences = 0;
  const double pixels = static_cast<double>(frames.pixel_count);
  const std::uint8_t* q_image = frames.image(q);
  std::vector<double> d;
  double minimum = kInf;
  std::size_t e_index = 0;
  for (const SeqSlamSpan& span : c.d_rows) {
    d.assign(span.last - span.first + 1, kInf);
    for (std::size_t r = span.first; r <= span.last; ++r) {
      if (exclusion_.excluded(r, q)) continue;  // +infinity, not computed (as seqslam_difference_block)
      d[r - span.first] =
          static_cast<double>(seqslam_sad(frames.image(r), q_image, frames.pixel_count)) / pixels;
      ++c.differences;
    }
    for (; e_index < c.e_rows.size() && c.e_rows[e_index].last <= span.last; ++e_index) {
      const SeqSlamSpan& rows = c.e_rows[e_index];
      std::vector<double>& values = c.e[e_index];
      values.resize(rows.last - rows.first + 1);
      for (std::size_t r = rows.first; r <= rows.last; ++r) {
        const double v =
            seqslam_enhanced_entry(d.data(), span.first, frame_count_, config_.contrast_window_rows, r);
        values[r - rows.first] = v;
        if (std::isfinite(v)) minimum = std::min(minimum, v);
      }
    }
  }
  return minimum;
}

void SeqSlamGatedSearch::subtract(double minimum) {
  minimum_ = minimum;
  if (!std::isfinite(minimum)) return;  // no finite entry: nothing to shift (as the full run)
  for (const std::size_t q : work_columns_) {
    for (std::vector<double>& values : columns_[q].e) {
      for (double& v : values) v -= minimum;  // +inf stays +inf
    }
  }
}

const double* SeqSlamGatedSearch::Column::find(std::size_t first, std::size_t last) const {
  const auto it = std::upper_bound(e_rows.begin(), e_rows.end(), first,
                                   [](std::size_t row, const SeqSlamSpan& s) { return row < s.first; });
  if (it == e_rows.begin()) return nullptr;
  const auto index = static_cast<std::size_t>(it - e_rows.begin()) - 1;
  const SeqSlamSpan& span = e_rows[index];
  if (last > span.last || index >= e.size() || e[index].empty()) return nullptr;
  return e[index].data() + (first - span.first);
}

std::vector<double> SeqSlamGatedSearch::sequence_scores(std::size_t query, std::size_t* first_start) const {
  *first_start = 0;
  const std::vector<SeqSlamSpan> starts = start_rows(query);
  if (starts.empty()) return {};
  const std::size_t h = half_sequence_;
  const std::size_t ds = 2 * h;
  const std::size_t n = frame_count_;
  const std::size_t s_first = starts.front().first;
  std::vector<double> scores(starts.back().last - s_first + 1, kInf);
  std::vector<double> acc, best;
  // The arithmetic of seqslam_sequence_scores, start row by start row: the sum over t in order for each
  // move (a row past the last frame makes it +infinity), then the minimum over the moves in order.
  for (const SeqSlamSpan& s : starts) {
    const std::size_t count = s.last - s.first + 1;
    best.assign(count, kInf);
    for (const int move : config_.moves()) {
      acc.assign(count, 0.0);
      for (std::size_t t = 0; t <= ds; ++t) {
        const std::size_t offset = t * static_cast<std::size_t>(move) / ds;  // floor(t * move / ds)
        const std::size_t row_first = s.first + offset;
        const std::size_t inside = row_first < n ? std::min(count, n - row_first) : 0;
        if (inside > 0) {
          const double* e = columns_[query - h + t].find(row_first, row_first + inside - 1);
          if (!e) {
            throw std::logic_error("SeqSlamGatedSearch: query " + std::to_string(query) + " reads rows " +
                                   std::to_string(row_first) + ".." + std::to_string(row_first + inside - 1) +
                                   " of column " + std::to_string(query - h + t) + ", not computed");
          }
          for (std::size_t k = 0; k < inside; ++k) acc[k] += e[k];
        }
        for (std::size_t k = inside; k < count; ++k) acc[k] = kInf;  // beyond the last reference row
      }
      for (std::size_t k = 0; k < count; ++k) best[k] = std::min(best[k], acc[k]);
    }
    std::copy(best.begin(), best.end(), scores.begin() + static_cast<std::ptrdiff_t>(s.first - s_first));
  }
  *first_start = s_first;
  return scores;
}

SeqSlamMatch SeqSlamGatedSearch::match_query(std::size_t query) const {
  std::size_t first = 0;
  const std::vector<double> scores = sequence_scores(query, &first);
  return seqslam_match_from_scores(query, scores.data(), scores.size(), first, config_);
}

std::vector<SeqSlamMatch> SeqSlamGatedSearch::run(std::size_t frame_count, const SeqSlamFrames& frames) {
  plan(frame_count);
  double minimum = kInf;
  for (const std::size_t q : work_columns_) minimum = std::min(minimum, compute_column(q, frames));
  subtract(minimum);
  std::vector<SeqSlamMatch> matches(frame_count);
  for (std::size_t q = 0; q < frame_count; ++q) matches[q].query = q;
  for (const std::size_t query : queries_) matches[query] = match_query(query);
  return matches;
}

std::optional<double> SeqSlamGatedSearch::entry(std::size_t r, std::size_t q) const {
  if (q >= columns_.size()) return std::nullopt;
  const double* e = columns_[q].find(r, r);
  if (!e) return std::nullopt;
  return *e;
}

bool SeqSlamGatedSearch::covered(std::size_t i, std::size_t j) const {
  if (i >= covered_.size()) return false;
  for (const SeqSlamSpan& span : covered_[i]) {
    if (j >= span.first && j <= span.last) return true;
  }
  return false;
}

std::size_t SeqSlamGatedSearch::difference_entries() const {
  std::size_t total = 0;
  for (const Column& c : columns_) total += c.differences;
  return total;
}

std::size_t SeqSlamGatedSearch::enhanced_entries() const {
  std::size_t total = 0;
  for (const Column& c : columns_) {
    for (const std::vector<double>& values : c.e) total += values.size();
  }
  return total;
}

}  // namespace loopgate
