// The lamps belong to their owner: the real veneerd binary against a Hue
// bridge it did not start (the emulator in this process, reached only over
// HTTP, like a bridge on the LAN), with a second client playing the Hue app
// that switches and colours lamps before and during a set.
#include <gtest/gtest.h>

#include <fstream>

#include <nlohmann/json.hpp>

#include "rig_test_util.hpp"
#include "veneer/io/imageset.hpp"
#include "veneer/rig/client.hpp"
#include "veneerd/sim/hue_emulator.hpp"
#include "veneerd/hw/hue_lamps.hpp"
#include "veneerd/hw/hue_setup.hpp"

namespace fs = std::filesystem;
using rigtest::DaemonProcess;
using veneerd::ColourMode;
using veneerd::LampState;
using Kind = veneer::rig::Event::Kind;

namespace {

constexpr int kLamps = 6;

struct Bridge {
  veneerd::HueBridgeEmulator emulator;
  std::string app_key;                       // a second user: the owner's Hue app
  std::unique_ptr<veneerd::hw::HueLamps> app;    // the app's view of the ring lamps

  Bridge() : emulator([] {
      veneerd::HueEmulatorOptions o;
      o.lamps = kLamps + 2;  // two lamps elsewhere in the house
      o.key = "rig-key";
      o.apply_delay_ms = 30;
      o.latency_ms = 2;
      return o;
    }()) {
    if (!emulator.start().ok()) return;
    emulator.press_link_button();
    auto key = veneerd::hw::pair_bridge(emulator.address(), 3000, 100, nullptr);
    if (!key) return;
    app_key = *key;
    veneerd::hw::HueLampsOptions o;
    o.bridge = emulator.address();
    o.key = app_key;
    for (int i = 1; i <= kLamps; ++i) o.lamps.push_back(std::to_string(i));
    o.settle_ms = 0;
    auto l = veneerd::hw::HueLamps::create(o);
    if (l) app = std::move(*l);
  }
  // The app sets lamps over HTTP, as the owner would.
  void app_sets(const std::vector<LampState>& states) {
    auto r = app->ensure(states);
    ASSERT_TRUE(r.ok()) << r.message();
  }
  std::vector<LampState> now() {
    auto r = app->read();
    EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.message());
    return r.ok() ? *r : std::vector<LampState>{};
  }
};

fs::path write_config(const fs::path& dir, const Bridge& b, const std::string& key) {
  nlohmann::json lamps = nlohmann::json::array();
  for (int i = 1; i <= kLamps; ++i) lamps.push_back(std::to_string(i));
  nlohmann::json config = {
      {"name", "owner-test-rig"},
      {"lamps", {{"backend", "hue"}, {"bridge", b.emulator.address()}, {"key", key}, {"lamps", lamps},
                 {"settle_ms", 60}}},
      // The simulated camera renders what the bridge reports; it finds the bridge in the lamps section.
      {"camera", {{"backend", "simulated"}, {"scene", "orange"}, {"size", {96, 64}}, {"noise_sigma", 0}}},
      {"trigger", {{"backend", "simulated"}}},
      {"led", {{"backend", "simulated"}}},
      {"capture", {{"shutter_s", 0.033}, {"aperture", 8}, {"iso", 100}}}};
  fs::path file = dir / "veneerd.json";
  std::ofstream(file) << config.dump(2);
  return file;
}

std::unique_ptr<veneer::rig::Client> connect(const DaemonProcess& d, const fs::path& store) {
  auto token = veneer::rig::read_token_file(store / "token");
  if (!token) return nullptr;
  auto c = veneer::rig::Client::connect({"127.0.0.1", d.port()}, *token);
  return c ? std::move(*c) : nullptr;
}

// The owner's evening: two lamps on in their own modes, one off remembering a
// warm dim white, the rest off in the rig's white.
std::vector<LampState> owners_states() {
  std::vector<LampState> s(kLamps, LampState{});
  s[1] = LampState{.on = true, .brightness = 140, .mode = ColourMode::ct, .ct = 420};
  s[4] = LampState{.on = true, .brightness = 70, .mode = ColourMode::hs, .hue = 47000, .sat = 220};
  s[2] = LampState{.on = true, .brightness = 35, .mode = ColourMode::ct, .ct = 480};
  return s;
}

void expect_owner_states(Bridge& b, const std::vector<LampState>& owner) {
  auto now = b.now();
  ASSERT_EQ(now.size(), owner.size());
  for (size_t i = 0; i < owner.size(); ++i) {
    EXPECT_EQ(now[i].on, owner[i].on) << "lamp " << i + 1 << ": " << veneerd::describe(now[i]);
    EXPECT_TRUE(veneerd::same_colour(now[i], owner[i]))
        << "lamp " << i + 1 << " shows " << veneerd::describe(now[i]) << ", its owner had "
        << veneerd::describe(owner[i]) << " (bri " << owner[i].brightness << ")";
    EXPECT_EQ(now[i].mode, owner[i].mode) << "lamp " << i + 1;
  }
}

// Captures a set and pulls it; the stored set's id through `id`.
veneer::Expected<veneer::io::ImageSet> capture_and_pull(veneer::rig::Client& c, const fs::path& into,
                                                    const std::function<void(const veneer::rig::Event&)>& on_event,
                                                    std::string* id = nullptr) {
  auto started = c.capture();
  if (!started) return started.error();
  auto done = c.wait_event(
      [&](const veneer::rig::Event& e) {
        if (on_event) on_event(e);
        return e.set_id == *started && (e.kind == Kind::set_stored || e.kind == Kind::capture_failed);
      },
      120);
  if (!done) return done.error();
  if (done->kind != Kind::set_stored) return veneer::make_error("capture failed: " + done->reason);
  if (id) *id = *started;
  if (auto s = c.pull(*started, into / *started); !s) return s.error();
  return veneer::io::read_set(into / *started);
}

double max_abs_diff(const cv::Mat& a, const cv::Mat& b) {
  if (a.size() != b.size() || a.type() != b.type()) return 1e9;
  double m = 0;
  cv::minMaxLoc(cv::abs(a - b), nullptr, &m);
  return m;
}

}  // namespace

TEST(LampOwner, LampsSwitchedAndColouredByAnotherClientBeforeAndDuringASetNeverReachAFrame) {
  fs::path dir = rigtest::temp_dir("owner");
  Bridge b;
  ASSERT_TRUE(b.app) << "pairing the second client failed";
  fs::path store = dir / "store";
  auto d = DaemonProcess::start(store, {"--config", write_config(dir, b, "rig-key").string()});
  ASSERT_TRUE(d && d->port() != 0) << (d ? d->log() : "");
  auto c = connect(*d, store);
  ASSERT_TRUE(c);

  // A reference set with every lamp off beforehand: what each frame must look like.
  b.app_sets(std::vector<LampState>(kLamps, LampState{}));
  auto reference = capture_and_pull(*c, dir / "pulled", nullptr);
  ASSERT_TRUE(reference) << reference.message() << d->log();
  ASSERT_EQ(reference->images.size(), static_cast<size_t>(kLamps));
  for (size_t i = 0; i < reference->images.size(); ++i)
    ASSERT_GT(cv::mean(reference->images[i])[1], 10 * cv::mean(reference->ambient)[1] + 1e-4) << "lamp " << i + 1;

  // The owner switches and colours lamps after veneerd started (as the Hue app or a scene would).
  const auto owner = owners_states();
  b.app_sets(owner);
  // veneer rig status shows them as the bridge has them.
  bool shown = false;
  for (int i = 0; i < 100 && !shown; ++i) {
    auto s = c->status();
    ASSERT_TRUE(s) << s.message();
    shown = s->lamps_on.size() == static_cast<size_t>(kLamps) && s->lamps_on[1] && s->lamps_on[2] && s->lamps_on[4] &&
            !s->lamps_on[0];
    if (shown) {
      EXPECT_EQ(s->lamps[1].colour_mode, "ct");
      EXPECT_EQ(s->lamps[1].ct, 420);
      EXPECT_TRUE(s->lamps_problem.empty()) << s->lamps_problem;
      EXPECT_TRUE(s->ready);
    }
    if (!shown) std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  EXPECT_TRUE(shown) << "rig status never showed the owner's lamps";

  // During the set: right after the rig's 4th and 9th light commands another
  // client switches lamps on and colours them; and when shot 3 is reported
  // the app switches lamp 6 on in red over HTTP.
  b.emulator.interfere_after(4, "1", LampState{.on = true, .brightness = 254, .x = 0.6, .y = 0.33});
  b.emulator.interfere_after(9, "4", LampState{.on = true, .brightness = 200, .mode = ColourMode::hs, .hue = 1000, .sat = 254});
  auto app_during = [&](const veneer::rig::Event& e) {
    if (e.kind == Kind::shot_taken && e.k == 3) {
      std::vector<LampState> now = b.now();
      if (now.size() == static_cast<size_t>(kLamps)) {
        now[5] = LampState{.on = true, .brightness = 254, .x = 0.65, .y = 0.3};
        (void)b.app->command(b.now(), now);
      }
    }
  };
  std::string id;
  auto set = capture_and_pull(*c, dir / "pulled", app_during, &id);
  ASSERT_TRUE(set) << set.message() << d->log();

  // Every stored frame shows exactly its lamp, and the ambient frame is dark.
  EXPECT_LT(max_abs_diff(set->ambient, reference->ambient), 1e-3) << "the ambient frame saw a lamp";
  ASSERT_EQ(set->images.size(), reference->images.size());
  for (size_t i = 0; i < set->images.size(); ++i)
    EXPECT_LT(max_abs_diff(set->images[i], reference->images[i]), 1e-3) << "frame " << i + 1 << " is not lamp " << i + 1 << " alone";
  EXPECT_TRUE(set->warnings.empty()) << set->warnings.front();
  // The interference did happen, and the rig saw it (not a lucky ordering).
  const std::string log = d->log();
  EXPECT_NE(log.find("another client switched it"), std::string::npos) << log;

  // Afterwards every lamp is back to its owner's state (on/off, level, colour mode and values):
  // the owner's lamps 2, 3, 5 were switched on again by the rig in their modes.
  // Lamps 1, 4 and 6, switched on by the other client mid-set, go back to off.
  expect_owner_states(b, owner);
  EXPECT_FALSE(fs::exists(store / "lamps-owner.json"));

  // A plain exit leaves the owner's lamps alone (it used to switch them all off).
  d->stop(SIGTERM);
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  expect_owner_states(b, owner);
  fs::remove_all(dir);
}

TEST(LampOwner, ACrashWhileTheRigHoldsTheLampsIsRepairedAtTheNextStart) {
  fs::path dir = rigtest::temp_dir("owner-crash");
  Bridge b;
  ASSERT_TRUE(b.app);
  const auto owner = owners_states();
  b.app_sets(owner);
  fs::path store = dir / "store";
  fs::path config = write_config(dir, b, "rig-key");
  {
    auto d = DaemonProcess::start(store, {"--config", config.string()});
    ASSERT_TRUE(d && d->port() != 0) << (d ? d->log() : "");
    auto c = connect(*d, store);
    ASSERT_TRUE(c);
    ASSERT_TRUE(c->capture());
    auto shot = c->wait_event([](const veneer::rig::Event& e) { return e.kind == Kind::shot_taken && e.k == 3; }, 60);
    ASSERT_TRUE(shot) << shot.message();
    d->stop(SIGKILL);  // power cut with lamp 3 (or 2) on in rig white
  }
  ASSERT_TRUE(fs::exists(store / "lamps-owner.json"));
  // The lamps are not the owner's now.
  auto during = b.now();
  int differ = 0;
  for (size_t i = 0; i < owner.size(); ++i) differ += veneerd::same_light(during[i], owner[i]) ? 0 : 1;
  EXPECT_GT(differ, 0);

  auto d = DaemonProcess::start(store, {"--config", config.string()});
  ASSERT_TRUE(d && d->port() != 0) << (d ? d->log() : "");
  bool back = false;
  for (int i = 0; i < 100 && !back; ++i) {
    back = !fs::exists(store / "lamps-owner.json");
    if (!back) std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  EXPECT_TRUE(back) << d->log();
  expect_owner_states(b, owner);
  EXPECT_NE(d->log().find("after an interrupted run"), std::string::npos) << d->log();
  fs::remove_all(dir);
}

TEST(LampOwner, AWrongKeyIsNamedWithTheFixAndTheRigIsNotReady) {
  fs::path dir = rigtest::temp_dir("owner-key");
  Bridge b;
  ASSERT_TRUE(b.app);
  fs::path store = dir / "store";
  auto d = DaemonProcess::start(store, {"--config", write_config(dir, b, "not-paired").string()});
  ASSERT_TRUE(d && d->port() != 0) << (d ? d->log() : "");
  auto c = connect(*d, store);
  ASSERT_TRUE(c);
  veneer::Expected<veneer::rig::RigStatus> s = veneer::make_error("no status");
  for (int i = 0; i < 100; ++i) {
    s = c->status();
    ASSERT_TRUE(s) << s.message();
    if (!s->lamps_problem.empty()) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  EXPECT_FALSE(s->ready);
  EXPECT_NE(s->lamps_problem.find("refused the key 'not-paired'"), std::string::npos) << s->lamps_problem;
  EXPECT_NE(s->lamps_problem.find("veneerd hue pair --address " + b.emulator.address()), std::string::npos)
      << s->lamps_problem;
  EXPECT_NE(d->log().find("NOT ready"), std::string::npos) << d->log();
  // The CLI says so too.
  auto out = rigtest::run(rigtest::veneer_cli() + rigtest::cli_rig_args(d->address(), store) + " status");
  EXPECT_NE(out.out.find("NOT READY"), std::string::npos) << out.out;
  EXPECT_NE(out.out.find("veneerd hue pair"), std::string::npos) << out.out;
  fs::remove_all(dir);
}
