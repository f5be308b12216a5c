// Button debounce and gestures, fed with edge sequences that bounce.
#include <gtest/gtest.h>

#include <vector>

#include "button.h"

namespace {

constexpr uint64_t ms = 1000;

struct Rig {
  vf_button b;
  explicit Rig(vf_button_config cfg = vf_button_default_config()) { vf_button_init(&b, &cfg, 0, 0); }
  // Contact bounce: `n` alternating edges 1 ms apart, ending at `level`.
  void bounce_to(int level, uint64_t t, int n = 5) {
    for (int i = 0; i < n; ++i) vf_button_edge(&b, (n - i) % 2 == 1 ? level : !level, t + i * ms);
  }
  std::vector<vf_press> drain(uint64_t until) {
    vf_button_update(&b, until);
    std::vector<vf_press> out;
    vf_button_event e;
    while (vf_button_pop(&b, &e)) out.push_back(e.press);
    return out;
  }
};

TEST(Button, DefaultsAreSane) {
  vf_button_config c = vf_button_default_config();
  EXPECT_EQ(c.debounce_us, 20 * ms);
  EXPECT_GT(c.long_press_us, c.double_gap_us);
}

TEST(Button, BounceOnPressAndReleaseGivesOneShortPress) {
  Rig r;
  r.bounce_to(1, 100 * ms);
  // Still bouncing: not yet pressed.
  vf_button_update(&r.b, 105 * ms);
  EXPECT_EQ(vf_button_level(&r.b), 0);
  vf_button_update(&r.b, 130 * ms);
  EXPECT_EQ(vf_button_level(&r.b), 1);
  r.bounce_to(0, 300 * ms, 7);
  vf_button_update(&r.b, 340 * ms);
  EXPECT_EQ(vf_button_level(&r.b), 0);
  // Nothing before the double-press window closes ...
  EXPECT_TRUE(r.drain(400 * ms).empty());
  // ... then exactly one short press.
  auto presses = r.drain(2000 * ms);
  ASSERT_EQ(presses.size(), 1u);
  EXPECT_EQ(presses[0], VF_PRESS_SHORT);
}

TEST(Button, BounceOnlyEdgesNeverCommit) {
  Rig r;
  // 50 edges each 5 ms apart: the line never holds for 20 ms.
  for (int i = 0; i < 50; ++i) vf_button_edge(&r.b, i % 2 == 0, 100 * ms + i * 5 * ms);
  vf_button_edge(&r.b, 0, 100 * ms + 50 * 5 * ms);
  EXPECT_TRUE(r.drain(5000 * ms).empty());
  EXPECT_EQ(vf_button_level(&r.b), 0);
}

TEST(Button, PressShorterThanDebounceIgnored) {
  Rig r;
  vf_button_edge(&r.b, 1, 100 * ms);
  vf_button_edge(&r.b, 0, 115 * ms);  // 15 ms < 20 ms debounce
  EXPECT_TRUE(r.drain(3000 * ms).empty());
  // Exactly the debounce time counts as a press.
  vf_button_edge(&r.b, 1, 4000 * ms);
  vf_button_edge(&r.b, 0, 4020 * ms);
  auto presses = r.drain(6000 * ms);
  ASSERT_EQ(presses.size(), 1u);
  EXPECT_EQ(presses[0], VF_PRESS_SHORT);
}

TEST(Button, LongPressReportedWhileHeldOnceOnly) {
  Rig r;
  r.bounce_to(1, 100 * ms);
  EXPECT_TRUE(r.drain(850 * ms).empty());  // 750 ms held: not long yet
  auto presses = r.drain(950 * ms);        // past 800 ms
  ASSERT_EQ(presses.size(), 1u);
  EXPECT_EQ(presses[0], VF_PRESS_LONG);
  r.bounce_to(0, 3000 * ms);
  EXPECT_TRUE(r.drain(6000 * ms).empty());  // release after a long press adds nothing
}

TEST(Button, ReleaseJustBeforeLongDeadlineIsShort) {
  Rig r;
  vf_button_edge(&r.b, 1, 0 * ms + 1);
  // Release at 790 ms; the debounce confirms it at 810 ms, after the 800 ms
  // long-press deadline. The release still wins.
  vf_button_edge(&r.b, 0, 790 * ms);
  auto presses = r.drain(3000 * ms);
  ASSERT_EQ(presses.size(), 1u);
  EXPECT_EQ(presses[0], VF_PRESS_SHORT);
}

TEST(Button, BouncedReleaseNearDeadlineStillLong) {
  Rig r;
  vf_button_edge(&r.b, 1, 1);
  vf_button_edge(&r.b, 0, 790 * ms);  // a glitch, not a release
  vf_button_edge(&r.b, 1, 795 * ms);
  auto presses = r.drain(900 * ms);
  ASSERT_EQ(presses.size(), 1u);
  EXPECT_EQ(presses[0], VF_PRESS_LONG);
}

TEST(Button, DoublePressRecognised) {
  Rig r;
  r.bounce_to(1, 100 * ms);
  r.bounce_to(0, 250 * ms);
  r.bounce_to(1, 450 * ms);  // 200 ms after release < 350 ms gap
  auto presses = r.drain(500 * ms);
  ASSERT_EQ(presses.size(), 1u);
  EXPECT_EQ(presses[0], VF_PRESS_DOUBLE);
  // Holding the second press does not turn it into a long press too.
  r.bounce_to(0, 2000 * ms);
  EXPECT_TRUE(r.drain(5000 * ms).empty());
}

TEST(Button, TwoPressesFarApartAreTwoShorts) {
  Rig r;
  r.bounce_to(1, 100 * ms);
  r.bounce_to(0, 250 * ms);
  r.bounce_to(1, 800 * ms);  // 550 ms after release > 350 ms gap
  r.bounce_to(0, 950 * ms);
  auto presses = r.drain(3000 * ms);
  ASSERT_EQ(presses.size(), 2u);
  EXPECT_EQ(presses[0], VF_PRESS_SHORT);
  EXPECT_EQ(presses[1], VF_PRESS_SHORT);
}

TEST(Button, ConfigurableTimesAndNoDoubleMode) {
  vf_button_config c{5 * ms, 200 * ms, 0};
  Rig r(c);
  vf_button_edge(&r.b, 1, 10 * ms);
  vf_button_edge(&r.b, 0, 20 * ms);  // 10 ms press, debounce 5 ms → counts
  // No double-press window: reported at the confirmed release.
  auto presses = r.drain(25 * ms);
  ASSERT_EQ(presses.size(), 1u);
  EXPECT_EQ(presses[0], VF_PRESS_SHORT);
  vf_button_edge(&r.b, 1, 100 * ms);
  presses = r.drain(310 * ms);  // 210 ms > 200 ms long press
  ASSERT_EQ(presses.size(), 1u);
  EXPECT_EQ(presses[0], VF_PRESS_LONG);
}

TEST(Button, NextDeadlineDrivesTheTimer) {
  Rig r;
  uint64_t dl = 0;
  EXPECT_FALSE(vf_button_next_deadline(&r.b, &dl));
  vf_button_edge(&r.b, 1, 100 * ms);
  ASSERT_TRUE(vf_button_next_deadline(&r.b, &dl));
  EXPECT_EQ(dl, 120 * ms);  // debounce confirmation
  vf_button_update(&r.b, dl);
  ASSERT_TRUE(vf_button_next_deadline(&r.b, &dl));
  EXPECT_EQ(dl, 900 * ms);  // long-press deadline from the edge time
  // Sleeping until each deadline (no edges) yields the long press.
  while (vf_button_next_deadline(&r.b, &dl)) vf_button_update(&r.b, dl);
  vf_button_event e;
  ASSERT_TRUE(vf_button_pop(&r.b, &e));
  EXPECT_EQ(e.press, VF_PRESS_LONG);
  EXPECT_EQ(e.at_us, 900 * ms);
}

TEST(Button, HeldAtStartIsIgnoredUntilReleased) {
  vf_button b;
  vf_button_config c = vf_button_default_config();
  vf_button_init(&b, &c, 1, 0);
  vf_button_update(&b, 5000 * ms);
  vf_button_edge(&b, 0, 6000 * ms);
  vf_button_update(&b, 9000 * ms);
  EXPECT_FALSE(vf_button_pop(&b, nullptr));
}

TEST(Button, NonMonotonicTimesDoNotUnderflow) {
  Rig r;
  vf_button_edge(&r.b, 1, 100 * ms);
  vf_button_edge(&r.b, 0, 50 * ms);  // clock went back: treated as "now"
  EXPECT_TRUE(r.drain(3000 * ms).empty());
}

}  // namespace
