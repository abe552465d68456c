#include "io/provenance.hpp"

#include <spdlog/fmt/fmt.h>
#include <unistd.h>

#include <array>
#include <chrono>
#include <cstdint>
#include <ctime>
#include <mutex>

namespace loopgate {
namespace {

struct Invocation {
  std::string command_line;
  std::string start_time_utc;
};

Invocation& invocation() {
  static Invocation value;
  return value;
}

std::string shell_word(const std::string& word) {
  if (!word.empty() && word.find_first_of(" \t\n'\"\\$`*?[]{}()<>|&;#~!") == std::string::npos) return word;
  std::string out = "'";
  for (const char c : word) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return out + "'";
}

std::string utc_now_iso8601() {
  const std::time_t now = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
  std::tm utc{};
  gmtime_r(&now, &utc);
  std::array<char, 32> text{};
  std::strftime(text.data(), text.size(), "%Y-%m-%dT%H:%M:%SZ", &utc);
  return text.data();
}

std::string host_name() {
  std::array<char, 256> name{};
  if (gethostname(name.data(), name.size() - 1) != 0) return "unknown";
  return name.data();
}

}  // namespace

void record_invocation(int argc, const char* const* argv) {
  std::string line;
  for (int k = 0; k < argc; ++k) line += (k ? " " : "") + shell_word(argv[k]);
  invocation() = {line, utc_now_iso8601()};
}

std::string fnv1a_hex(const std::string& text) {
  std::uint64_t hash = 0xcbf29ce484222325ULL;
  for (const char c : text) {
    hash ^= static_cast<unsigned char>(c);
    hash *= 0x100000001b3ULL;
  }
  return fmt::format("{:016x}", hash);
}

nlohmann::json provenance_json(const nlohmann::json& effective_config) {
  return {{"version", build_version()},
          {"command_line", invocation().command_line},
          {"start_time_utc", invocation().start_time_utc},
          {"host", host_name()},
          {"config_hash", fnv1a_hex(effective_config.dump())}};
}

}  // namespace loopgate
