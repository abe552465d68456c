// Private helpers of src/io: whole-file text reading with line numbers, field splitting, fast
// number parsing (std::from_chars) and shortest round-trip number formatting (std::to_chars),
// plus the strict/lenient problem log every reader reports through.
#pragma once

#include <cstddef>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "core/error.hpp"
#include "core/types.hpp"
#include "io/dataset.hpp"

namespace loopgate::io_detail {

// Where readers report problems. Strict: report() throws DataError. Lenient: report() records a
// DataIssue (when a sink is given) and returns, and the caller skips or keeps the row.
class IssueLog {
 public:
  IssueLog(bool strict, std::vector<DataIssue>* sink) : strict_(strict), sink_(sink) {}
  void report(const std::filesystem::path& file, std::size_t line, const std::string& message);
  bool strict() const { return strict_; }
  // A table read in two passes (its rows, then their time order): between begin_table() and end_table()
  // the problems are held, so that they come out in line order. end_table() then throws the problem of the
  // earliest line (strict), or records them in line order (lenient) and refuses the file when more than
  // half of its `rows` data rows are bad: lenient reading keeps the good rows of a damaged file, not the
  // rest of a bad one (DataError naming the count and the first problem). The rows of a bag are the messages
  // of one topic: `topic` names it in that error (empty: the rows are lines of `file`).
  void begin_table();
  void end_table(const std::filesystem::path& file, std::size_t rows, const std::string& topic = {});

 private:
  bool strict_ = true;
  std::vector<DataIssue>* sink_ = nullptr;
  bool in_table_ = false;
  std::vector<DataIssue> held_;  // the current table's problems
};

// Thrown by the field parsers of a Row; for_each_row() turns it into a report with the line number.
struct RowError {
  std::string message;
};

enum class Delimiter { kComma, kWhitespace };

// One data line of a text table, split into fields.
class Row {
 public:
  std::size_t line = 0;  // 1-based line number in the file
  std::vector<std::string_view> fields;

  std::size_t size() const { return fields.size(); }
  // Parsers: throw RowError naming the column and what was expected.
  double number(std::size_t column, std::string_view name) const;         // finite double
  Timestamp integer_ns(std::size_t column, std::string_view name) const;  // integer nanoseconds
  Timestamp seconds_ns(std::size_t column, std::string_view name) const;  // decimal seconds -> ns
  void expect_columns(std::size_t expected, std::string_view what) const;
};

// A text file held in memory. Throws DataError when the file is missing or unreadable.
class TextFile {
 public:
  explicit TextFile(const std::filesystem::path& file);
  const std::filesystem::path& path() const { return path_; }
  const std::string& text() const { return text_; }

 private:
  std::filesystem::path path_;
  std::string text_;
};

// Calls on_row(const Row&) for every non-empty line that is not a '#' comment. A RowError thrown by
// on_row is reported to `log` with the file and line (the row is then skipped in lenient mode); a
// malformed last line without a final newline is reported as truncated. Returns the number of data rows.
template <class OnRow>
std::size_t for_each_row(const TextFile& file, Delimiter delimiter, IssueLog& log, OnRow&& on_row);

// Splits `line` into fields (comma: fields are trimmed; whitespace: runs of blanks separate).
void split_fields(std::string_view line, Delimiter delimiter, std::vector<std::string_view>& fields);

// Decimal seconds ("1403715274.30214", "1.037359e-01") to integer ns. Plain decimals are converted
// exactly (no double rounding), exponent notation through double. Returns false when malformed.
bool parse_seconds_ns(std::string_view text, Timestamp& t_ns);

// Shortest text that parses back to exactly `value`.
void append_double(std::string& out, double value);
void append_int(std::string& out, std::int64_t value);
// Exact seconds with 9 decimals from integer ns ("12.000000500").
void append_seconds(std::string& out, Timestamp t_ns);

// Writes `text` to `file` (parent directories created). Throws DataError on failure.
void write_text_file(const std::filesystem::path& file, const std::string& text);

// ---- implementation of the template ----

template <class OnRow>
std::size_t for_each_row(const TextFile& file, Delimiter delimiter, IssueLog& log, OnRow&& on_row) {
  const std::string_view text = file.text();
  Row row;
  std::size_t pos = 0;
  std::size_t line_no = 0;
  std::size_t rows = 0;
  while (pos < text.size()) {
    ++line_no;
    const std::size_t end = text.find('\n', pos);
    const bool terminated = end != std::string_view::npos;
    std::string_view line = text.substr(pos, terminated ? end - pos : std::string_view::npos);
    pos = terminated ? end + 1 : text.size();
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    const std::size_t first = line.find_first_not_of(" \t");
    if (first == std::string_view::npos || line[first] == '#') continue;
    row.line = line_no;
    ++rows;
    split_fields(line, delimiter, row.fields);
    try {
      on_row(static_cast<const Row&>(row));
    } catch (const RowError& e) {
      log.report(file.path(), line_no,
                 terminated ? e.message : e.message + " (truncated last line: no newline at end of file)");
    }
  }
  return rows;
}

}  // namespace loopgate::io_detail
