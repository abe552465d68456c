#include "pipeline/loops_writer.hpp"

#include <string>
#include <utility>

namespace loopgate {

void LoopsWriter::open(const std::filesystem::path& file, Label label_i, Label label_j) {
  label_i_ = std::move(label_i);
  label_j_ = std::move(label_j);
  csv_.open(file, {"i", "j", "t_i", "t_j", "score"});
}

void LoopsWriter::write(std::size_t frame_i, std::size_t frame_j, Timestamp t_i_ns, Timestamp t_j_ns,
                        double score) {
  const std::size_t shown_i = label_i_ ? label_i_(frame_i) : frame_i;
  const std::size_t shown_j = label_j_ ? label_j_(frame_j) : frame_j;
  csv_.write_row({std::to_string(shown_i), std::to_string(shown_j), format_fixed(ns_to_s(t_i_ns), 9),
                  format_fixed(ns_to_s(t_j_ns), 9), format_fixed(score, 6)});
  loops_.push_back(Detection{frame_i, frame_j, score});
}

void LoopsWriter::close() {
  if (csv_.is_open()) csv_.close();
}

}  // namespace loopgate
