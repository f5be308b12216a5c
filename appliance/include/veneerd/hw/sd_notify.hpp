#pragma once
// systemd's notify protocol for veneerd.service (Type=notify, WatchdogSec=):
// a datagram to $NOTIFY_SOCKET. Written out here (a dozen lines) so the
// daemon needs no libsystemd; every call is a no-op returning false when the
// daemon was not started by systemd.
//
//   main():   start everything, then sd_ready();
//   a timer:  every sd_watchdog_interval() / 2, sd_watchdog() — only while the
//             event loop really turns, so a hung daemon gets restarted;
//   exit:     sd_stopping().
#include <chrono>
#include <optional>
#include <string>

namespace veneerd::hw {

bool sd_notify_message(const std::string& message);  // e.g. "READY=1\nSTATUS=..."
inline bool sd_ready() { return sd_notify_message("READY=1"); }
inline bool sd_watchdog() { return sd_notify_message("WATCHDOG=1"); }
inline bool sd_stopping() { return sd_notify_message("STOPPING=1"); }
inline bool sd_status(const std::string& text) { return sd_notify_message("STATUS=" + text); }

// $WATCHDOG_USEC when set for this process ($WATCHDOG_PID matches or is unset).
std::optional<std::chrono::microseconds> sd_watchdog_interval();

}  // namespace veneerd::hw
