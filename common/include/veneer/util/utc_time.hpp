#pragma once
// UTC time stamps as text, the one place that formats them: a set's
// `created`, the rig's saved configuration and deleted sets (ISO 8601, the
// default format), set ids and PTP object dates (their own formats).
#include <ctime>
#include <string>

namespace veneer {

// ISO 8601 in UTC to the second, e.g. "2026-11-22T08:15:30Z".
inline constexpr const char* kIsoUtc = "%Y-%m-%dT%H:%M:%SZ";

// `t` in UTC, formatted by std::strftime's `format` (at most 31 characters out).
std::string utc_time(std::time_t t, const char* format = kIsoUtc);
// The current time, likewise.
std::string utc_now(const char* format = kIsoUtc);

}  // namespace veneer
