// Errors about input data name the file, the line or frame, and what was expected.
#pragma once

#include <cstddef>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <string_view>

namespace loopgate {

// `text` quoted for an error message, capped: at most `max_chars` characters of it (control characters shown
// as '?'), and when cut, "...' (N bytes)" instead of the rest, so that a huge field never makes a huge
// message (or a huge summary.json).
std::string quote_excerpt(std::string_view text, std::size_t max_chars = 64);

// Thrown for bad input. what() reads "FILE:LINE: MESSAGE" (or "FILE: MESSAGE" without a line, or line 0).
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
