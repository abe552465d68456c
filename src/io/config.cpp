#include "io/config.hpp"

#include <spdlog/spdlog.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <fstream>
#include <sstream>

#include "io/file_guard.hpp"

namespace loopgate {

namespace {

std::string join(const std::vector<std::string>& items, const std::string& separator) {
  std::string out;
  for (std::size_t i = 0; i < items.size(); ++i) out += (i ? separator : "") + items[i];
  return out;
}

std::string trim(const std::string& text) {
  std::size_t begin = 0;
  std::size_t end = text.size();
  while (begin < end && std::isspace(static_cast<unsigned char>(text[begin]))) ++begin;
  while (end > begin && std::isspace(static_cast<unsigned char>(text[end - 1]))) --end;
  return text.substr(begin, end - begin);
}

std::string where(const std::string& origin) {
  return origin.empty() ? std::string{} : " (" + origin + ")";
}

[[noreturn]] void throw_type(const std::string& name, const RawConfigValue& value, const char* type) {
  throw ConfigError(name + ": expected " + type + ", got " + quote_excerpt(value.text) + where(value.origin));
}

std::string mark_origin(const std::string& origin, const YAML::Mark& mark) {
  return origin + ":" + std::to_string(mark.line + 1);
}

RawConfig parse_yaml(const std::string& text, const std::string& origin) {
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    throw ConfigError(origin + ":" + std::to_string(e.mark.line + 1) + ": invalid YAML: " + e.msg);
  }
  RawConfig raw;
  if (!root || root.IsNull()) return raw;
  if (!root.IsMap()) {
    throw ConfigError(origin + ": expected a mapping of sections (section: {key: value})");
  }
  // yaml-cpp keeps both entries of a key given twice, and the last one would silently win: an error, naming
  // both lines.
  std::map<std::string, std::string> section_origin;
  std::map<std::string, std::string> key_origin;
  for (const auto& section : root) {
    const std::string section_name = section.first.as<std::string>();
    const YAML::Node& body = section.second;
    const std::string section_at = mark_origin(origin, section.first.Mark());
    if (const auto [it, fresh] = section_origin.emplace(section_name, section_at); !fresh) {
      throw ConfigError(section_name + ": section given twice, at " + it->second + " and " + section_at +
                        " (each section once; a later one would silently replace keys of the first)");
    }
    if (body.IsNull()) continue;
    if (!body.IsMap()) {
      throw ConfigError(section_name + ": expected a mapping of key: value" +
                        where(mark_origin(origin, body.Mark())));
    }
    for (const auto& entry : body) {
      const std::string key = entry.first.as<std::string>();
      const YAML::Node& value = entry.second;
      const std::string value_origin = mark_origin(origin, value.Mark());
      const std::string key_at = mark_origin(origin, entry.first.Mark());
      if (const auto [it, fresh] = key_origin.emplace(section_name + "." + key, key_at); !fresh) {
        throw ConfigError(section_name + "." + key + ": key given twice, at " + it->second + " and " +
                          key_at + " (each key once; the last value would silently win)");
      }
      if (value.IsNull()) {
        raw.set(section_name, key, "", value_origin);
      } else if (value.IsScalar()) {
        raw.set(section_name, key, value.Scalar(), value_origin);
      } else {
        throw ConfigError(section_name + "." + key + ": expected a scalar value" + where(value_origin));
      }
    }
  }
  return raw;
}

}  // namespace

namespace {
// The keys whose values are paths, and for the one read only when another key holds a given word, that key
// and word: a config naming a trajectory file still runs with `--set odometry.source=ekf` where that file is
// absent.
struct PathKey {
  const char* name;
  const char* read_when_key = nullptr;
  const char* read_when_word = nullptr;
};
constexpr PathKey kPathKeys[] = {{"run.dataset"},
                                 {"odometry.file", "odometry.source", "file"},
                                 {"dataset.bag_asl_dir"},
                                 {"dataset.calibration"},
                                 {"eval.truth_pairs_file"}};
}  // namespace

const std::vector<std::string>& config_path_keys() {
  static const std::vector<std::string> keys = [] {
    std::vector<std::string> out;
    for (const PathKey& k : kPathKeys) out.emplace_back(k.name);
    return out;
  }();
  return keys;
}

namespace {
// The value of "section.key" in `sections` (const or not); nullptr when absent.
template <class Sections>
auto* find_value(Sections& sections, const std::string& name) {
  const std::size_t dot = name.find('.');
  const auto section = sections.find(name.substr(0, dot));
  decltype(&section->second.begin()->second) none = nullptr;
  if (section == sections.end()) return none;
  const auto value = section->second.find(name.substr(dot + 1));
  return value == section->second.end() ? none : &value->second;
}
}  // namespace

RawConfig RawConfig::from_yaml_file(const std::filesystem::path& file) {
  std::error_code ec;
  if (!std::filesystem::exists(file, ec)) throw ConfigError(file.string() + ": configuration file not found");
  try {
    require_regular_file(file, "the configuration file");  // a FIFO would block open() forever
  } catch (const DataError& e) {
    throw ConfigError(e.what());
  }
  std::ifstream in(file);
  if (!in) throw ConfigError(file.string() + ": cannot read the configuration file");
  std::stringstream buffer;
  buffer << in.rdbuf();
  RawConfig raw = parse_yaml(buffer.str(), file.string());
  // Paths in a YAML file are relative to the file's folder, so a config works from any working directory.
  const std::filesystem::path folder = std::filesystem::absolute(file, ec).parent_path();
  for (const std::string& name : config_path_keys()) {
    RawConfigValue* value = find_value(raw.sections_, name);
    if (value == nullptr || value->text.empty()) continue;
    const std::filesystem::path written(value->text);
    if (written.is_absolute()) continue;
    value->written = value->text;
    value->text = (folder / written).lexically_normal().string();
  }
  return raw;
}

const RawConfigValue* RawConfig::find(const std::string& name) const {
  return find_value(sections_, name);
}

void RawConfig::require_resolved_paths_exist() const {
  for (const PathKey& key : kPathKeys) {
    const std::string name = key.name;
    const RawConfigValue* value = find(name);
    if (value == nullptr || value->written.empty()) continue;
    if (key.read_when_key != nullptr) {  // read only when another key holds a given word
      const RawConfigValue* chooser = find(key.read_when_key);
      if (chooser == nullptr || chooser->text != key.read_when_word) continue;
    }
    std::error_code ec;
    if (std::filesystem::exists(value->text, ec)) continue;
    throw ConfigError(name + ": '" + value->written + "' (" + value->origin +
                      ") names nothing: relative to the configuration file's folder it is " + value->text +
                      " (a path in a YAML config is relative to that file; give an absolute path, or pass "
                      "it with --set " +
                      name + "=PATH or --dataset, which are relative to the working directory)");
  }
}

RawConfig RawConfig::from_yaml_string(const std::string& text, const std::string& origin) {
  return parse_yaml(text, origin);
}

void RawConfig::set(const std::string& section, const std::string& key, const std::string& value,
                    const std::string& origin) {
  sections_[section][key] = RawConfigValue{value, origin, {}};
}

void RawConfig::apply_override(const std::string& assignment) {
  const auto equals = assignment.find('=');
  const std::string name = trim(assignment.substr(0, equals));
  const auto dot = name.find('.');
  if (equals == std::string::npos || dot == std::string::npos || dot == 0 || dot + 1 == name.size()) {
    throw ConfigError("--set " + quote_excerpt(assignment) + ": expected section.key=value");
  }
  constexpr std::size_t kMaxOriginChars = 80;  // the origin is quoted in every error about this value
  const std::string shown =
      assignment.size() > kMaxOriginChars ? assignment.substr(0, kMaxOriginChars) + "..." : assignment;
  set(name.substr(0, dot), name.substr(dot + 1), trim(assignment.substr(equals + 1)), "--set " + shown);
}

namespace config_detail {

bool parse_bool(const std::string& name, const RawConfigValue& value) {
  std::string lower = value.text;
  std::transform(lower.begin(), lower.end(), lower.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  if (lower == "true" || lower == "yes" || lower == "on" || lower == "1") return true;
  if (lower == "false" || lower == "no" || lower == "off" || lower == "0") return false;
  throw_type(name, value, "a bool (true/false)");
}

template <class T>
T parse_integer(const std::string& name, const RawConfigValue& value, const char* type) {
  const std::string text = trim(value.text);
  T out{};
  const char* begin = text.data();
  const char* end = begin + text.size();
  if (begin != end && *begin == '+') ++begin;
  const auto [ptr, ec] = std::from_chars(begin, end, out);
  if (text.empty() || ec != std::errc{} || ptr != end) throw_type(name, value, type);
  return out;
}

int parse_int(const std::string& name, const RawConfigValue& value) {
  return parse_integer<int>(name, value, "an integer (int)");
}

std::int64_t parse_int64(const std::string& name, const RawConfigValue& value) {
  return parse_integer<std::int64_t>(name, value, "an integer (int64)");
}

double parse_double(const std::string& name, const RawConfigValue& value) {
  const std::string text = trim(value.text);
  double out = 0;
  const char* begin = text.data();
  const char* end = begin + text.size();
  if (begin != end && *begin == '+') ++begin;
  const auto [ptr, ec] = std::from_chars(begin, end, out);
  if (text.empty() || ec != std::errc{} || ptr != end || !std::isfinite(out)) {
    throw_type(name, value, "a finite number (double)");
  }
  return out;
}

void throw_unknown(const std::string& what, const std::string& name, const std::string& origin,
                   const std::vector<std::string>& allowed) {
  throw ConfigError("unknown " + what + " '" + name + "'" + where(origin) +
                    "; known: " + join(allowed, ", "));
}

void throw_bad_word(const std::string& name, const RawConfigValue& value, const std::string& choices) {
  throw ConfigError(name + ": " + quote_excerpt(value.text) + " is not one of " + choices +
                    where(value.origin));
}

void rethrow_with_origin(const RawConfig& raw, const ConfigError& error) {
  const std::string what = error.what();
  const std::size_t colon = what.find(": ");
  const std::string name = what.substr(0, colon);
  const std::size_t dot = name.find('.');
  if (colon != std::string::npos && dot != std::string::npos && name.find(' ') == std::string::npos) {
    const auto section = raw.sections().find(name.substr(0, dot));
    if (section != raw.sections().end()) {
      const auto key = section->second.find(name.substr(dot + 1));
      if (key != section->second.end() && !key->second.origin.empty() &&
          what.find("(" + key->second.origin + ")") == std::string::npos) {
        throw ConfigError(what + " (" + key->second.origin + ")");
      }
    }
  }
  throw error;
}

std::string format_value(bool value) {
  return value ? "true" : "false";
}
std::string format_value(int value) {
  return std::to_string(value);
}
std::string format_value(std::int64_t value) {
  return std::to_string(value);
}
std::string format_value(double value) {
  char buffer[64];
  const auto [ptr, ec] = std::to_chars(buffer, buffer + sizeof(buffer), value);
  return ec == std::errc{} ? std::string(buffer, ptr) : std::string("nan");
}
std::string format_value(const std::string& value) {
  return "'" + value + "'";
}

}  // namespace config_detail

void log_config_lines(const std::vector<std::string>& lines) {
  spdlog::debug("configuration:");
  for (const auto& line : lines) spdlog::debug("  {}", line);
}

std::string config_yaml_text(const nlohmann::json& sections, const std::string& header) {
  std::string text;
  std::istringstream lines(header);
  for (std::string line; std::getline(lines, line);) text += "# " + line + "\n";
  const auto& path_keys = config_path_keys();
  for (const auto& [section, fields] : sections.items()) {
    text += section + ":\n";
    for (const auto& [key, value] : fields.items()) {
      // Paths absolute: the file is read again from its own folder, where a relative path would move.
      const bool path = std::find(path_keys.begin(), path_keys.end(), section + "." + key) != path_keys.end();
      if (path && value.is_string() && !value.get<std::string>().empty()) {
        std::error_code ec;
        const std::filesystem::path absolute = std::filesystem::absolute(value.get<std::string>(), ec);
        text += "  " + key + ": " + nlohmann::json(absolute.lexically_normal().string()).dump() + "\n";
      } else {
        text += "  " + key + ": " + value.dump() + "\n";
      }
    }
  }
  return text;
}

void write_config_yaml(const std::filesystem::path& file, const nlohmann::json& sections,
                       const std::string& header) {
  const std::string text = config_yaml_text(sections, header);
  std::ofstream out(file, std::ios::binary | std::ios::trunc);
  out << text;
  out.flush();
  if (!out)
    throw std::runtime_error(file.string() +
                             ": cannot write the configuration (disk full or no permission?)");
}

}  // namespace loopgate
