// Hue setup (discovery answer, link-button pairing, lamp list, flashing)
// against the bridge emulator over real HTTP on loopback.
#include <gtest/gtest.h>

#include <cstdlib>
#include <sstream>
#include <thread>

#include "veneerd/sim/hue_emulator.hpp"
#include "veneerd/hw/hue_setup.hpp"

namespace veneerd::hw {
namespace {

using veneerd::ColourMode;
using veneerd::LampState;

struct Bridge {
  HueBridgeEmulator emu;
  Bridge() : emu(options()) {
    auto s = emu.start();
    EXPECT_TRUE(s.ok()) << s.message();
  }
  static HueEmulatorOptions options() {
    HueEmulatorOptions o;
    o.apply_delay_ms = 0;
    o.enforce_limits = false;
    return o;
  }
  std::string address() const { return emu.address(); }
};

TEST(HueSetup, PairingNeedsTheLinkButton) {
  Bridge b;
  PairAttempt first = pair_once(b.address());
  EXPECT_EQ(first.outcome, PairAttempt::Outcome::press_link_button);
  EXPECT_NE(first.message.find("link button"), std::string::npos);
  b.emu.press_link_button();
  PairAttempt second = pair_once(b.address());
  ASSERT_EQ(second.outcome, PairAttempt::Outcome::paired) << second.message;
  EXPECT_FALSE(second.key.empty());
  // The key works: the lamp list comes back.
  auto lamps = list_bridge_lamps(b.address(), second.key);
  ASSERT_TRUE(lamps.ok()) << lamps.message();
  ASSERT_EQ(lamps->size(), 7u);
  EXPECT_EQ(lamps->front().id, "1");
  EXPECT_EQ(lamps->front().name, "Ring 1");
}

TEST(HueSetup, PairLoopTellsTheUserAndWaits) {
  Bridge b;
  std::vector<std::string> told;
  std::thread presser;
  auto key = pair_bridge(b.address(), 10000, 50, [&](const std::string& m) {
    told.push_back(m);
    presser = std::thread([&] { b.emu.press_link_button(); });
  });
  if (presser.joinable()) presser.join();
  ASSERT_TRUE(key.ok()) << key.message();
  ASSERT_EQ(told.size(), 1u);
  EXPECT_NE(told[0].find("Press the round link button"), std::string::npos);
}

TEST(HueSetup, PairTimesOutWithClearMessage) {
  Bridge b;
  auto key = pair_bridge(b.address(), 200, 50, nullptr);
  ASSERT_FALSE(key.ok());
  EXPECT_NE(key.message().find("was not pressed"), std::string::npos) << key.message();
}

TEST(HueSetup, WrongKeyIsExplained) {
  Bridge b;
  auto lamps = list_bridge_lamps(b.address(), "not-a-key");
  ASSERT_FALSE(lamps.ok());
  EXPECT_NE(lamps.message().find("not paired"), std::string::npos) << lamps.message();
}

TEST(HueSetup, FlashEachLampInTurnAndGiveItBack) {
  Bridge b;
  // The owner's lamps: 1 on in ct mode, 2 off remembering red, 3 off.
  b.emu.set_lamp("1", LampState{.on = true, .brightness = 90, .mode = ColourMode::ct, .ct = 400});
  b.emu.set_lamp("2", LampState{.on = false, .brightness = 50, .x = 0.6, .y = 0.3});
  b.emu.press_link_button();
  auto p = pair_once(b.address());
  ASSERT_EQ(p.outcome, PairAttempt::Outcome::paired);
  std::vector<std::string> order;
  std::vector<bool> lit_when_announced;
  auto s = flash_lamps_in_turn(b.address(), p.key, {"3", "1", "2"}, 0, [&](const std::string& id, int pos) {
    order.push_back(id + "@" + std::to_string(pos));
    // The lamp flashed before this one is back to its owner's state already.
    if (pos == 1) lit_when_announced.push_back(b.emu.lamp("3")->on);
  });
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_EQ(order, (std::vector<std::string>{"3@0", "1@1", "2@2"}));
  EXPECT_EQ(lit_when_announced, std::vector<bool>{false});
  EXPECT_FALSE(b.emu.lamp("3")->on) << "flash left lamp 3 on";
  EXPECT_FALSE(b.emu.lamp("2")->on);
  EXPECT_NEAR(b.emu.lamp("2")->x, 0.6, 1e-4);
  EXPECT_EQ(b.emu.lamp("2")->brightness, 50);
  EXPECT_TRUE(b.emu.lamp("1")->on);
  EXPECT_EQ(b.emu.lamp("1")->mode, ColourMode::ct);
  EXPECT_EQ(b.emu.lamp("1")->ct, 400);
  EXPECT_FALSE(b.emu.lamp("4")->on);
}

TEST(HueSetup, ProbeFindsTheBridgeAndRejectsNothing) {
  Bridge b;
  auto info = probe_bridge(b.address());
  ASSERT_TRUE(info.ok()) << info.message();
  EXPECT_EQ(info->address, b.address());
  std::string dead;
  {
    Bridge gone;
    dead = gone.address();
  }  // stopped: nothing listens there now
  auto none = probe_bridge(dead, 500);
  ASSERT_FALSE(none.ok());
  EXPECT_NE(none.message().find("no Hue bridge answers at " + dead), std::string::npos) << none.message();
  std::vector<std::string> notes;
  DiscoverOptions o;
  o.addresses = {b.address()};
  o.mdns = false;
  auto found = discover_bridges(o, &notes);
  ASSERT_EQ(found.size(), 1u);
  ASSERT_FALSE(notes.empty());
}

// mDNS through Avahi without avahi-daemon (the system bus pointed nowhere):
// one note says so, and the manual address is still found.
TEST(HueSetup, MdnsWithoutAvahiIsOneNoteAndTheAddressStillWorks) {
  Bridge b;
  ::setenv("DBUS_SYSTEM_BUS_ADDRESS", "unix:path=/nonexistent/veneer-test-no-dbus", 1);
  std::vector<std::string> notes;
  DiscoverOptions o;
  o.addresses = {b.address()};
  o.mdns = true;
  o.mdns_timeout_ms = 500;
  auto found = discover_bridges(o, &notes);
  ::unsetenv("DBUS_SYSTEM_BUS_ADDRESS");
  ASSERT_EQ(found.size(), 1u);
  int mdns_notes = 0;
  for (const auto& n : notes) {
    if (n.rfind("mDNS: ", 0) != 0) continue;
    ++mdns_notes;
    EXPECT_EQ(n.rfind("mDNS: DNS-SD unavailable: ", 0), 0u) << n;
  }
  EXPECT_EQ(mdns_notes, 1);
}

TEST(HueSetup, ParsesABridgeConfigAnswer) {
  // The shape of a real bridge's unauthenticated /api/config answer.
  auto b = parse_bridge_config(R"({"name":"Philips hue","datastoreversion":"131","swversion":"1956097030",
    "apiversion":"1.56.0","mac":"00:17:88:aa:bb:cc","bridgeid":"001788FFFEAABBCC","factorynew":false,
    "replacesbridgeid":null,"modelid":"BSB002","starterkitid":""})");
  ASSERT_TRUE(b.ok()) << b.message();
  EXPECT_EQ(b->name, "Philips hue");
  EXPECT_EQ(b->bridgeid, "001788FFFEAABBCC");
  EXPECT_EQ(b->apiversion, "1.56.0");
  EXPECT_FALSE(parse_bridge_config("<html>router login</html>").ok());
  EXPECT_FALSE(parse_bridge_config(R"({"hello":"world"})").ok());
  HueError e = parse_hue_error(R"([{"error":{"type":101,"address":"","description":"link button not pressed"}}])");
  EXPECT_EQ(e.type, 101);
  EXPECT_EQ(parse_hue_error(R"([{"success":{"username":"x"}}])").type, 0);
  auto lamps = parse_bridge_lights(R"({"10":{"name":"b","state":{"on":true,"reachable":false}},"2":{"name":"a"}})");
  ASSERT_TRUE(lamps.ok());
  ASSERT_EQ(lamps->size(), 2u);
  EXPECT_EQ((*lamps)[0].id, "2");  // numeric order
  EXPECT_FALSE((*lamps)[1].reachable);
}

TEST(HueSetup, CommandLine) {
  Bridge b;
  std::ostringstream out, err;
  EXPECT_EQ(hue_command({"hue"}, out, err), 2);
  // --help anywhere: the whole help on stdout, exit 0.
  for (std::vector<std::string> args : {std::vector<std::string>{"hue", "--help"}, {"hue", "pair", "--help"}, {"hue", "-h"}}) {
    out.str("");
    EXPECT_EQ(hue_command(args, out, err), 0);
    EXPECT_NE(out.str().find("link button"), std::string::npos) << out.str();
    EXPECT_NE(out.str().find("veneerd hue flash --address"), std::string::npos) << out.str();
  }
  EXPECT_EQ(hue_command({"hue", "lamps", "--address", b.address()}, out, err), 2);  // no key
  EXPECT_NE(err.str().find("needs --key"), std::string::npos) << err.str();
  b.emu.press_link_button();
  out.str("");
  ASSERT_EQ(hue_command({"hue", "pair", "--address", b.address(), "--timeout", "5"}, out, err), 0) << err.str();
  std::string key = out.str();
  key.erase(key.find_last_not_of("\n") + 1);
  out.str("");
  ASSERT_EQ(hue_command({"hue", "lamps", "--address", b.address(), "--key", key}, out, err), 0) << err.str();
  EXPECT_NE(out.str().find("1\tRing 1\t"), std::string::npos) << out.str();
  err.str("");
  EXPECT_EQ(hue_command({"hue", "flash", "--address", b.address(), "--key", key, "--lamps", "2,99"}, out, err), 1);
  EXPECT_NE(err.str().find("no lamp 99"), std::string::npos) << err.str();
  out.str("");
  ASSERT_EQ(hue_command({"hue", "flash", "--address", b.address(), "--key", key, "--lamps", "2,1", "--gap-ms", "0"}, out, err), 0);
  EXPECT_NE(out.str().find("flashing lamp 2"), std::string::npos) << out.str();
  out.str("");
  ASSERT_EQ(hue_command({"hue", "discover", "--address", b.address(), "--no-mdns"}, out, err), 0) << err.str();
  EXPECT_NE(out.str().find(b.address()), std::string::npos);
}

}  // namespace
}  // namespace veneerd::hw
