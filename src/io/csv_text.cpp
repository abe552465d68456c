#include "io/csv_text.hpp"

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <fstream>
#include <limits>
#include <system_error>

#include "io/file_guard.hpp"

namespace loopgate::io_detail {

namespace {

constexpr int kNsDigits = 9;  // decimals of a second in a nanosecond timestamp
constexpr std::int64_t kNsPerSecond = 1'000'000'000;

// A field in an error message: capped, so that a 20 MB field does not end up whole in summary.json.
std::string quoted(std::string_view field) {
  return quote_excerpt(field);
}

std::string column_label(std::size_t column, std::string_view name) {
  return "column " + std::to_string(column + 1) + " (" + std::string(name) + ")";
}

// Parses a whole field as a double; false when malformed (not finite values are parsed).
bool parse_double(std::string_view text, double& value) {
  if (!text.empty() && text.front() == '+') text.remove_prefix(1);
  if (text.empty()) return false;
  const auto [ptr, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
  return ec == std::errc{} && ptr == text.data() + text.size();
}

bool parse_int64(std::string_view text, std::int64_t& value) {
  if (!text.empty() && text.front() == '+') text.remove_prefix(1);
  if (text.empty()) return false;
  const auto [ptr, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
  return ec == std::errc{} && ptr == text.data() + text.size();
}

bool all_digits(std::string_view text) {
  for (const char c : text) {
    if (c < '0' || c > '9') return false;
  }
  return true;
}

}  // namespace

void IssueLog::report(const std::filesystem::path& file, std::size_t line, const std::string& message) {
  if (in_table_) {
    held_.push_back(DataIssue{file, line, message});
    return;
  }
  if (strict_) throw DataError(file, line, message);
  if (sink_) sink_->push_back(DataIssue{file, line, message});
}

void IssueLog::begin_table() {
  in_table_ = true;
  held_.clear();
}

void IssueLog::end_table(const std::filesystem::path& file, std::size_t rows, const std::string& topic) {
  in_table_ = false;
  std::vector<DataIssue> issues = std::move(held_);
  held_.clear();
  std::stable_sort(issues.begin(), issues.end(),
                   [](const DataIssue& a, const DataIssue& b) { return a.line < b.line; });
  if (issues.empty()) return;
  if (strict_) throw DataError(issues.front().file, issues.front().line, issues.front().message);
  const std::size_t rejected = issues.size();
  if (rows > 0 && 2 * rejected > rows) {
    if (!topic.empty()) {
      throw DataError(file,
                      std::to_string(rejected) + " of the " + std::to_string(rows) + " messages of " + topic +
                          " are bad (first: " + issues.front().to_string() +
                          "); more than half of the topic is rejected, so the rest is not trusted either");
    }
    throw DataError(file, std::to_string(rejected) + " of its " + std::to_string(rows) +
                              " rows are bad (first: " + issues.front().to_string() +
                              "); more than half of the file is rejected, so the rest is not trusted either");
  }
  if (sink_) sink_->insert(sink_->end(), issues.begin(), issues.end());
}

double Row::number(std::size_t column, std::string_view name) const {
  const std::string_view field = fields.at(column);
  double value = 0;
  if (!parse_double(field, value)) {
    throw RowError{column_label(column, name) + ": expected a number, got " + quoted(field)};
  }
  if (!std::isfinite(value)) {
    throw RowError{column_label(column, name) + ": expected a finite number, got " + quoted(field)};
  }
  return value;
}

Timestamp Row::integer_ns(std::size_t column, std::string_view name) const {
  const std::string_view field = fields.at(column);
  std::int64_t value = 0;
  if (!parse_int64(field, value)) {
    throw RowError{column_label(column, name) + ": expected an integer timestamp in ns, got " +
                   quoted(field)};
  }
  return value;
}

Timestamp Row::seconds_ns(std::size_t column, std::string_view name) const {
  const std::string_view field = fields.at(column);
  Timestamp t_ns = 0;
  if (!parse_seconds_ns(field, t_ns)) {
    // 16 digits and more without a dot: a time in nanoseconds (EuRoC's, a bag's) given to a file in seconds.
    const bool nanoseconds =
        field.size() >= 16 && field.find_first_not_of("0123456789") == std::string_view::npos;
    throw RowError{column_label(column, name) + ": expected a finite time in seconds, got " + quoted(field) +
                   (nanoseconds ? "; it looks like a time in nanoseconds (" + std::to_string(field.size()) +
                                      " digits): this file takes seconds, e.g. " +
                                      std::string(field.substr(0, field.size() - 9)) + "." +
                                      std::string(field.substr(field.size() - 9))
                                : std::string())};
  }
  return t_ns;
}

void Row::expect_columns(std::size_t expected, std::string_view what) const {
  if (fields.size() != expected) {
    throw RowError{"expected " + std::to_string(expected) + " columns (" + std::string(what) + "), got " +
                   std::to_string(fields.size())};
  }
}

TextFile::TextFile(const std::filesystem::path& file) : path_(file) {
  std::error_code ec;
  if (!std::filesystem::exists(file, ec)) throw DataError(file, "file not found");
  if (std::filesystem::is_directory(file, ec)) throw DataError(file, "expected a file, found a directory");
  require_regular_file(file);  // a FIFO or a device would block open() or never end
  std::ifstream in(file, std::ios::binary);
  if (!in) throw DataError(file, "cannot open file for reading");
  in.seekg(0, std::ios::end);
  const std::streamoff size = in.tellg();
  if (size < 0) throw DataError(file, "cannot read file");
  in.seekg(0, std::ios::beg);
  text_.resize(static_cast<std::size_t>(size));
  if (size > 0 && !in.read(text_.data(), size)) throw DataError(file, "cannot read file");
}

void split_fields(std::string_view line, Delimiter delimiter, std::vector<std::string_view>& fields) {
  fields.clear();
  constexpr std::string_view kBlanks = " \t\r";
  if (delimiter == Delimiter::kWhitespace) {
    std::size_t pos = line.find_first_not_of(kBlanks);
    while (pos != std::string_view::npos) {
      const std::size_t end = line.find_first_of(kBlanks, pos);
      fields.push_back(line.substr(pos, end == std::string_view::npos ? std::string_view::npos : end - pos));
      if (end == std::string_view::npos) break;
      pos = line.find_first_not_of(kBlanks, end);
    }
    return;
  }
  std::size_t pos = 0;
  while (true) {
    const std::size_t end = line.find(',', pos);
    std::string_view field =
        line.substr(pos, end == std::string_view::npos ? std::string_view::npos : end - pos);
    const std::size_t first = field.find_first_not_of(kBlanks);
    if (first == std::string_view::npos) {
      field = field.substr(0, 0);
    } else {
      field = field.substr(first, field.find_last_not_of(kBlanks) - first + 1);
    }
    fields.push_back(field);
    if (end == std::string_view::npos) break;
    pos = end + 1;
  }
}

bool parse_seconds_ns(std::string_view text, Timestamp& t_ns) {
  if (text.find_first_of("eEnN") != std::string_view::npos) {  // exponent notation (or nan/inf)
    double t_s = 0;
    if (!parse_double(text, t_s) || !std::isfinite(t_s)) return false;
    constexpr double kMaxSeconds = static_cast<double>(std::numeric_limits<Timestamp>::max()) / kNsPerS;
    if (std::abs(t_s) >= kMaxSeconds) return false;
    t_ns = s_to_ns(t_s);
    return true;
  }
  bool negative = false;
  if (!text.empty() && (text.front() == '-' || text.front() == '+')) {
    negative = text.front() == '-';
    text.remove_prefix(1);
  }
  const std::size_t dot = text.find('.');
  const std::string_view whole = text.substr(0, dot);
  const std::string_view fraction = dot == std::string_view::npos ? std::string_view{} : text.substr(dot + 1);
  if ((whole.empty() && fraction.empty()) || !all_digits(whole) || !all_digits(fraction)) return false;
  std::int64_t seconds = 0;
  if (!whole.empty() && !parse_int64(whole, seconds)) return false;
  if (seconds > std::numeric_limits<Timestamp>::max() / kNsPerSecond - 1) return false;
  std::int64_t ns = 0;
  for (int i = 0; i < kNsDigits; ++i) {
    ns = ns * 10 +
         (static_cast<std::size_t>(i) < fraction.size() ? fraction[static_cast<std::size_t>(i)] - '0' : 0);
  }
  if (fraction.size() > static_cast<std::size_t>(kNsDigits) && fraction[kNsDigits] >= '5') ++ns;  // round
  const std::int64_t total = seconds * kNsPerSecond + ns;
  t_ns = negative ? -total : total;
  return true;
}

void append_double(std::string& out, double value) {
  std::array<char, 32> buffer{};
  const auto [ptr, ec] = std::to_chars(buffer.data(), buffer.data() + buffer.size(), value);
  out.append(buffer.data(), ec == std::errc{} ? ptr : buffer.data());
}

void append_int(std::string& out, std::int64_t value) {
  std::array<char, 24> buffer{};
  const auto [ptr, ec] = std::to_chars(buffer.data(), buffer.data() + buffer.size(), value);
  out.append(buffer.data(), ec == std::errc{} ? ptr : buffer.data());
}

void append_seconds(std::string& out, Timestamp t_ns) {
  if (t_ns < 0) {
    out.push_back('-');
    // -INT64_MIN overflows; such a timestamp (292 years before 1970) is not a sensor time.
    t_ns = t_ns == std::numeric_limits<Timestamp>::min() ? std::numeric_limits<Timestamp>::max() : -t_ns;
  }
  append_int(out, t_ns / kNsPerSecond);
  out.push_back('.');
  std::string fraction = std::to_string(t_ns % kNsPerSecond);
  out.append(static_cast<std::size_t>(kNsDigits) - fraction.size(), '0');
  out += fraction;
}

void write_text_file(const std::filesystem::path& file, const std::string& text) {
  std::error_code ec;
  if (file.has_parent_path()) {
    std::filesystem::create_directories(file.parent_path(), ec);
    if (ec) throw DataError(file.parent_path(), "cannot create directory: " + ec.message());
  }
  // Whole or absent: written under a temporary name, renamed when complete.
  std::filesystem::path partial = file;
  partial += ".partial";
  std::ofstream out(partial, std::ios::binary | std::ios::trunc);
  if (!out) throw DataError(file, "cannot open file for writing");
  out.write(text.data(), static_cast<std::streamsize>(text.size()));
  out.close();
  if (!out) {
    std::filesystem::remove(partial, ec);
    throw DataError(file, "write failed (disk full?)");
  }
  std::filesystem::rename(partial, file, ec);
  if (ec) {
    std::filesystem::remove(partial, ec);
    throw DataError(file, "cannot rename " + partial.string() + ": " + ec.message());
  }
}

}  // namespace loopgate::io_detail
