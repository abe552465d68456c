// Helpers shared by the tests: paths to the binary and to the shared data, temporary folders.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

namespace loopgate::testing {

// ../shared/data, or empty when absent (tests then GTEST_SKIP with a message).
std::filesystem::path shared_data_dir();
// A fresh empty directory under the system temp dir, removed at process exit.
std::filesystem::path make_temp_dir(const std::string& tag);
// Absolute path of the built `loopgate` binary.
std::filesystem::path loopgate_binary();
// Runs a shell command, returns its exit status; stdout+stderr captured into *output if given.
int run_command(const std::string& command, std::string* output = nullptr);

// Whole file as text (empty when it cannot be read).
std::string read_file(const std::filesystem::path& file);
// Rows of a CSV file as written by loopgate (double-quoted fields may hold commas), without the header
// row, which goes to *header when given.
std::vector<std::vector<std::string>> read_csv(const std::filesystem::path& file,
                                               std::vector<std::string>* header = nullptr);
// Index of column `name` in a CSV header; throws std::runtime_error naming it when absent.
std::size_t column_index(const std::vector<std::string>& header, const std::string& name);

}  // namespace loopgate::testing

#define LOOPGATE_REQUIRE_SHARED_DATA(rel)                                                    \
  do {                                                                                       \
    if (::loopgate::testing::shared_data_dir().empty() ||                                    \
        !std::filesystem::exists(::loopgate::testing::shared_data_dir() / (rel))) {          \
      GTEST_SKIP() << "shared data absent: " << (rel) << " (expected under ../shared/data)"; \
    }                                                                                        \
  } while (0)
