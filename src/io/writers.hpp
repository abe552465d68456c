// Streaming writers for run outputs: CSV tables, TUM trajectories, JSON documents and Chrome trace-event
// files (which Perfetto and chrome://tracing open). Rows are written as they come so that the outputs of
// an interrupted run stay readable; every writer throws DataError naming the file when it cannot write.
#pragma once

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/types.hpp"

namespace loopgate {

// Formats a double in fixed notation with `decimals` digits ("nan" / "inf" kept as such).
std::string format_fixed(double value, int decimals);

// A CSV file with a header row. Cells containing a comma, quote or newline are quoted (RFC 4180).
class CsvWriter {
 public:
  CsvWriter() = default;
  CsvWriter(const std::filesystem::path& file, const std::vector<std::string>& columns);
  void open(const std::filesystem::path& file, const std::vector<std::string>& columns);
  bool is_open() const { return out_.is_open(); }

  // Throws DataError when the number of cells differs from the number of columns.
  void write_row(const std::vector<std::string>& cells);
  void flush();
  void close();
  std::size_t columns() const { return columns_; }

 private:
  std::filesystem::path file_;
  std::ofstream out_;
  std::size_t columns_ = 0;
};

// A TUM trajectory written pose by pose: "t_s tx ty tz qx qy qz qw".
class TumWriter {
 public:
  TumWriter() = default;
  explicit TumWriter(const std::filesystem::path& file);
  void open(const std::filesystem::path& file);
  void write(Timestamp t_ns, const Eigen::Isometry3d& T_w_b);
  void flush();
  void close();

 private:
  std::filesystem::path file_;
  std::ofstream out_;
};

// Writes `json` (indented) to `file` through a temporary file and a rename, so readers never see half.
void write_json_file(const std::filesystem::path& file, const nlohmann::json& json);

// One complete ("X") event of the Chrome trace-event format: a span on a thread track.
struct TraceEvent {
  std::string name;
  std::string category;
  double start_us = 0;
  double duration_us = 0;
  int thread_id = 0;
  std::int64_t seq = -1;    // written into args when >= 0
  std::int64_t frame = -1;  // written into args when >= 0
};

// Collects trace events and writes {"traceEvents": [...], "displayTimeUnit": "ms"} with thread names.
class TraceWriter {
 public:
  void add(TraceEvent event) { events_.push_back(std::move(event)); }
  void name_thread(int thread_id, const std::string& name);
  std::size_t size() const { return events_.size(); }
  void write(const std::filesystem::path& file) const;

 private:
  std::vector<TraceEvent> events_;
  std::vector<std::pair<int, std::string>> thread_names_;
};

}  // namespace loopgate
