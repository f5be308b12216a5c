// The "hue" lamps backend against the bridge emulator on loopback: the real
// libcurl path, pacing, retries, errors, reachability, settle time.
#include <gtest/gtest.h>

#include <chrono>
#include <thread>

#include "veneerd/sim/hue_emulator.hpp"
#include "veneerd/hw/hue_lamps.hpp"
#include "veneerd/devices/registry.hpp"

using namespace std::chrono_literals;
using veneerd::HueBridgeEmulator;
using veneerd::hw::HueLamps;
using veneerd::hw::HueLampsOptions;
using veneerd::LampState;

namespace {

std::vector<bool> one_hot(int n, int i) {
  std::vector<bool> v(n, false);
  v[i] = true;
  return v;
}

class Lamps : public ::testing::Test {
 protected:
  void start(int apply_delay_ms = 0, int latency_ms = 0) {
    veneerd::HueEmulatorOptions o;
    o.apply_delay_ms = apply_delay_ms;
    o.latency_ms = latency_ms;
    bridge = std::make_unique<HueBridgeEmulator>(o);
    ASSERT_TRUE(bridge->start().ok());
  }
  HueLampsOptions options() const {
    HueLampsOptions o;
    o.bridge = bridge->address();
    o.key = "veneer-sim";
    o.lamps = {"1", "2", "3", "4", "5", "6", "7"};
    o.settle_ms = 0;
    o.timeout_ms = 2000;
    return o;
  }
  std::unique_ptr<HueLamps> make(const HueLampsOptions& o) {
    auto l = HueLamps::create(o);
    EXPECT_TRUE(l.ok()) << (l.ok() ? "" : l.message());
    return l.ok() ? std::move(*l) : nullptr;
  }
  void SetUp() override { start(); }
  void TearDown() override { bridge->stop(); }

  std::unique_ptr<HueBridgeEmulator> bridge;
};

}  // namespace

TEST_F(Lamps, SetReadRestore) {
  // The owner left lamps 2 (red, dim) and 5 (rig white) on.
  bridge->set_lamp("2", LampState{.on = true, .brightness = 80, .x = 0.6, .y = 0.3});
  bridge->set_lamp("5", LampState{.on = true, .brightness = 254});
  auto lamps = make(options());
  ASSERT_TRUE(lamps);
  EXPECT_EQ(lamps->count(), 7);
  auto owner = lamps->read();
  ASSERT_TRUE(owner.ok()) << owner.message();
  ASSERT_EQ(owner->size(), 7u);
  EXPECT_TRUE((*owner)[1].on);
  EXPECT_EQ((*owner)[1].brightness, 80);
  EXPECT_NEAR((*owner)[1].x, 0.6, 1e-9);
  EXPECT_TRUE((*owner)[4].on);
  EXPECT_FALSE((*owner)[0].on);

  ASSERT_TRUE(lamps->all_off().ok());
  EXPECT_EQ(bridge->on_pattern(), std::vector<bool>(7, false));
  for (int i = 0; i < 7; ++i) {
    auto st = lamps->set(one_hot(7, i), 200);
    ASSERT_TRUE(st.ok()) << st.message();
    EXPECT_EQ(bridge->on_pattern(), one_hot(7, i));
    auto s = bridge->lamp(std::to_string(i + 1));
    EXPECT_EQ(s->brightness, 200);
    EXPECT_NEAR(s->x, 0.3227, 1e-9);  // rig colour sent with every switch
  }
  auto now = lamps->read();
  ASSERT_TRUE(now.ok());
  EXPECT_TRUE((*now)[6].on);

  ASSERT_TRUE(lamps->restore(*owner).ok());
  auto back = bridge->lamps();
  for (int i = 0; i < 7; ++i) {
    EXPECT_EQ(back[i].state.on, (*owner)[i].on) << i;
    if ((*owner)[i].on) {
      EXPECT_EQ(back[i].state.brightness, (*owner)[i].brightness) << i;
      EXPECT_NEAR(back[i].state.x, (*owner)[i].x, 1e-9) << i;
      EXPECT_NEAR(back[i].state.y, (*owner)[i].y, 1e-9) << i;
    }
  }
}

TEST_F(Lamps, SwitchingToTheNextLampCostsTwoLightCommands) {
  auto lamps = make(options());
  ASSERT_TRUE(lamps->all_off().ok());
  ASSERT_TRUE(lamps->set(one_hot(7, 0)).ok());
  auto before = bridge->counters().light_commands;
  for (int i = 1; i < 7; ++i) ASSERT_TRUE(lamps->set(one_hot(7, i)).ok());
  EXPECT_EQ(bridge->counters().light_commands - before, 12u);
  // The same pattern again costs nothing.
  ASSERT_TRUE(lamps->set(one_hot(7, 6)).ok());
  EXPECT_EQ(bridge->counters().light_commands - before, 12u);
}

TEST_F(Lamps, AllOffUsesTheGroupWhenConfigured) {
  auto o = options();
  o.group = "1";
  auto lamps = make(o);
  ASSERT_TRUE(lamps->set(std::vector<bool>(7, true)).ok());
  EXPECT_EQ(bridge->on_pattern(), std::vector<bool>(7, true));
  auto lights_before = bridge->counters().light_commands;
  ASSERT_TRUE(lamps->all_off().ok());
  EXPECT_EQ(bridge->on_pattern(), std::vector<bool>(7, false));
  EXPECT_EQ(bridge->counters().group_commands, 1u);
  EXPECT_EQ(bridge->counters().light_commands, lights_before);
  // A second all-off inside the group's one-second window is paced or done per lamp, never refused.
  ASSERT_TRUE(lamps->set(one_hot(7, 3)).ok());
  ASSERT_TRUE(lamps->all_off().ok());
  EXPECT_EQ(bridge->counters().refused_rate, 0u);
  EXPECT_EQ(bridge->on_pattern(), std::vector<bool>(7, false));
}

TEST_F(Lamps, BurstThroughTheBackendIsPacedNotRefused) {
  auto lamps = make(options());
  bridge->reset_counters();
  // 7 + 24 light commands as fast as the caller can ask (lamps 1,2 / 3,4
  // alternate): more than the bridge takes in a second.
  for (int i = 0; i < 7; ++i) {
    std::vector<bool> on(7, false);
    on[(i % 2) ? 0 : 2] = true;
    on[(i % 2) ? 1 : 3] = true;
    auto st = lamps->set(on);
    ASSERT_TRUE(st.ok()) << st.message();
  }
  auto c = bridge->counters();
  EXPECT_EQ(c.refused_rate, 0u);
  EXPECT_EQ(c.refused_busy, 0u);
  EXPECT_EQ(c.light_commands, 2u + 6u * 4u);  // first call: the 2 lamps to switch on; then 2 off + 2 on
  EXPECT_GT(lamps->stats().paced_waits, 0u);
  EXPECT_EQ(lamps->stats().refused, 0u);
  EXPECT_LE(c.max_in_flight_seen, 3u);
}

TEST_F(Lamps, RefusedCommandsAreRetried) {
  auto lamps = make(options());
  bridge->fail_next(2, 503);
  auto st = lamps->set(one_hot(7, 2));
  ASSERT_TRUE(st.ok()) << st.message();
  EXPECT_EQ(bridge->on_pattern(), one_hot(7, 2));
  EXPECT_EQ(lamps->stats().refused, 2u);
  EXPECT_GE(lamps->stats().retries, 2u);

  bridge->fail_next(1, 429);
  ASSERT_TRUE(lamps->set(one_hot(7, 3)).ok());
  EXPECT_EQ(lamps->stats().refused, 3u);
  EXPECT_EQ(bridge->on_pattern(), one_hot(7, 3));
}

TEST_F(Lamps, DroppedConnectionIsRetried) {
  auto lamps = make(options());
  ASSERT_TRUE(lamps->all_off().ok());
  bridge->drop_next(1);
  auto st = lamps->set(one_hot(7, 4));
  ASSERT_TRUE(st.ok()) << st.message();
  EXPECT_EQ(bridge->on_pattern(), one_hot(7, 4));
  EXPECT_EQ(bridge->counters().dropped, 1u);
}

TEST_F(Lamps, BridgeErrorsAreClearAndBounded) {
  auto o = options();
  o.timeout_ms = 600;
  auto lamps = make(o);

  bridge->fail_next(1000, 500);
  auto st = lamps->set(one_hot(7, 0));
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.message().find("HTTP 500"), std::string::npos) << st.message();
  bridge->fail_next(0, 500);
  // Requests of the abandoned set() that were already on the wire land first.
  std::this_thread::sleep_for(300ms);

  bridge->hue_error_next(1, 901);
  st = lamps->set(one_hot(7, 1));
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.message().find("901"), std::string::npos) << st.message();

  // A bridge that keeps refusing: gives up after the timeout with the reason.
  bridge->fail_next(1000, 503);
  auto t0 = std::chrono::steady_clock::now();
  st = lamps->set(one_hot(7, 5));
  auto took = std::chrono::steady_clock::now() - t0;
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.message().find("HTTP 503"), std::string::npos) << st.message();
  EXPECT_NE(st.message().find("600 ms"), std::string::npos) << st.message();
  EXPECT_LT(took, 10s);  // hang check
  bridge->fail_next(0, 503);

  // Every connection dropped.
  bridge->drop_next(1000);
  st = lamps->set(one_hot(7, 6));
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.message().find("GET /lights"), std::string::npos) << st.message();
  EXPECT_NE(st.message().find("600 ms"), std::string::npos) << st.message();
  bridge->drop_next(0);

  // And it recovers once the bridge behaves.
  st = lamps->set(one_hot(7, 6));
  EXPECT_TRUE(st.ok()) << st.message();
  EXPECT_EQ(bridge->on_pattern(), one_hot(7, 6));
}

TEST_F(Lamps, SlowBridgeTimesOut) {
  auto o = options();
  o.timeout_ms = 300;
  auto lamps = make(o);
  bridge->set_latency(3000ms);
  auto t0 = std::chrono::steady_clock::now();
  auto st = lamps->set(one_hot(7, 0));
  auto took = std::chrono::steady_clock::now() - t0;
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.message().find("300 ms"), std::string::npos) << st.message();
  EXPECT_LT(took, 2500ms);  // gave up before the bridge would have answered
  auto r = lamps->read();
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.message().find("did not answer"), std::string::npos) << r.message();
}

TEST_F(Lamps, UnreachableLampIsNamed) {
  auto lamps = make(options());
  bridge->set_reachable("3", false);
  auto st = lamps->set(one_hot(7, 2));
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.message().find("lamp 3 (Hue id 3) is unreachable"), std::string::npos)
      << st.message();
  auto r = lamps->read();
  ASSERT_TRUE(r.ok());
  EXPECT_FALSE((*r)[2].reachable);
}

TEST_F(Lamps, UnauthorizedKeyAndUnknownLamp) {
  auto o = options();
  o.key = "not-paired";
  auto lamps = make(o);
  auto st = lamps->set(one_hot(7, 0));
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.message().find("unauthorized user"), std::string::npos) << st.message();
  EXPECT_NE(st.message().find("veneerd hue pair --address"), std::string::npos) << st.message();
  auto r = lamps->read();
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.message().find("not-paired"), std::string::npos) << r.message();

  auto o2 = options();
  o2.lamps = {"1", "2", "42"};
  auto l2 = make(o2);
  auto r2 = l2->read();
  ASSERT_FALSE(r2.ok());
  EXPECT_NE(r2.message().find("lamp 3 (Hue id 42) is not known"), std::string::npos) << r2.message();
  EXPECT_NE(r2.message().find("veneerd hue lamps"), std::string::npos) << r2.message();
}

TEST_F(Lamps, ReadBackWaitsForABridgeThatShowsChangesLate) {
  bridge->stop();
  start(/*apply_delay_ms=*/400);
  // No settle time: set() still returns only once the bridge shows the change,
  // and a change that is merely late is not sent again.
  auto lamps = make(options());
  ASSERT_TRUE(lamps->set(one_hot(7, 0)).ok());
  EXPECT_TRUE(bridge->lamp("1")->on);
  EXPECT_EQ(bridge->counters().light_commands, 1u);
  // A bridge slower than confirm_ms looks like another client undoing the
  // command: it is sent again, and the set succeeds once the bridge shows it.
  auto o = options();
  o.confirm_ms = 250;
  auto impatient = make(o);
  ASSERT_TRUE(impatient->set(one_hot(7, 1)).ok());
  EXPECT_EQ(bridge->on_pattern(), one_hot(7, 1));
  EXPECT_GT(bridge->counters().light_commands, 3u);
}

TEST_F(Lamps, ColourModesAreReadAndRestoredInTheirOwnMode) {
  using veneerd::ColourMode;
  bridge->set_lamp("1", LampState{.on = true, .brightness = 90, .mode = ColourMode::ct, .ct = 420});
  bridge->set_lamp("2", LampState{.on = true, .brightness = 200, .mode = ColourMode::hs, .hue = 30000, .sat = 180});
  bridge->set_lamp("3", LampState{.on = false, .brightness = 40, .mode = ColourMode::ct, .ct = 300});
  bridge->set_lamp("4", LampState{.on = true, .brightness = 10, .mode = ColourMode::xy, .x = 0.2, .y = 0.1});
  auto lamps = make(options());
  auto owner = lamps->read();
  ASSERT_TRUE(owner.ok()) << owner.message();
  EXPECT_EQ((*owner)[0].mode, ColourMode::ct);
  EXPECT_EQ((*owner)[0].ct, 420);
  EXPECT_EQ((*owner)[1].mode, ColourMode::hs);
  EXPECT_EQ((*owner)[1].hue, 30000);
  EXPECT_EQ((*owner)[1].sat, 180);
  EXPECT_EQ((*owner)[3].mode, ColourMode::xy);
  // The rig takes them over: every lamp on in rig white, then all off.
  ASSERT_TRUE(lamps->set(std::vector<bool>(7, true)).ok());
  for (const auto& l : bridge->lamps()) EXPECT_EQ(l.state.mode, ColourMode::xy) << l.id;
  // Lamp 3 goes off carrying its owner's ct 300 at bri 40 (sent while it is on).
  std::vector<LampState> off = *owner;
  for (auto& l : off) l.on = false;
  auto proven = lamps->ensure(off);
  ASSERT_TRUE(proven.ok()) << proven.message();
  EXPECT_EQ(bridge->lamp("3")->mode, ColourMode::ct);
  EXPECT_EQ(bridge->lamp("3")->ct, 300);
  EXPECT_EQ(bridge->lamp("3")->brightness, 40);
  EXPECT_FALSE(bridge->lamp("3")->on);
  ASSERT_TRUE(lamps->restore(*owner).ok());
  auto l1 = bridge->lamp("1"), l2 = bridge->lamp("2"), l4 = bridge->lamp("4");
  EXPECT_TRUE(l1->on);
  EXPECT_EQ(l1->mode, ColourMode::ct);
  EXPECT_EQ(l1->ct, 420);
  EXPECT_EQ(l1->brightness, 90);
  EXPECT_EQ(l2->mode, ColourMode::hs);
  EXPECT_EQ(l2->hue, 30000);
  EXPECT_EQ(l2->sat, 180);
  EXPECT_EQ(l4->mode, ColourMode::xy);
  EXPECT_NEAR(l4->x, 0.2, 1e-4);
  EXPECT_EQ(l4->brightness, 10);
  EXPECT_FALSE(bridge->lamp("3")->on);
  EXPECT_EQ(bridge->counters().refused_rate, 0u);
}

TEST_F(Lamps, AnotherClientUndoingACommandIsCorrectedAndThenNamed) {
  auto o = options();
  o.confirm_ms = 150;
  auto lamps = make(o);
  // Right after the rig's command for lamp 1, another app switches lamp 5 on.
  bridge->interfere_after(1, "5", LampState{.on = true, .brightness = 254, .x = 0.6, .y = 0.35});
  auto r = lamps->ensure([&] {
    std::vector<LampState> w(7, veneerd::rig_white());
    for (int i = 1; i < 7; ++i) w[i].on = false;
    return w;
  }());
  ASSERT_TRUE(r.ok()) << r.message();
  EXPECT_EQ(bridge->on_pattern(), one_hot(7, 0));
  // One that keeps doing it after each of the rig's commands wins: the error names the lamp.
  for (int k = 1; k <= 20; ++k) bridge->interfere_after(k, "6", LampState{.on = true, .brightness = 254});
  auto st = lamps->set(one_hot(7, 1));
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.message().find("lamp 6 (Hue id 6) shows on"), std::string::npos) << st.message();
  EXPECT_NE(st.message().find("another client"), std::string::npos) << st.message();
}

TEST(HueLampsOptions, ConfigErrorsNameTheField) {
  using nlohmann::json;
  auto ok = HueLampsOptions::from_json(
      json{{"bridge", "127.0.0.1:80"}, {"key", "k"}, {"lamps", {"1", 2}}, {"group", "0"}, {"settle_ms", 150}});
  ASSERT_TRUE(ok.ok()) << ok.message();
  EXPECT_EQ(ok->lamps, (std::vector<std::string>{"1", "2"}));
  EXPECT_EQ(ok->group, "0");
  EXPECT_EQ(ok->settle_ms, 150);

  auto expect_error = [](const json& j, const std::string& needle) {
    auto r = HueLampsOptions::from_json(j);
    ASSERT_FALSE(r.ok()) << j.dump();
    EXPECT_NE(r.message().find(needle), std::string::npos) << r.message();
  };
  expect_error(json{{"key", "k"}, {"lamps", {"1"}}}, "'bridge'");
  expect_error(json{{"bridge", "h"}, {"lamps", {"1"}}}, "'key'");
  expect_error(json{{"bridge", "h"}, {"key", "k"}}, "'lamps'");
  expect_error(json{{"bridge", "h"}, {"key", "k"}, {"lamps", {"1", "1"}}}, "twice");
  expect_error(json{{"bridge", "h"}, {"key", "k"}, {"lamps", {"1"}}, {"settle_ms", "x"}}, "'settle_ms'");
  expect_error(json{{"bridge", "h"}, {"key", "k"}, {"lamps", {"1"}}, {"timeout_ms", 1}}, "'timeout_ms'");
  expect_error(json::array(), "JSON object");
}

TEST(HueResults, ParsesSuccessAndErrorArrays) {
  auto r = veneerd::hw::parse_hue_results(
      R"([{"success":{"/lights/1/state/on":true}},{"error":{"type":201,"address":"/lights/1/state/bri","description":"parameter, bri, is not modifiable. Device is set to off."}}])");
  ASSERT_TRUE(r.ok());
  ASSERT_EQ(r->size(), 2u);
  EXPECT_TRUE((*r)[0].success);
  EXPECT_EQ((*r)[0].address, "/lights/1/state/on");
  EXPECT_FALSE((*r)[1].success);
  EXPECT_EQ((*r)[1].error_type, 201);
  EXPECT_EQ((*r)[1].address, "/lights/1/state/bri");
  EXPECT_FALSE(veneerd::hw::parse_hue_results("{}").ok());
  EXPECT_FALSE(veneerd::hw::parse_hue_results("[1]").ok());
  EXPECT_FALSE(veneerd::hw::parse_hue_results("nope").ok());
}

// The real back-ends register under hw/, the simulated ones under sim/:
// neither list holds the other's.
TEST(DeviceRegistry, RealAndSimulatedBackendsRegisterApart) {
  auto& reg = veneerd::DeviceRegistry::instance();
  auto count = [](const auto& list, const std::string& name) {
    int n = 0;
    for (const auto& [k, f] : list) n += k == name;
    return n;
  };
  veneerd::register_hardware_devices();
  veneerd::register_hardware_devices();  // idempotent
  EXPECT_EQ(count(reg.lamps, "hue"), 1);
  EXPECT_EQ(count(reg.cameras, "gphoto2"), 1);
  EXPECT_EQ(count(reg.leds, "none"), 1);
  EXPECT_EQ(count(reg.cameras, "simulated"), 0) << "registered by register_hardware_devices()";
  EXPECT_EQ(count(reg.triggers, "simulated"), 0);
  veneerd::register_simulated_devices();
  veneerd::register_simulated_devices();
  EXPECT_EQ(count(reg.lamps, "hue"), 1);
  EXPECT_EQ(count(reg.cameras, "simulated"), 1);
  EXPECT_EQ(count(reg.triggers, "simulated"), 1);
  EXPECT_EQ(count(reg.leds, "simulated"), 1);
  auto bad = veneerd::DeviceRegistry::make(reg.lamps, "lamps", "hue", nlohmann::json{{"bridge", "x"}});
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.message().find("'key'"), std::string::npos) << bad.message();
  auto unknown = veneerd::DeviceRegistry::make(reg.cameras, "camera", "nikon-9000", nlohmann::json::object());
  ASSERT_FALSE(unknown.ok());
  EXPECT_NE(unknown.message().find("simulated"), std::string::npos) << unknown.message();
}
