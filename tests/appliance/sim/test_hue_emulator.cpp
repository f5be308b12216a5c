// The Hue bridge emulator answered through raw libcurl: bridge semantics,
// error bodies, rate limits, ack-before-change, faults.
#include <curl/curl.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>
#include <arpa/inet.h>

#include <chrono>
#include <thread>

#include <nlohmann/json.hpp>

#include "veneerd/sim/hue_emulator.hpp"

using json = nlohmann::json;
using namespace std::chrono_literals;

namespace {

struct Reply {
  long status = 0;
  std::string body;
  bool ok = false;
};

size_t collect(char* d, size_t s, size_t n, void* u) {
  static_cast<std::string*>(u)->append(d, s * n);
  return s * n;
}

// One raw request (its own connection unless `easy` is reused).
Reply raw(CURL* easy, const std::string& method, const std::string& url, const std::string& body = "") {
  Reply r;
  curl_easy_setopt(easy, CURLOPT_URL, url.c_str());
  curl_easy_setopt(easy, CURLOPT_WRITEFUNCTION, collect);
  curl_easy_setopt(easy, CURLOPT_WRITEDATA, &r.body);
  curl_easy_setopt(easy, CURLOPT_TIMEOUT_MS, 5000L);
  curl_easy_setopt(easy, CURLOPT_NOSIGNAL, 1L);
  if (method == "GET") {
    curl_easy_setopt(easy, CURLOPT_HTTPGET, 1L);
    curl_easy_setopt(easy, CURLOPT_CUSTOMREQUEST, nullptr);
  } else {
    curl_easy_setopt(easy, CURLOPT_CUSTOMREQUEST, method.c_str());
    curl_easy_setopt(easy, CURLOPT_POSTFIELDS, body.c_str());
    curl_easy_setopt(easy, CURLOPT_POSTFIELDSIZE, static_cast<long>(body.size()));
  }
  r.ok = curl_easy_perform(easy) == CURLE_OK;
  curl_easy_getinfo(easy, CURLINFO_RESPONSE_CODE, &r.status);
  return r;
}

class Emulator : public ::testing::Test {
 protected:
  void SetUp() override {
    veneerd::HueEmulatorOptions o;
    o.apply_delay_ms = 0;
    bridge = std::make_unique<veneerd::HueBridgeEmulator>(o);
    ASSERT_TRUE(bridge->start().ok());
    easy = curl_easy_init();
    base = "http://" + bridge->address() + "/api/veneer-sim";
  }
  void TearDown() override {
    curl_easy_cleanup(easy);
    bridge->stop();
  }
  Reply get(const std::string& path) { return raw(easy, "GET", base + path); }
  Reply put(const std::string& path, const std::string& body) { return raw(easy, "PUT", base + path, body); }

  std::unique_ptr<veneerd::HueBridgeEmulator> bridge;
  CURL* easy = nullptr;
  std::string base;
};

}  // namespace

TEST_F(Emulator, ListsLampsLikeABridge) {
  auto r = get("/lights");
  ASSERT_TRUE(r.ok);
  ASSERT_EQ(r.status, 200);
  json j = json::parse(r.body);
  ASSERT_EQ(j.size(), 7u);
  EXPECT_EQ(j["1"]["name"], "Ring 1");
  EXPECT_EQ(j["7"]["name"], "Ring 7");
  EXPECT_EQ(j["3"]["state"]["on"], false);
  EXPECT_EQ(j["3"]["state"]["reachable"], true);
  EXPECT_TRUE(j["3"]["state"]["xy"].is_array());
  auto one = json::parse(get("/lights/4").body);
  EXPECT_EQ(one["name"], "Ring 4");
  auto config = json::parse(get("/config").body);
  EXPECT_EQ(config["apiversion"], "1.56.0");
}

TEST_F(Emulator, ColourModesFollowTheLastColourParameter) {
  bridge->set_apply_delay(std::chrono::milliseconds(0));
  auto state = [&] { return json::parse(get("/lights/2").body)["state"]; };
  ASSERT_EQ(put("/lights/2/state", R"({"on":true,"ct":400,"bri":100})").status, 200);
  auto s = state();
  EXPECT_EQ(s["colormode"], "ct");
  EXPECT_EQ(s["ct"], 400);
  // xy is reported in every mode: 400 mired (2500 K) is a warm white.
  EXPECT_NEAR(s["xy"][0].get<double>(), 0.477, 0.01);
  EXPECT_NEAR(s["xy"][1].get<double>(), 0.414, 0.01);
  ASSERT_EQ(put("/lights/2/state", R"({"hue":0,"sat":254})").status, 200);
  s = state();
  EXPECT_EQ(s["colormode"], "hs");
  EXPECT_EQ(s["sat"], 254);
  EXPECT_GT(s["xy"][0].get<double>(), 0.6);  // saturated red
  EXPECT_EQ(s["ct"], 400);                    // kept, not shown
  ASSERT_EQ(put("/lights/2/state", R"({"xy":[0.2,0.3]})").status, 200);
  s = state();
  EXPECT_EQ(s["colormode"], "xy");
  EXPECT_NEAR(s["xy"][0].get<double>(), 0.2, 1e-9);
  // Out-of-range colour values are refused with the bridge's error 7.
  auto bad = json::parse(put("/lights/2/state", R"({"ct":90})").body);
  EXPECT_EQ(bad[0]["error"]["type"], 7);
  EXPECT_EQ(state()["colormode"], "xy");
}

TEST_F(Emulator, AnotherClientsChangeLandsAfterTheNthCommand) {
  bridge->set_apply_delay(std::chrono::milliseconds(0));
  bridge->interfere_after(2, "5", veneerd::LampState{.on = true, .brightness = 77});
  ASSERT_EQ(put("/lights/1/state", R"({"on":true})").status, 200);
  EXPECT_FALSE(bridge->lamp("5")->on);
  ASSERT_EQ(put("/lights/1/state", R"({"on":false})").status, 200);
  EXPECT_TRUE(bridge->lamp("5")->on);
  EXPECT_EQ(bridge->lamp("5")->brightness, 77);
}

TEST_F(Emulator, ErrorBodies) {
  auto unauth = json::parse(raw(easy, "GET", "http://" + bridge->address() + "/api/wrong-key/lights").body);
  ASSERT_TRUE(unauth.is_array());
  EXPECT_EQ(unauth[0]["error"]["type"], 1);
  EXPECT_EQ(unauth[0]["error"]["description"], "unauthorized user");

  auto missing = json::parse(get("/lights/99").body);
  EXPECT_EQ(missing[0]["error"]["type"], 3);
  EXPECT_EQ(missing[0]["error"]["address"], "/lights/99");

  auto bad_json = json::parse(put("/lights/1/state", "{not json").body);
  EXPECT_EQ(bad_json[0]["error"]["type"], 2);

  auto bad_param = json::parse(put("/lights/1/state", R"({"on":true,"warp":9})").body);
  ASSERT_EQ(bad_param.size(), 2u);
  EXPECT_TRUE(bad_param[0].contains("success"));
  EXPECT_EQ(bad_param[1]["error"]["type"], 6);

  auto bad_value = json::parse(put("/lights/1/state", R"({"on":true,"bri":999})").body);
  EXPECT_EQ(bad_value[1]["error"]["type"], 7);

  auto not_found = raw(easy, "GET", "http://" + bridge->address() + "/elsewhere");
  EXPECT_EQ(not_found.status, 404);
}

TEST_F(Emulator, BrightnessToAnOffLampNeedsOnInTheSameBody) {
  put("/lights/2/state", R"({"on":false})");
  auto refused = json::parse(put("/lights/2/state", R"({"bri":200,"xy":[0.5,0.4]})").body);
  ASSERT_EQ(refused.size(), 2u);
  EXPECT_EQ(refused[0]["error"]["type"], 201);
  EXPECT_EQ(refused[0]["error"]["address"], "/lights/2/state/bri");
  EXPECT_EQ(bridge->lamp("2")->on, false);

  auto ok = json::parse(put("/lights/2/state", R"({"on":true,"bri":200,"xy":[0.5,0.4],"transitiontime":0})").body);
  ASSERT_EQ(ok.size(), 4u);
  for (const auto& e : ok) EXPECT_TRUE(e.contains("success")) << e.dump();
  EXPECT_EQ(ok[0]["success"]["/lights/2/state/on"], true);
  auto s = bridge->lamp("2");
  EXPECT_TRUE(s->on);
  EXPECT_EQ(s->brightness, 200);
  EXPECT_DOUBLE_EQ(s->x, 0.5);
}

TEST_F(Emulator, AcknowledgesBeforeTheChangeTakesEffect) {
  bridge->set_apply_delay(1500ms);
  auto ack = put("/lights/5/state", R"({"on":true})");
  ASSERT_EQ(ack.status, 200);
  EXPECT_TRUE(json::parse(ack.body)[0].contains("success"));
  // Within the window the bridge still reports the old state...
  auto during = json::parse(get("/lights/5").body);
  EXPECT_EQ(during["state"]["on"], false);
  EXPECT_FALSE(bridge->lamp("5")->on);
  // ...and later the new one.
  auto deadline = std::chrono::steady_clock::now() + 10s;
  while (!bridge->lamp("5")->on && std::chrono::steady_clock::now() < deadline) std::this_thread::sleep_for(50ms);
  EXPECT_TRUE(bridge->lamp("5")->on);
  EXPECT_EQ(json::parse(get("/lights/5").body)["state"]["on"], true);
}

TEST_F(Emulator, BurstOfLightCommandsGets429) {
  int refused = 0, accepted = 0;
  for (int i = 0; i < 30; ++i) {
    auto r = put("/lights/" + std::to_string(1 + i % 7) + "/state", i % 2 ? R"({"on":true})" : R"({"on":false})");
    ASSERT_TRUE(r.ok);
    if (r.status == 429) ++refused;
    else if (r.status == 200) ++accepted;
  }
  EXPECT_GT(refused, 0);
  EXPECT_LE(accepted, 30 - refused);
  auto c = bridge->counters();
  EXPECT_EQ(static_cast<int>(c.refused_rate), refused);
  EXPECT_EQ(static_cast<int>(c.light_commands), accepted);
  // Group commands: one per second.
  auto g1 = put("/groups/0/action", R"({"on":false})");
  auto g2 = put("/groups/0/action", R"({"on":false})");
  EXPECT_EQ(g1.status, 200);
  EXPECT_EQ(g2.status, 429);
  // Reads are not rate limited.
  for (int i = 0; i < 20; ++i) EXPECT_EQ(get("/lights").status, 200);
}

TEST_F(Emulator, MoreThanThreeInFlightGets503) {
  bridge->set_latency(400ms);
  CURLM* multi = curl_multi_init();
  std::vector<CURL*> handles;
  std::vector<std::string> bodies(6);
  for (int i = 0; i < 6; ++i) {
    CURL* e = curl_easy_init();
    std::string url = base + "/lights";
    curl_easy_setopt(e, CURLOPT_URL, url.c_str());
    curl_easy_setopt(e, CURLOPT_WRITEFUNCTION, collect);
    curl_easy_setopt(e, CURLOPT_WRITEDATA, &bodies[i]);
    curl_easy_setopt(e, CURLOPT_TIMEOUT_MS, 5000L);
    curl_multi_add_handle(multi, e);
    handles.push_back(e);
  }
  int running = 1;
  while (running) {
    curl_multi_perform(multi, &running);
    if (running) curl_multi_poll(multi, nullptr, 0, 100, nullptr);
  }
  int busy = 0, ok = 0;
  for (CURL* e : handles) {
    long status = 0;
    curl_easy_getinfo(e, CURLINFO_RESPONSE_CODE, &status);
    busy += status == 503;
    ok += status == 200;
    curl_multi_remove_handle(multi, e);
    curl_easy_cleanup(e);
  }
  curl_multi_cleanup(multi);
  EXPECT_GT(busy, 0);
  EXPECT_GT(ok, 0);
  EXPECT_EQ(busy + ok, 6);
  EXPECT_EQ(static_cast<int>(bridge->counters().refused_busy), busy);
}

TEST_F(Emulator, InjectedFaults) {
  bridge->fail_next(1, 500);
  EXPECT_EQ(get("/lights").status, 500);
  EXPECT_EQ(get("/lights").status, 200);

  bridge->hue_error_next(1, 901);
  auto e = json::parse(put("/lights/1/state", R"({"on":true})").body);
  EXPECT_EQ(e[0]["error"]["type"], 901);
  EXPECT_FALSE(bridge->lamp("1")->on);

  bridge->drop_next(1);
  CURL* fresh = curl_easy_init();  // a new connection: curl retries only reused ones
  curl_easy_setopt(fresh, CURLOPT_FRESH_CONNECT, 1L);
  auto dropped = raw(fresh, "GET", base + "/lights");
  curl_easy_cleanup(fresh);
  EXPECT_FALSE(dropped.ok);  // connection closed without an answer
  EXPECT_EQ(get("/lights").status, 200);
  EXPECT_EQ(bridge->counters().dropped, 1u);

  bridge->set_reachable("6", false);
  EXPECT_EQ(json::parse(get("/lights/6").body)["state"]["reachable"], false);
}

TEST_F(Emulator, Pairing) {
  std::string api = "http://" + bridge->address() + "/api";
  auto refused = json::parse(raw(easy, "POST", api, R"({"devicetype":"veneer#rig"})").body);
  EXPECT_EQ(refused[0]["error"]["type"], 101);
  bridge->press_link_button();
  auto ok = json::parse(raw(easy, "POST", api, R"({"devicetype":"veneer#rig"})").body);
  ASSERT_TRUE(ok[0].contains("success")) << ok.dump();
  std::string user = ok[0]["success"]["username"];
  EXPECT_EQ(raw(easy, "GET", api + "/" + user + "/lights").status, 200);
  EXPECT_TRUE(json::parse(raw(easy, "GET", api + "/" + user + "/lights").body).is_object());
}

TEST_F(Emulator, MalformedRequestOnTheSocketGetsAnErrorAndTheServerLives) {
  int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(bridge->port());
  inet_pton(AF_INET, "127.0.0.1", &addr.sin_addr);
  ASSERT_EQ(::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr), 0);
  std::string junk = "\x01\x02 nonsense\r\n\r\n";
  ASSERT_EQ(::send(fd, junk.data(), junk.size(), 0), static_cast<ssize_t>(junk.size()));
  char buf[512];
  ssize_t n = ::recv(fd, buf, sizeof buf, 0);
  ::close(fd);
  ASSERT_GT(n, 0);
  EXPECT_EQ(std::string(buf, 12), "HTTP/1.1 400");
  EXPECT_EQ(get("/lights").status, 200);
  EXPECT_EQ(bridge->counters().bad_requests, 1u);
}

TEST_F(Emulator, StopsWhileRequestsAreSlow) {
  bridge->set_latency(20000ms);
  std::thread t([&] {
    CURL* e = curl_easy_init();
    raw(e, "GET", base + "/lights");
    curl_easy_cleanup(e);
  });
  std::this_thread::sleep_for(200ms);
  auto start = std::chrono::steady_clock::now();
  bridge->stop();
  t.join();
  EXPECT_LT(std::chrono::steady_clock::now() - start, 5s);  // a hang check, not a timing measure
  EXPECT_FALSE(bridge->running());
}
