// Streaming writers for run outputs: CSV tables, TUM trajectories, JSON documents and Chrome trace-event
// files (which Perfetto and chrome://tracing open). Every file is whole or absent: it is written
// under a temporary name (FILE.partial, rows streamed as they come, flushed now and then, so that a killed
// process leaves what it had under that name) and renamed to FILE by close() once complete; a writer
// destroyed without close(), or whose close() fails, removes its temporary file. Every writer throws
// DataError naming the file and the system's reason when it cannot write (a full disk).
#pragma once

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <mutex>
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

  ~CsvWriter();
  CsvWriter(const CsvWriter&) = delete;
  CsvWriter& operator=(const CsvWriter&) = delete;

  // Throws DataError when the number of cells differs from the number of columns.
  void write_row(const std::vector<std::string>& cells);
  void flush();
  // Completes the file: flush, close, rename FILE.partial to FILE. Throws DataError (the temporary file then
  // removed) when that fails.
  void close();
  // Gives the file up: FILE.partial removed, FILE not written.
  void abandon();
  std::size_t columns() const { return columns_; }
  const std::filesystem::path& file() const { return file_; }

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
  ~TumWriter();
  TumWriter(const TumWriter&) = delete;
  TumWriter& operator=(const TumWriter&) = delete;
  void open(const std::filesystem::path& file);
  void write(Timestamp t_ns, const Eigen::Isometry3d& T_w_b);
  void flush();
  void close();    // as CsvWriter::close()
  void abandon();  // as CsvWriter::abandon()

 private:
  std::filesystem::path file_;
  std::ofstream out_;
};

// Writes `json` (indented) to `file` through a temporary file and a rename, so readers never see half.
// Throws DataError naming the file (the temporary file removed) when it cannot.
void write_json_file(const std::filesystem::path& file, const nlohmann::json& json);

// The temporary name of an output being written: FILE.PID.partial, unique per process, so that two
// processes never write one temporary file.
std::filesystem::path partial_path(const std::filesystem::path& file);

// One event of the Chrome trace-event format: a span ("X", start and duration) or an instant ("i", at
// start_us) on a thread track.
struct TraceEvent {
  std::string name;
  std::string category;
  double start_us = 0;
  double duration_us = 0;
  int thread_id = 0;
  std::int64_t seq = -1;    // written into args when >= 0
  std::int64_t frame = -1;  // written into args when >= 0
  char phase = 'X';         // 'X' span, 'i' instant
  std::string detail;       // written into args when not empty
};

// Collects trace events and writes {"traceEvents": [...], "displayTimeUnit": "ms"} with the process and
// thread names. add() may be called from several threads at once.
class TraceWriter {
 public:
  void add(TraceEvent event);
  void name_process(const std::string& name) { process_name_ = name; }
  void name_thread(int thread_id, const std::string& name);
  std::size_t size() const;
  void write(const std::filesystem::path& file) const;

 private:
  mutable std::mutex mutex_;
  std::vector<TraceEvent> events_;
  std::string process_name_;
  std::vector<std::pair<int, std::string>> thread_names_;
};

}  // namespace loopgate
