// Private: the time-order rule of the dataset readers (issue 15), shared by the text tables (rows are lines)
// and the ROS1 bag reader (rows are the messages of one topic).
#pragma once

#include <algorithm>
#include <cstddef>
#include <filesystem>
#include <string>
#include <vector>

#include "core/types.hpp"
#include "io/csv_text.hpp"

namespace loopgate::io_detail {

// A time for a message: seconds with 9 decimals (the tables in seconds) or integer ns.
inline std::string time_text(Timestamp t_ns, bool seconds) {
  if (!seconds) return std::to_string(t_ns) + " ns";
  std::string out;
  append_seconds(out, t_ns);
  return out + " s";
}

// A row of a time-ordered table, parsed, before the order is judged: `line` is its line in the file, or for
// the messages of a bag topic its 0-based position on the topic.
template <class T>
struct TimedRow {
  std::size_t line = 0;
  Timestamp t_ns = 0;
  T value;
};

// Rows in strictly increasing time order minus the rows that break the series: a row whose step to each
// neighbour (its one neighbour at either end of the table) is more than kIsolatedFactor times the median step
// and more than kIsolatedMinStepNs. This is the rule of the middle of a table carried to its ends: in the
// middle, a stamp of 0 or a typo far from its neighbours is out of order and dropped; at the start or the end
// the same stamp is in order, and without this rule a leading 0 would time the first frame in 1970 (and a
// replay at run.rate 1 would wait decades for the second). Tables of fewer than 3 rows have no median step
// and keep every row. report(row, message, false) is called for each row dropped.
inline constexpr double kIsolatedFactor = 1000.0;
inline constexpr Timestamp kIsolatedMinStepNs = 1'000'000'000;

template <class T, class Report>
std::vector<TimedRow<T>> drop_isolated_rows(std::vector<TimedRow<T>> rows, const char* what, bool seconds,
                                            const std::string& unit, Report& report) {
  const std::size_t n = rows.size();
  if (n < 3) return rows;
  std::vector<Timestamp> steps(n - 1);
  for (std::size_t i = 0; i + 1 < n; ++i) steps[i] = rows[i + 1].t_ns - rows[i].t_ns;
  std::vector<Timestamp> sorted = steps;
  std::nth_element(sorted.begin(), sorted.begin() + static_cast<std::ptrdiff_t>((n - 2) / 2), sorted.end());
  const Timestamp median = sorted[(n - 2) / 2];
  const double limit =
      std::max(kIsolatedFactor * static_cast<double>(median), static_cast<double>(kIsolatedMinStepNs));
  const auto far = [&](std::size_t step) { return static_cast<double>(steps[step]) > limit; };
  std::vector<TimedRow<T>> kept;
  kept.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    const bool isolated = (i == 0 || far(i - 1)) && (i + 1 == n || far(i));
    if (!isolated) {
      kept.push_back(std::move(rows[i]));
      continue;
    }
    const std::size_t near = i + 1 < n ? i + 1 : i - 1;
    const Timestamp step = i + 1 < n ? steps[i] : steps[i - 1];
    report(static_cast<const TimedRow<T>&>(rows[i]),
           std::string(what) + " " + time_text(rows[i].t_ns, seconds) + " is " + time_text(step, true) +
               " from " + unit + " " + std::to_string(rows[near].line) + " (" +
               time_text(rows[near].t_ns, seconds) +
               "), its nearest neighbour, more than 1000 times the median step between rows (" +
               time_text(median, true) +
               "): a stamp that breaks the series (a 0 or a typo), dropped like a row out of order",
           false);
  }
  return kept;
}

// The rows whose times strictly increase, keeping as many as possible: the longest strictly increasing
// subsequence (earliest rows preferred among equal times). Every other row is reported, judged against the
// kept rows on both sides of it, so that a single outlier (a typo of 10^5 s at row 10) is the one row
// dropped whichever way it jumps, not the 1 990 good rows after it: report(row, message, true) is called
// for each in row order, the message naming the kept rows around it as "<unit> N" ("line 12", "message 12").
// Then the rows that break the series are dropped (drop_isolated_rows).
template <class T, class Report>
std::vector<TimedRow<T>> keep_increasing_rows(std::vector<TimedRow<T>> rows, const char* what, bool seconds,
                                              const std::string& unit, Report&& report) {
  const std::size_t n = rows.size();
  // Patience sorting on the reversed sequence of negated times (strictly increasing), so that among equal
  // times the earliest row is the one kept.
  std::vector<std::size_t> tails;           // tails[k]: position (in reversed order) ending a run of k + 1
  std::vector<std::ptrdiff_t> previous(n);  // link to the run's element before, -1 at its start
  const auto key = [&](std::size_t k) { return -rows[n - 1 - k].t_ns; };
  for (std::size_t k = 0; k < n; ++k) {
    const auto it = std::lower_bound(tails.begin(), tails.end(), key(k),
                                     [&](std::size_t a, Timestamp value) { return key(a) < value; });
    previous[k] = it == tails.begin() ? -1 : static_cast<std::ptrdiff_t>(*(it - 1));
    if (it == tails.end()) {
      tails.push_back(k);
    } else {
      *it = k;
    }
  }
  std::vector<char> keep(n, 0);
  for (std::ptrdiff_t k = tails.empty() ? -1 : static_cast<std::ptrdiff_t>(tails.back()); k >= 0;
       k = previous[static_cast<std::size_t>(k)]) {
    keep[n - 1 - static_cast<std::size_t>(k)] = 1;
  }
  if (tails.size() == n) return drop_isolated_rows(std::move(rows), what, seconds, unit, report);
  std::vector<std::ptrdiff_t> next_kept(n, -1);
  for (std::ptrdiff_t i = static_cast<std::ptrdiff_t>(n) - 1, next = -1; i >= 0; --i) {
    next_kept[static_cast<std::size_t>(i)] = next;
    if (keep[static_cast<std::size_t>(i)]) next = i;
  }
  std::vector<TimedRow<T>> kept;
  kept.reserve(tails.size());
  std::ptrdiff_t last_kept = -1;
  for (std::size_t i = 0; i < n; ++i) {
    if (keep[i]) {
      kept.push_back(std::move(rows[i]));
      last_kept = static_cast<std::ptrdiff_t>(i);
      continue;
    }
    const Timestamp t = rows[i].t_ns;
    std::string message = std::string(what) + " " + time_text(t, seconds);
    const TimedRow<T>* before = last_kept >= 0 ? &kept.back() : nullptr;
    const TimedRow<T>* after = next_kept[i] >= 0 ? &rows[static_cast<std::size_t>(next_kept[i])] : nullptr;
    if (before && t == before->t_ns) {
      message = "duplicate " + message + " (" + unit + " " + std::to_string(before->line) + " has it)";
    } else if (before && t < before->t_ns) {
      message += " is before " + unit + " " + std::to_string(before->line) + " (" +
                 time_text(before->t_ns, seconds) + ")";
    } else {
      message += " is after " + unit + " " + std::to_string(after->line) + " (" +
                 time_text(after->t_ns, seconds) + ")";
    }
    report(static_cast<const TimedRow<T>&>(rows[i]), message, true);
  }
  return drop_isolated_rows(std::move(kept), what, seconds, unit, report);
}

// keep_increasing_rows for the lines of a text table `file`, reported to `log` with their line numbers.
// Called between IssueLog::begin_table() and end_table(): in strict mode the earliest problem of the table is
// the error.
template <class T>
std::vector<TimedRow<T>> keep_increasing(const std::filesystem::path& file, IssueLog& log,
                                         std::vector<TimedRow<T>> rows, const char* what, bool seconds) {
  return keep_increasing_rows(
      std::move(rows), what, seconds, "line",
      [&](const TimedRow<T>& row, const std::string& message, bool out_of_order) {
        log.report(file, row.line,
                   out_of_order ? message +
                                      ", expected strictly increasing times: this row is out of "
                                      "order with the rows around it"
                                : message);
      });
}

}  // namespace loopgate::io_detail
