#include "core/error.hpp"

namespace loopgate {

std::string quote_excerpt(std::string_view text, std::size_t max_chars) {
  const bool cut = text.size() > max_chars;
  std::string out = "'";
  for (const char c : text.substr(0, cut ? max_chars : text.size()))
    out += (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) ? '?' : c;
  if (cut) return out + "...' (" + std::to_string(text.size()) + " bytes)";
  return out + "'";
}

DataError::DataError(const std::filesystem::path& file, std::size_t line, const std::string& message)
    : std::runtime_error(file.string() + (line > 0 ? ":" + std::to_string(line) : std::string()) + ": " +
                         message),
      file_(file),
      line_(line),
      message_(message) {}

DataError::DataError(const std::filesystem::path& file, const std::string& message)
    : std::runtime_error(file.string() + ": " + message), file_(file), message_(message) {}

}  // namespace loopgate
