// UTC time stamps as text (utc_time.hpp).
#include "veneer/util/utc_time.hpp"

#include <atomic>

namespace veneer {

std::string utc_time(std::time_t t, const char* format) {
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  return std::strftime(buf, sizeof buf, format, &tm) ? std::string(buf) : std::string();
}

namespace {
std::atomic<long long> g_wall_step{0};  // [s]
}  // namespace

std::time_t wall_now() { return std::time(nullptr) + static_cast<std::time_t>(g_wall_step.load()); }

void step_wall_clock(long long seconds) { g_wall_step += seconds; }

std::string utc_now(const char* format) { return utc_time(wall_now(), format); }

}  // namespace veneer
