#include "pipeline/loops/loops_writer.hpp"

#include <string>
#include <utility>

namespace loopgate {

namespace {
const std::vector<std::string> kColumns = {"i", "j", "t_i", "t_j", "score"};
}

void LoopsWriter::open(const std::filesystem::path& file, Label label_i, Label label_j) {
  label_i_ = std::move(label_i);
  label_j_ = std::move(label_j);
  file_ = file;
  csv_.open(file, kColumns);
}

void LoopsWriter::write(std::size_t frame_i, std::size_t frame_j, Timestamp t_i_ns, Timestamp t_j_ns,
                        double score) {
  const std::size_t shown_i = label_i_ ? label_i_(frame_i) : frame_i;
  const std::size_t shown_j = label_j_ ? label_j_(frame_j) : frame_j;
  std::vector<std::string> cells = {std::to_string(shown_i), std::to_string(shown_j),
                                    format_fixed(ns_to_s(t_i_ns), 9), format_fixed(ns_to_s(t_j_ns), 9),
                                    format_fixed(score, 6)};
  csv_.write_row(cells);
  rows_.push_back(std::move(cells));
  loops_.push_back(Detection{frame_i, frame_j, score});
  if (listener_) listener_(loops_.back());
}

void LoopsWriter::close() {
  if (csv_.is_open()) csv_.close();
}

void LoopsWriter::rewrite_with(const std::vector<std::string>& columns,
                               const std::function<std::vector<std::string>(std::size_t)>& cells) {
  if (file_.empty()) return;
  std::vector<std::string> header = kColumns;
  header.insert(header.end(), columns.begin(), columns.end());
  CsvWriter csv(file_, header);
  for (std::size_t k = 0; k < rows_.size(); ++k) {
    std::vector<std::string> row = rows_[k];
    const std::vector<std::string> extra = cells(k);
    row.insert(row.end(), extra.begin(), extra.end());
    csv.write_row(row);
  }
  csv.close();
}

}  // namespace loopgate
