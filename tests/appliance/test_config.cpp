#include <gtest/gtest.h>

#include "veneerd/config.hpp"

using nlohmann::json;

TEST(Config, ReadsAFullConfig) {
  json doc = json::parse(R"({
    "name": "bench rig", "listen": "0.0.0.0:7900", "store": "/tmp/sets",
    "lamps": {"backend": "hue", "bridge": "10.0.0.2", "key": "k", "lamps": ["3","4","5"],
              "settle_ms": 200, "positions_m": [[0,0.47,1],[0.47,0,1],[-0.47,0,1]]},
    "camera": {"backend": "gphoto2"},
    "gpio": {"chip": "gpiochip0", "button_line": 17, "led_line": 27},
    "capture": {"shutter_s": 0.25, "aperture": 8, "iso": 100}
  })");
  auto c = veneerd::parse_config(doc, "rig.json");
  ASSERT_TRUE(c) << c.message();
  EXPECT_EQ(c->name, "bench rig");
  EXPECT_EQ(c->listen_host, "0.0.0.0");
  EXPECT_EQ(c->listen_port, 7900);
  EXPECT_EQ(c->token_path(), std::filesystem::path("/tmp/sets/token"));
  EXPECT_EQ(c->lamp_ids, (std::vector<std::string>{"3", "4", "5"}));
  EXPECT_EQ(c->lamp_positions.size(), 3u);
  EXPECT_EQ(c->settle_ms, 200);
  EXPECT_EQ(c->camera.backend, "gphoto2");
  EXPECT_DOUBLE_EQ(c->exposure.shutter_s, 0.25);
  // The shared gpio block reaches the trigger's and LED's sections.
  EXPECT_EQ(c->trigger.section.value("button_line", 0), 17);
  EXPECT_EQ(c->led.section.value("led_line", 0), 27);
}

TEST(Config, OneClearErrorPerBadField) {
  struct Case {
    const char* doc;
    const char* says;
  };
  const Case cases[] = {
      {R"({"listen": "host:port"})", "listen"},
      {R"({"listen": 7878})", "listen: expected a non-empty string"},
      {R"({"lamps": {"settle_ms": -5}})", "lamps.settle_ms"},
      {R"({"lamps": {"lamps": [3, 4]}})", "lamps.lamps[0]"},
      {R"({"lamps": {"lamps": ["1","2"], "positions_m": [[0,0,1]]}})", "positions_m has 1 entries"},
      {R"({"lamps": {"positions_m": [[0,0]]}})", "lamps.positions_m[0]"},
      {R"({"camera": "gphoto2"})", "camera: expected an object"},
      {R"({"camera": {"backend": 3}})", "camera.backend"},
      {R"({"gpio": {"button_line": "17"}})", "gpio.button_line"},
      {R"({"capture": {"iso": 1.5}})", "capture.iso"},
      {R"({"capture": {"shutter_s": 1000}})", "capture.shutter_s"},
      {R"({"colour": "red"})", "unknown field 'colour'"},
  };
  for (const auto& c : cases) {
    auto r = veneerd::parse_config(json::parse(c.doc), "rig.json");
    ASSERT_FALSE(r) << c.doc;
    EXPECT_NE(r.message().find("rig.json"), std::string::npos) << r.message();
    EXPECT_NE(r.message().find(c.says), std::string::npos) << r.message();
  }
}

TEST(Config, ListenAddresses) {
  std::string host;
  uint16_t port = 0;
  ASSERT_TRUE(veneerd::parse_listen("127.0.0.1:0", host, port));
  EXPECT_EQ(host, "127.0.0.1");
  EXPECT_EQ(port, 0);
  ASSERT_TRUE(veneerd::parse_listen(":9000", host, port));
  EXPECT_EQ(host, "0.0.0.0");
  EXPECT_EQ(port, 9000);
  EXPECT_FALSE(veneerd::parse_listen("x:99999", host, port));
}

TEST(Config, ThesisRingHasSevenLampsAroundTheCamera) {
  auto ring = veneerd::thesis_ring_positions();
  ASSERT_EQ(ring.size(), 7u);
  for (const auto& p : ring) {
    EXPECT_NEAR(std::hypot(p[0], p[1]), 0.47, 1e-9);
    EXPECT_NEAR(p[2], 1.0, 1e-9);
  }
}
