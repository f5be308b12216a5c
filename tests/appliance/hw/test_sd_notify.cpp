// The notify datagram reaches a socket the way systemd's does.
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <cstdlib>
#include <cstring>
#include <filesystem>

#include "veneerd/hw/sd_notify.hpp"

namespace veneerd::hw {
namespace {

TEST(SdNotify, NoSocketNoMessage) {
  ::unsetenv("NOTIFY_SOCKET");
  EXPECT_FALSE(sd_ready());
}

TEST(SdNotify, ReadyAndWatchdogArrive) {
  std::string path = (std::filesystem::temp_directory_path() / ("veneer-notify-" + std::to_string(::getpid()))).string();
  ::unlink(path.c_str());
  int fd = ::socket(AF_UNIX, SOCK_DGRAM, 0);
  ASSERT_GE(fd, 0);
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  std::strncpy(addr.sun_path, path.c_str(), sizeof(addr.sun_path) - 1);
  ASSERT_EQ(::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr), 0);
  ::setenv("NOTIFY_SOCKET", path.c_str(), 1);
  ASSERT_TRUE(sd_ready());
  ASSERT_TRUE(sd_watchdog());
  char buf[64];
  ssize_t n = ::recv(fd, buf, sizeof buf, 0);
  EXPECT_EQ(std::string(buf, size_t(n)), "READY=1");
  n = ::recv(fd, buf, sizeof buf, 0);
  EXPECT_EQ(std::string(buf, size_t(n)), "WATCHDOG=1");
  ::unsetenv("NOTIFY_SOCKET");
  ::close(fd);
  ::unlink(path.c_str());
}

TEST(SdNotify, WatchdogInterval) {
  ::setenv("WATCHDOG_USEC", "20000000", 1);
  ::unsetenv("WATCHDOG_PID");
  ASSERT_TRUE(sd_watchdog_interval().has_value());
  EXPECT_EQ(sd_watchdog_interval()->count(), 20000000);
  ::setenv("WATCHDOG_PID", "1", 1);  // meant for another process
  EXPECT_FALSE(sd_watchdog_interval().has_value());
  ::unsetenv("WATCHDOG_USEC");
  ::unsetenv("WATCHDOG_PID");
}

}  // namespace
}  // namespace veneerd::hw
