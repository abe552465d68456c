#include "io/file_guard.hpp"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "core/error.hpp"

namespace loopgate {

namespace fs = std::filesystem;

namespace {

const char* kind_of(fs::file_type type) {
  switch (type) {
    case fs::file_type::directory: return "a directory";
    case fs::file_type::fifo: return "a FIFO (named pipe)";
    case fs::file_type::socket: return "a socket";
    case fs::file_type::block: return "a block device";
    case fs::file_type::character: return "a character device";
    default: return "not a regular file";
  }
}

}  // namespace

void require_regular_file(const fs::path& file, const std::string& what) {
  std::error_code ec;
  const fs::file_status status = fs::status(file, ec);
  if (status.type() == fs::file_type::not_found) throw DataError(file, what + " not found");
  if (ec) throw DataError(file, what + ": " + ec.message());
  if (status.type() != fs::file_type::regular) {
    throw DataError(file, what + " is " + kind_of(status.type()) + ", expected a regular file");
  }
}

bool same_file(const fs::path& a, const fs::path& b) {
  std::error_code ec_a, ec_b;
  const fs::path ca = fs::weakly_canonical(fs::absolute(a, ec_a), ec_a);
  const fs::path cb = fs::weakly_canonical(fs::absolute(b, ec_b), ec_b);
  if (!ec_a && !ec_b && ca == cb) return true;
  std::error_code ec;
  return fs::exists(a, ec) && fs::exists(b, ec) && fs::equivalent(a, b, ec) && !ec;
}

bool path_inside(const fs::path& path, const fs::path& dir) {
  std::error_code ec;
  const fs::path p = fs::weakly_canonical(fs::absolute(path, ec), ec);
  const fs::path d = fs::weakly_canonical(fs::absolute(dir, ec), ec);
  if (ec) return false;
  auto pi = p.begin();
  for (auto di = d.begin(); di != d.end(); ++di, ++pi) {
    if (di->empty()) continue;  // a trailing separator
    if (pi == p.end() || *pi != *di) return false;
  }
  return true;
}

void refuse_outputs_over_inputs(const std::vector<NamedPath>& outputs, const std::vector<NamedPath>& inputs) {
  for (const NamedPath& out : outputs) {
    for (const NamedPath& in : inputs) {
      if (in.path.empty() || out.path.empty() || !same_file(out.path, in.path)) continue;
      throw ConfigError(out.what + " " + out.path.string() + " is also " + in.what + " (" + in.path.string() +
                        "): it would be overwritten while it is read; copy the input elsewhere or choose "
                        "another output");
    }
  }
}

namespace {

// The note of the command that holds the lock file `file` when another process holds it; empty when the file
// is absent, unlocked, or held by this process (a compare locks its folder, then each method folder in it).
std::string held_by_another_process(const fs::path& file) {
  const int fd = ::open(file.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return "";
  char buffer[256] = {};
  const ssize_t n = ::pread(fd, buffer, sizeof(buffer) - 1, 0);
  std::string who = n > 0 ? std::string(buffer, static_cast<std::size_t>(n)) : std::string();
  while (!who.empty() && (who.back() == '\n' || who.back() == ' ')) who.pop_back();
  const bool ours = who.rfind("pid " + std::to_string(::getpid()) + ":", 0) == 0;
  bool held = false;
  if (!ours && ::flock(fd, LOCK_SH | LOCK_NB) != 0) {
    held = errno == EWOULDBLOCK;
  } else if (!ours) {
    ::flock(fd, LOCK_UN);
  }
  ::close(fd);
  return held ? (who.empty() ? std::string("another process") : who) : std::string();
}

}  // namespace

OutputLock::OutputLock(const fs::path& dir, const std::string& holder) : file_(dir / kFileName) {
  // One writer per folder, nested folders too: a folder inside one that another command holds (a compare's
  // method folder, OUT/full) belongs to that command.
  {
    std::error_code abs_ec;
    const fs::path absolute = fs::weakly_canonical(fs::absolute(dir, abs_ec), abs_ec);
    for (fs::path up = absolute.parent_path(); !up.empty() && up != up.parent_path(); up = up.parent_path()) {
      const std::string who = held_by_another_process(up / kFileName);
      if (!who.empty()) {
        throw DataError(dir, "the output folder is inside " + up.string() +
                                 ", which another loopgate command is writing (" + who +
                                 "): wait for it to finish or choose another --out");
      }
    }
  }
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) throw DataError(dir, "cannot create the output folder: " + ec.message());
  if (!fs::is_directory(dir, ec)) throw DataError(dir, "the output folder is not a directory");
  // The file may be unlinked by the holder between our open() and flock(): then the lock we got is on a
  // file nobody else will open, so try again until the lock is on the file that is in the folder.
  for (;;) {
    const int fd = ::open(file_.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    if (fd < 0) throw DataError(file_, std::string("cannot create the lock file: ") + std::strerror(errno));
    if (::flock(fd, LOCK_EX | LOCK_NB) != 0) {
      const int error = errno;
      char buffer[256] = {};
      const ssize_t n = ::pread(fd, buffer, sizeof(buffer) - 1, 0);
      ::close(fd);
      if (error == EWOULDBLOCK) {
        std::string who =
            n > 0 ? std::string(buffer, static_cast<std::size_t>(n)) : std::string("another process");
        while (!who.empty() && (who.back() == '\n' || who.back() == ' ')) who.pop_back();
        throw DataError(dir, "the output folder is in use by another loopgate command (" + who +
                                 "): wait for it to finish or choose another --out");
      }
      throw DataError(file_, std::string("cannot lock: ") + std::strerror(error));
    }
    struct stat held {};
    struct stat named {};
    if (::fstat(fd, &held) == 0 && ::stat(file_.c_str(), &named) == 0 && held.st_dev == named.st_dev &&
        held.st_ino == named.st_ino) {
      fd_ = fd;
      break;
    }
    ::close(fd);
  }
  const std::string text = "pid " + std::to_string(::getpid()) + ": " + holder + "\n";
  if (::ftruncate(fd_, 0) != 0 || ::pwrite(fd_, text.data(), text.size(), 0) < 0) {
    // The lock holds without the note; only the message of a second command is less precise.
  }
}

OutputLock::~OutputLock() {
  if (fd_ < 0) return;
  ::unlink(file_.c_str());  // while still holding the lock (see the constructor's loop)
  ::close(fd_);
}

}  // namespace loopgate
