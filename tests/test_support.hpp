// Helpers shared by the tests: paths to the binary and to the shared data, temporary folders, the error a
// call throws.
#pragma once

#include <gtest/gtest.h>

#include <filesystem>
#include <string>
#include <vector>

#include "core/error.hpp"

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

// A command started in the background (fork + exec, no shell), for tests that signal it or run two at once:
// its stderr and stdout are read through a pipe, and tests wait on what it writes (an event), never on a
// timer. The destructor kills it (SIGKILL) if it still runs.
class Child {
 public:
  // `file_size_limit_bytes` > 0: RLIMIT_FSIZE of the child (every file it writes is cut there: a full disk).
  explicit Child(const std::vector<std::string>& args, long file_size_limit_bytes = 0);
  ~Child();
  Child(const Child&) = delete;
  Child& operator=(const Child&) = delete;

  // Reads the child's output until it holds `needle`; false when the child closed it (ended) first.
  bool wait_for_output(const std::string& needle);
  void send(int signal_number);
  // Reads the rest of the output and reaps the child: its exit status, or 128 + the signal that ended it.
  int wait();
  const std::string& output() const { return output_; }
  int pid() const { return pid_; }

 private:
  bool read_more();
  int pid_ = -1;
  int fd_ = -1;
  bool reaped_ = false;
  std::string output_;
};

// Runs `fn`, which must throw DataError, and returns that error (a test failure, and an empty error, when it
// throws none).
template <class Fn>
DataError catch_data_error(Fn&& fn) {
  try {
    fn();
  } catch (const DataError& e) {
    return e;
  }
  ADD_FAILURE() << "expected a DataError";
  return DataError("", "none");
}

}  // namespace loopgate::testing

#define LOOPGATE_REQUIRE_SHARED_DATA(rel)                                                    \
  do {                                                                                       \
    if (::loopgate::testing::shared_data_dir().empty() ||                                    \
        !std::filesystem::exists(::loopgate::testing::shared_data_dir() / (rel))) {          \
      GTEST_SKIP() << "shared data absent: " << (rel) << " (expected under ../shared/data)"; \
    }                                                                                        \
  } while (0)
