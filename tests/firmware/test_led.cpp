// Status-LED patterns per state.
#include <gtest/gtest.h>

#include <string>

#include "led.h"

namespace {

constexpr uint64_t ms = 1000;

// The level sampled every 50 ms over `span_ms`, as a string of 0/1.
std::string trace(vf_led_state s, uint64_t since, uint64_t span_ms) {
  std::string out;
  for (uint64_t t = 0; t < span_ms; t += 50) out += vf_led_level(s, since, since + t * ms) ? '1' : '0';
  return out;
}

TEST(Led, IdleIsSteadyOn) {
  EXPECT_EQ(trace(VF_LED_IDLE, 0, 3000), std::string(60, '1'));
  uint64_t at;
  EXPECT_FALSE(vf_led_next_change(VF_LED_IDLE, 0, 12345 * ms, &at));
}

TEST(Led, CapturingBlinksAtTwoHertz) {
  EXPECT_EQ(trace(VF_LED_CAPTURING, 7 * ms, 1000), "11111000001111100000");
}

TEST(Led, DoneFlashesThreeTimesThenStaysOn) {
  EXPECT_EQ(trace(VF_LED_DONE, 0, 1000), "11001100110011111111");
  EXPECT_EQ(vf_led_level(VF_LED_DONE, 0, 60000 * ms), 1);
  uint64_t at;
  EXPECT_FALSE(vf_led_next_change(VF_LED_DONE, 0, 700 * ms, &at));
}

TEST(Led, ErrorDoubleFlashRepeatsEverySecond) {
  std::string one = trace(VF_LED_ERROR, 0, 1000);
  EXPECT_EQ(one, "11001100000000000000");
  EXPECT_EQ(trace(VF_LED_ERROR, 0, 3000), one + one + one);
}

TEST(Led, NoCameraSlowBlink) {
  EXPECT_EQ(trace(VF_LED_NO_CAMERA, 0, 2000), std::string(20, '1') + std::string(20, '0'));
  EXPECT_EQ(vf_led_level(VF_LED_NO_CAMERA, 0, 2000 * ms), 1);
}

TEST(Led, PatternsDifferFromEachOther) {
  vf_led_state states[] = {VF_LED_IDLE, VF_LED_CAPTURING, VF_LED_DONE, VF_LED_ERROR, VF_LED_NO_CAMERA};
  for (auto a : states)
    for (auto b : states)
      if (a != b) {
        EXPECT_NE(trace(a, 0, 4000), trace(b, 0, 4000)) << vf_led_state_name(a) << " vs " << vf_led_state_name(b);
      }
}

TEST(Led, NextChangeLandsOnARealChange) {
  for (auto s : {VF_LED_CAPTURING, VF_LED_DONE, VF_LED_ERROR, VF_LED_NO_CAMERA}) {
    uint64_t now = 30 * ms;
    for (int i = 0; i < 10; ++i) {
      uint64_t at;
      if (!vf_led_next_change(s, 0, now, &at)) break;
      ASSERT_GT(at, now) << vf_led_state_name(s);
      EXPECT_NE(vf_led_level(s, 0, at), vf_led_level(s, 0, at - 1)) << vf_led_state_name(s) << " at " << at;
      // No change strictly between now and at.
      EXPECT_EQ(vf_led_level(s, 0, at - 1), vf_led_level(s, 0, now)) << vf_led_state_name(s);
      now = at;
    }
  }
  uint64_t at;
  ASSERT_TRUE(vf_led_next_change(VF_LED_ERROR, 0, 350 * ms, &at));
  EXPECT_EQ(at, 1000 * ms);  // the dark gap ends at the start of the next cycle
}

TEST(Led, TimeBeforeStateEntryCountsAsStart) {
  EXPECT_EQ(vf_led_level(VF_LED_CAPTURING, 500 * ms, 100 * ms), 1);
}

}  // namespace
