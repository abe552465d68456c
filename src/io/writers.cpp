#include "io/writers.hpp"

#include <spdlog/fmt/fmt.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <string>

#include "core/error.hpp"

namespace loopgate {

namespace {

std::string csv_escape(const std::string& cell) {
  if (cell.find_first_of(",\"\n\r") == std::string::npos) return cell;
  std::string out = "\"";
  for (const char c : cell) {
    if (c == '"') out += '"';
    out += c;
  }
  out += '"';
  return out;
}

// The system's reason of the last failed call, e.g. "No space left on device".
std::string reason() {
  return errno != 0 ? std::string(std::strerror(errno)) : std::string("unknown error");
}

// Opens FILE.partial for `file`.
void open_stream(std::ofstream& out, const std::filesystem::path& file) {
  if (file.has_parent_path()) {
    std::error_code ec;
    std::filesystem::create_directories(file.parent_path(), ec);
  }
  errno = 0;
  out.open(partial_path(file), std::ios::out | std::ios::trunc);
  if (!out) throw DataError(file, "cannot open " + partial_path(file).string() + " for writing: " + reason());
}

void check_stream(const std::ofstream& out, const std::filesystem::path& file) {
  if (!out) throw DataError(file, "write failed: " + reason());
}

void remove_partial(std::ofstream& out, const std::filesystem::path& file) {
  if (file.empty()) return;
  if (out.is_open()) out.close();
  std::error_code ec;
  std::filesystem::remove(partial_path(file), ec);
}

// flush, close, rename FILE.partial -> FILE; on failure the temporary file is removed and DataError thrown.
void commit(std::ofstream& out, const std::filesystem::path& file) {
  if (!out.is_open()) return;
  errno = 0;
  out.flush();
  const bool flushed = static_cast<bool>(out);
  const std::string flush_reason = flushed ? std::string() : reason();
  out.close();
  if (!flushed || !out) {
    const std::string why = flushed ? reason() : flush_reason;
    remove_partial(out, file);
    throw DataError(file, "write failed: " + why);
  }
  std::error_code ec;
  std::filesystem::rename(partial_path(file), file, ec);
  if (ec) {
    remove_partial(out, file);
    throw DataError(file, "cannot rename " + partial_path(file).string() + ": " + ec.message());
  }
}

}  // namespace

std::filesystem::path partial_path(const std::filesystem::path& file) {
  std::filesystem::path partial = file;
  partial += "." + std::to_string(::getpid()) + ".partial";
  return partial;
}

std::string format_fixed(double value, int decimals) {
  if (std::isnan(value)) return "nan";
  if (std::isinf(value)) return value > 0 ? "inf" : "-inf";
  if (value == 0.0) value = 0.0;  // no "-0.000"
  return fmt::format("{:.{}f}", value, decimals);
}

CsvWriter::CsvWriter(const std::filesystem::path& file, const std::vector<std::string>& columns) {
  open(file, columns);
}

CsvWriter::~CsvWriter() {
  remove_partial(out_, out_.is_open() ? file_ : std::filesystem::path());
}

void CsvWriter::abandon() {
  remove_partial(out_, out_.is_open() ? file_ : std::filesystem::path());
}

void CsvWriter::open(const std::filesystem::path& file, const std::vector<std::string>& columns) {
  abandon();
  file_ = file;
  columns_ = columns.size();
  open_stream(out_, file);
  write_row(columns);
}

void CsvWriter::write_row(const std::vector<std::string>& cells) {
  if (cells.size() != columns_) {
    throw DataError(
        file_, "row has " + std::to_string(cells.size()) + " cells, expected " + std::to_string(columns_));
  }
  for (std::size_t i = 0; i < cells.size(); ++i) {
    if (i) out_ << ',';
    out_ << csv_escape(cells[i]);
  }
  out_ << '\n';
  check_stream(out_, file_);
}

void CsvWriter::flush() {
  errno = 0;
  out_.flush();
  check_stream(out_, file_);
}

void CsvWriter::close() {
  commit(out_, file_);
}

TumWriter::TumWriter(const std::filesystem::path& file) {
  open(file);
}

TumWriter::~TumWriter() {
  remove_partial(out_, out_.is_open() ? file_ : std::filesystem::path());
}

void TumWriter::abandon() {
  remove_partial(out_, out_.is_open() ? file_ : std::filesystem::path());
}

void TumWriter::open(const std::filesystem::path& file) {
  abandon();
  file_ = file;
  open_stream(out_, file);
}

void TumWriter::write(Timestamp t_ns, const Eigen::Isometry3d& T_w_b) {
  const Eigen::Vector3d p = T_w_b.translation();
  const Eigen::Quaterniond q(T_w_b.rotation());
  out_ << fmt::format("{:.9f} {:.9f} {:.9f} {:.9f} {:.9f} {:.9f} {:.9f} {:.9f}\n", ns_to_s(t_ns), p.x(),
                      p.y(), p.z(), q.x(), q.y(), q.z(), q.w());
  check_stream(out_, file_);
}

void TumWriter::flush() {
  errno = 0;
  out_.flush();
  check_stream(out_, file_);
}

void TumWriter::close() {
  commit(out_, file_);
}

void write_json_file(const std::filesystem::path& file, const nlohmann::json& json) {
  std::ofstream out;
  open_stream(out, file);
  // Invalid UTF-8 in a string (a file name, a quoted field) is replaced, not a reason to lose the file.
  out << json.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) << '\n';
  if (!out) {
    const std::string why = reason();
    remove_partial(out, file);
    throw DataError(file, "write failed: " + why);
  }
  commit(out, file);
}

void TraceWriter::add(TraceEvent event) {
  std::lock_guard lock(mutex_);
  events_.push_back(std::move(event));
}

void TraceWriter::name_thread(int thread_id, const std::string& name) {
  std::lock_guard lock(mutex_);
  for (auto& [tid, known] : thread_names_) {
    if (tid == thread_id) {
      known = name;
      return;
    }
  }
  thread_names_.emplace_back(thread_id, name);
}

std::size_t TraceWriter::size() const {
  std::lock_guard lock(mutex_);
  return events_.size();
}

void TraceWriter::write(const std::filesystem::path& file) const {
  std::lock_guard lock(mutex_);
  nlohmann::json events = nlohmann::json::array();
  if (!process_name_.empty()) {
    events.push_back(
        {{"name", "process_name"}, {"ph", "M"}, {"pid", 1}, {"args", {{"name", process_name_}}}});
  }
  std::vector<std::pair<int, std::string>> names = thread_names_;
  for (const auto& e : events_) {  // every other track is named by its thread index
    if (std::none_of(names.begin(), names.end(), [&](const auto& n) { return n.first == e.thread_id; }))
      names.emplace_back(e.thread_id, "thread " + std::to_string(e.thread_id));
  }
  for (const auto& [tid, name] : names) {
    events.push_back(
        {{"name", "thread_name"}, {"ph", "M"}, {"pid", 1}, {"tid", tid}, {"args", {{"name", name}}}});
  }
  for (const auto& e : events_) {
    nlohmann::json event = {{"name", e.name},   {"cat", e.category}, {"ph", std::string(1, e.phase)},
                            {"ts", e.start_us}, {"pid", 1},          {"tid", e.thread_id}};
    if (e.phase == 'X') event["dur"] = e.duration_us;
    if (e.phase == 'i') event["s"] = "t";  // an instant on its thread's track
    nlohmann::json args = nlohmann::json::object();
    if (e.seq >= 0) args["seq"] = e.seq;
    if (e.frame >= 0) args["frame"] = e.frame;
    if (!e.detail.empty()) args["detail"] = e.detail;
    event["args"] = args;
    events.push_back(std::move(event));
  }
  write_json_file(file, {{"traceEvents", events}, {"displayTimeUnit", "ms"}});
}

}  // namespace loopgate
