#include "core/error.hpp"

namespace loopgate {

DataError::DataError(const std::filesystem::path& file, std::size_t line, const std::string& message)
    : std::runtime_error(file.string() + ":" + std::to_string(line) + ": " + message),
      file_(file),
      line_(line),
      message_(message) {}

DataError::DataError(const std::filesystem::path& file, const std::string& message)
    : std::runtime_error(file.string() + ": " + message), file_(file), message_(message) {}

}  // namespace loopgate
