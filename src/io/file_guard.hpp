// Guards on the files a command reads and writes:
//  - every input is a regular file: a FIFO, socket or device given as a config or a csv would block open()
//    forever or never end;
//  - no output path is an input path: a run must not overwrite what it reads (a previous run's
//    trajectory.tum given as odometry.file, `describe --out IMAGE`, pictures written over the input images);
//  - one command at a time writes into an output folder (OutputLock).
#pragma once

#include <cstddef>
#include <filesystem>
#include <string>
#include <vector>

namespace loopgate {

// Throws DataError naming `file` when it does not exist, is a directory, or is not a regular file (after
// following symbolic links): "FILE: WHAT is a FIFO, expected a regular file".
void require_regular_file(const std::filesystem::path& file, const std::string& what = "input");

// A path with what it is, for messages ("odometry.file", "--out").
struct NamedPath {
  std::string what;
  std::filesystem::path path;
};

// True when a and b name the same file: the same path once made absolute with symbolic links resolved, or
// (both existing) the same inode.
bool same_file(const std::filesystem::path& a, const std::filesystem::path& b);

// True when `path` is `dir` or lies inside it (paths made absolute, symbolic links resolved).
bool path_inside(const std::filesystem::path& path, const std::filesystem::path& dir);

// Throws ConfigError when an output is one of the inputs: "OUTPUT_WHAT PATH is also INPUT_WHAT: it would be
// overwritten while it is read; ...".
void refuse_outputs_over_inputs(const std::vector<NamedPath>& outputs, const std::vector<NamedPath>& inputs);

// An exclusive lock on an output folder for the lifetime of the object (the folder is created when absent):
// DIR/.loopgate.lock, held with flock(). A second command writing into the same folder fails at once with a
// DataError naming the folder and the holder ("in use by pid N: loopgate run"). The lock file is removed when
// the lock is released; a lock left by a killed process is released by the kernel with it. A folder inside
// one another process holds, or one that holds a folder another process holds, is refused in the same way.
class OutputLock {
 public:
  OutputLock(const std::filesystem::path& dir, const std::string& holder);
  ~OutputLock();
  OutputLock(const OutputLock&) = delete;
  OutputLock& operator=(const OutputLock&) = delete;

  static constexpr const char* kFileName = ".loopgate.lock";
  // Entries of the folder looked at for a lock another process holds inside it.
  static constexpr std::size_t kMaxEntriesChecked = 100000;

 private:
  std::filesystem::path file_;
  int fd_ = -1;
};

}  // namespace loopgate
