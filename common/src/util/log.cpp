#include "veneer/util/log.hpp"

#include <cstdlib>
#include <map>
#include <mutex>
#include <sstream>

#include <spdlog/sinks/stdout_color_sinks.h>

namespace veneer::log {
namespace {

struct Registry {
  std::mutex mutex;
  std::map<std::string, std::shared_ptr<spdlog::logger>> loggers;
  std::map<std::string, spdlog::level::level_enum> levels;  // "" = default
  bool env_read = false;
};

Registry& registry() {
  static Registry r;
  return r;
}

spdlog::level::level_enum level_for(Registry& r, const std::string& category) {
  auto it = r.levels.find(category);
  if (it != r.levels.end()) return it->second;
  it = r.levels.find("");
  return it != r.levels.end() ? it->second : spdlog::level::info;
}

void parse_into(Registry& r, const std::string& spec) {
  std::stringstream ss(spec);
  std::string item;
  while (std::getline(ss, item, ',')) {
    if (item.empty()) continue;
    auto eq = item.find('=');
    std::string cat = eq == std::string::npos ? "" : item.substr(0, eq);
    std::string lvl = eq == std::string::npos ? item : item.substr(eq + 1);
    r.levels[cat] = spdlog::level::from_str(lvl);
  }
}

}  // namespace

std::shared_ptr<spdlog::logger> get(const std::string& category) {
  Registry& r = registry();
  std::lock_guard lock(r.mutex);
  if (!r.env_read) {
    r.env_read = true;
    if (const char* env = std::getenv("VENEER_LOG")) parse_into(r, env);
  }
  auto it = r.loggers.find(category);
  if (it != r.loggers.end()) return it->second;
  static auto sink = std::make_shared<spdlog::sinks::stderr_color_sink_mt>();
  auto logger = std::make_shared<spdlog::logger>(category, sink);
  logger->set_pattern("%Y-%m-%dT%H:%M:%S.%e %^%-5l%$ [%n] %v");
  logger->set_level(level_for(r, category));
  r.loggers.emplace(category, logger);
  return logger;
}

void set_levels(const std::string& spec) {
  Registry& r = registry();
  std::lock_guard lock(r.mutex);
  parse_into(r, spec);
  for (auto& [cat, logger] : r.loggers) logger->set_level(level_for(r, cat));
}

}  // namespace veneer::log
