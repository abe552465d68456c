// Errors about input data name the file, the line or frame, and what was expected.
#pragma once

#include <cstddef>
#include <filesystem>
#include <stdexcept>
#include <string>

namespace loopgate {

// Thrown for bad input. what() reads "FILE:LINE: MESSAGE" (or "FILE: MESSAGE" without a line).
class DataError : public std::runtime_error {
 public:
  DataError(const std::filesystem::path& file, std::size_t line, const std::string& message);
  DataError(const std::filesystem::path& file, const std::string& message);

  const std::filesystem::path& file() const { return file_; }
  std::size_t line() const { return line_; }  // 0 when not tied to a line
  const std::string& message() const { return message_; }

 private:
  std::filesystem::path file_;
  std::size_t line_ = 0;
  std::string message_;
};

// Thrown for a bad configuration key or value; what() names the key.
class ConfigError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

}  // namespace loopgate
