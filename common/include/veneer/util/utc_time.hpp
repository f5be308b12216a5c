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
// The current time (wall_now()), likewise.
std::string utc_now(const char* format = kIsoUtc);

// The wall clock as this process reads it: the system's, plus the steps the
// simulated rig's fault plan makes (clock.step, as NTP stepping the clock
// would); std::time(nullptr) when nothing stepped it.
std::time_t wall_now();
// Steps wall_now() by `seconds` (forward or back) for this process.
void step_wall_clock(long long seconds);

}  // namespace veneer
