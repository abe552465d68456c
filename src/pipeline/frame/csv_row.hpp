// A CSV row whose columns are named where their values are made: the same code writes the header (from a
// row built once at open time) and every row, so columns and values cannot drift apart.
#pragma once

#include <string>
#include <string_view>
#include <vector>

namespace loopgate {

class CsvRow {
 public:
  void add(std::string_view name, std::string value) {
    names_.emplace_back(name);
    values_.push_back(std::move(value));
  }
  const std::vector<std::string>& names() const { return names_; }
  const std::vector<std::string>& values() const { return values_; }

 private:
  std::vector<std::string> names_;
  std::vector<std::string> values_;
};

}  // namespace loopgate
