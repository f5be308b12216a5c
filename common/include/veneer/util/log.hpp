#pragma once
// Logging with a category per component ("Camera", "Lamps", "Server", ...),
// each a spdlog logger whose level can be set at run time:
//   VENEER_LOG="Camera=debug,Lamps=warn"  or  veneer::log::set_levels("...").
#include <memory>
#include <string>

#include <spdlog/spdlog.h>

namespace veneer::log {

// The logger for a category, created on first use (thread-safe).
std::shared_ptr<spdlog::logger> get(const std::string& category);

// "Cat=level,Cat2=level,level" — a bare level applies to every category.
void set_levels(const std::string& spec);

}  // namespace veneer::log

#define VLOG_DEBUG(cat, ...) ::veneer::log::get(cat)->debug(__VA_ARGS__)
#define VLOG_INFO(cat, ...) ::veneer::log::get(cat)->info(__VA_ARGS__)
#define VLOG_WARN(cat, ...) ::veneer::log::get(cat)->warn(__VA_ARGS__)
#define VLOG_ERROR(cat, ...) ::veneer::log::get(cat)->error(__VA_ARGS__)
