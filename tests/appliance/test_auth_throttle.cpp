// The wrong-token throttle's policy, on a clock of its own (no waiting).
#include <gtest/gtest.h>

#include "veneerd/auth_throttle.hpp"

using veneerd::AuthThrottle;
using Clock = AuthThrottle::Clock;

namespace {
Clock::time_point at(double s) {
  return Clock::time_point{} + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(s));
}
double secs(Clock::duration d) { return std::chrono::duration<double>(d).count(); }
// Built by appends: gcc 12 -O3 misreports "literal" + std::string (-Wrestrict).
std::string name(const char* prefix, int i) {
  std::string s(prefix);
  s.append(std::to_string(i));
  return s;
}
}  // namespace

TEST(AuthThrottle, PeersAreAddressesAndIPv6Slash64s) {
  EXPECT_EQ(AuthThrottle::peer_key("192.0.2.7"), "192.0.2.7");
  EXPECT_EQ(AuthThrottle::peer_key("::ffff:192.0.2.7"), "192.0.2.7");
  EXPECT_EQ(AuthThrottle::peer_key("2001:db8:1:2:aaaa:bbbb:cccc:dddd"), "2001:db8:1:2::/64");
  EXPECT_EQ(AuthThrottle::peer_key("2001:db8:1:2::1"), AuthThrottle::peer_key("2001:db8:1:2:ffff::9"));
}

TEST(AuthThrottle, AfterTheFreeFailuresTurnsAreSpacedDoublingUpToTheCap) {
  AuthThrottle t;  // defaults: 3 free, 0.1 s doubling, cap 1 s
  double now = 0;
  // One connection after the other, each waiting for its turn.
  std::vector<double> waits;
  for (int i = 0; i < 12; ++i) {
    auto turn = t.admit("p", at(now));
    ASSERT_TRUE(turn);
    double wait = secs(*turn - at(now));
    waits.push_back(wait);
    now += wait;
    if (wait > 0) t.left_queue("p");
    t.failed("p", at(now));
  }
  std::vector<double> want = {0, 0, 0, 0.1, 0.2, 0.4, 0.8, 1, 1, 1, 1, 1};
  ASSERT_EQ(waits.size(), want.size());
  for (size_t i = 0; i < want.size(); ++i) EXPECT_NEAR(waits[i], want[i], 1e-6) << i;
  // Another address is not slowed by it.
  auto other = t.admit("q", at(now));
  ASSERT_TRUE(other);
  EXPECT_EQ(*other, at(now));
  // Many at once from the slowed address: in line, one per second, and no more than 8 wait.
  int refused = 0;
  double last = 0;
  for (int i = 0; i < 20; ++i) {
    auto turn = t.admit("p", at(now));
    if (!turn) {
      ++refused;
      continue;
    }
    last = secs(*turn - at(now));
  }
  EXPECT_EQ(refused, 20 - 8);  // 8 wait for turns 1 s apart, the rest are refused unread
  EXPECT_NEAR(last, 8.0, 1e-6);
  // A right token clears the record.
  for (int i = 0; i < 8; ++i) t.left_queue("p");
  t.succeeded("p");
  EXPECT_EQ(*t.admit("p", at(now + 20)), at(now + 20));
}

TEST(AuthThrottle, AThousandFailuresMakeOneSummaryLine) {
  AuthThrottle t;
  int firsts = 0, lines = 0;
  std::string summary;
  double now = 0;
  for (int i = 0; i < 1000; ++i) {
    now += 0.004;
    if (t.failed(name("10.0.0.", i % 100), at(now))) ++firsts;
    if (auto l = t.summary(at(now))) ++lines;
  }
  EXPECT_EQ(firsts, 1);
  EXPECT_EQ(lines, 0);
  std::optional<Clock::time_point> next;
  EXPECT_FALSE(t.summary(at(now + 1), &next));
  ASSERT_TRUE(next);  // asks to be asked again when the burst may be over
  auto l = t.summary(*next, &next);
  ASSERT_TRUE(l);
  EXPECT_FALSE(next);
  EXPECT_NE(l->find("1000 attempts"), std::string::npos) << *l;
  EXPECT_NE(l->find("100 address(es)"), std::string::npos) << *l;
  // A lone typo makes its first line only.
  EXPECT_TRUE(t.failed("10.0.0.1", at(now + 100)));
  EXPECT_FALSE(t.summary(at(now + 200)));
}

TEST(AuthThrottle, ALongBurstIsSummedUpEveryMinute) {
  AuthThrottle t;
  int lines = 0;
  for (int s = 0; s < 300; ++s) {
    t.failed("p", at(s));
    if (t.summary(at(s))) ++lines;
  }
  EXPECT_GE(lines, 4);
  EXPECT_LE(lines, 5);
}

TEST(AuthThrottle, RecordsStayBounded) {
  veneerd::AuthThrottleOptions o;
  o.max_peers = 100;
  AuthThrottle t(o);
  for (int i = 0; i < 10000; ++i) t.failed(name("p", i), at(i * 0.001));
  EXPECT_LE(t.peers(), 101u);
}
