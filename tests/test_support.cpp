#include "test_support.hpp"

#include <fcntl.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <mutex>
#include <random>
#include <sstream>
#include <stdexcept>
#include <vector>

namespace loopgate::testing {

namespace {
std::mutex g_dirs_mutex;
std::vector<std::filesystem::path> g_dirs;
void remove_temp_dirs() {
  if (std::getenv("LOOPGATE_KEEP_TEST_DIRS")) return;
  std::error_code ec;
  for (const auto& dir : g_dirs) std::filesystem::remove_all(dir, ec);
}
}  // namespace

std::filesystem::path shared_data_dir() {
  const std::filesystem::path dir = LOOPGATE_SHARED_DATA_DIR;
  std::error_code ec;
  return std::filesystem::is_directory(dir, ec) ? std::filesystem::canonical(dir) : std::filesystem::path{};
}

std::filesystem::path make_temp_dir(const std::string& tag) {
  std::lock_guard lock(g_dirs_mutex);
  static bool registered = false;
  if (!registered) {
    std::atexit(remove_temp_dirs);
    registered = true;
  }
  std::random_device rd;
  const auto dir = std::filesystem::temp_directory_path() /
                   ("loopgate-" + tag + "-" + std::to_string(::getpid()) + "-" + std::to_string(rd()));
  std::filesystem::create_directories(dir);
  g_dirs.push_back(dir);
  return dir;
}

std::filesystem::path loopgate_binary() {
  return LOOPGATE_BINARY;
}

int run_command(const std::string& command, std::string* output) {
  const std::string full = command + " 2>&1";
  FILE* pipe = ::popen(full.c_str(), "r");
  if (!pipe) return -1;
  std::array<char, 4096> buffer{};
  std::string captured;
  while (std::fgets(buffer.data(), static_cast<int>(buffer.size()), pipe)) captured += buffer.data();
  const int status = ::pclose(pipe);
  if (output) *output = captured;
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

std::string read_file(const std::filesystem::path& file) {
  std::ifstream in(file);
  std::stringstream buffer;
  buffer << in.rdbuf();
  return buffer.str();
}

std::vector<std::vector<std::string>> read_csv(const std::filesystem::path& file,
                                               std::vector<std::string>* header) {
  std::vector<std::vector<std::string>> rows;
  std::istringstream in(read_file(file));
  std::string line;
  bool first = true;
  while (std::getline(in, line)) {
    std::vector<std::string> cells(1);
    bool quoted = false;
    for (const char c : line) {
      if (c == '"') {
        quoted = !quoted;
      } else if (c == ',' && !quoted) {
        cells.emplace_back();
      } else {
        cells.back() += c;
      }
    }
    if (first) {
      first = false;
      if (header) *header = cells;
      continue;
    }
    rows.push_back(cells);
  }
  return rows;
}

std::size_t column_index(const std::vector<std::string>& header, const std::string& name) {
  const auto it = std::find(header.begin(), header.end(), name);
  if (it == header.end()) throw std::runtime_error("no column " + name);
  return static_cast<std::size_t>(it - header.begin());
}

Child::Child(const std::vector<std::string>& args, long file_size_limit_bytes) {
  int fds[2];
  if (::pipe2(fds, O_CLOEXEC) != 0) throw std::runtime_error("pipe failed");
  std::vector<std::string> copy = args;
  std::vector<char*> argv;
  for (auto& a : copy) argv.push_back(a.data());
  argv.push_back(nullptr);
  pid_ = ::fork();
  if (pid_ < 0) throw std::runtime_error("fork failed");
  if (pid_ == 0) {
    ::dup2(fds[1], STDOUT_FILENO);
    ::dup2(fds[1], STDERR_FILENO);
    if (file_size_limit_bytes > 0) {
      const rlimit limit{static_cast<rlim_t>(file_size_limit_bytes),
                         static_cast<rlim_t>(file_size_limit_bytes)};
      ::setrlimit(RLIMIT_FSIZE, &limit);
    }
    ::execv(argv[0], argv.data());
    ::_exit(127);
  }
  ::close(fds[1]);
  fd_ = fds[0];
}

Child::~Child() {
  if (!reaped_ && pid_ > 0) {
    ::kill(pid_, SIGKILL);
    int status = 0;
    ::waitpid(pid_, &status, 0);
  }
  if (fd_ >= 0) ::close(fd_);
}

bool Child::read_more() {
  char buffer[4096];
  const ssize_t n = ::read(fd_, buffer, sizeof(buffer));
  if (n <= 0) return false;
  output_.append(buffer, static_cast<std::size_t>(n));
  return true;
}

bool Child::wait_for_output(const std::string& needle) {
  while (output_.find(needle) == std::string::npos) {
    if (!read_more()) return false;
  }
  return true;
}

void Child::send(int signal_number) {
  if (!reaped_) ::kill(pid_, signal_number);
}

int Child::wait() {
  while (read_more()) {
  }
  int status = 0;
  if (!reaped_) ::waitpid(pid_, &status, 0);
  reaped_ = true;
  if (WIFEXITED(status)) return WEXITSTATUS(status);
  if (WIFSIGNALED(status)) return 128 + WTERMSIG(status);
  return -1;
}

}  // namespace loopgate::testing
