// UTC time stamps as text (utc_time.hpp).
#include "veneer/util/utc_time.hpp"

namespace veneer {

std::string utc_time(std::time_t t, const char* format) {
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  return std::strftime(buf, sizeof buf, format, &tm) ? std::string(buf) : std::string();
}

std::string utc_now(const char* format) { return utc_time(std::time(nullptr), format); }

}  // namespace veneer
