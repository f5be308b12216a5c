// The GPIO button and LED binding. Where the kernel's gpio-sim is available the
// button runs on a simulated chip; everywhere, real `struct gpioevent_data`
// records go through a pipe into libgpiod's own decoder
// (gpiod_line_event_read_fd), so decoding and debounce run for real.
#include <fcntl.h>
#include <linux/gpio.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <atomic>
#include <filesystem>
#include <fstream>
#include <future>
#include <thread>

#include "veneerd/hw/gpio.hpp"

namespace veneerd::hw {
namespace {

constexpr uint64_t ms = 1000;

struct PipeButton {
  int wr = -1;
  std::atomic<uint64_t> now{1000 * ms};
  std::unique_ptr<GpioTrigger> trigger;
  std::vector<Press> presses;

  explicit PipeButton(GpioButtonTiming timing = {}) {
    int p[2];
    EXPECT_EQ(::pipe(p), 0);
    wr = p[1];
    trigger = GpioTrigger::from_event_fd(p[0], /*active_low=*/true, /*initial_level=*/0, timing,
                                         [this] { return now.load(); });
    trigger->on_press = [this](Press pr) { presses.push_back(pr); };
  }
  ~PipeButton() {
    if (wr >= 0) ::close(wr);
  }
  // An edge on the physical line (active low: pressing pulls it down).
  void edge(bool rising, uint64_t t_us) {
    gpioevent_data ev{};
    ev.timestamp = t_us * 1000;  // the kernel stamps nanoseconds
    ev.id = rising ? GPIOEVENT_EVENT_RISING_EDGE : GPIOEVENT_EVENT_FALLING_EDGE;
    ASSERT_EQ(::write(wr, &ev, sizeof ev), ssize_t(sizeof ev));
  }
  void bounce_press(uint64_t t) {
    for (int i = 0; i < 5; ++i) edge(i % 2 == 1, t + i * ms);  // ends falling = pressed
  }
  void bounce_release(uint64_t t) {
    for (int i = 0; i < 5; ++i) edge(i % 2 == 0, t + i * ms);  // ends rising = released
  }
  // The daemon's loop: readable → on_readable; deadline → on_timer.
  void run_until(uint64_t t) {
    now = t;
    trigger->on_readable();
    while (auto dl = trigger->next_deadline_us()) {
      if (*dl > t) break;
      trigger->on_timer();
    }
  }
};

TEST(GpioButton, PipedEdgesWithBounceGiveOneShortPress) {
  PipeButton b;
  b.bounce_press(1100 * ms);
  b.bounce_release(1250 * ms);
  b.run_until(1300 * ms);
  EXPECT_TRUE(b.presses.empty());  // double-press window still open
  ASSERT_TRUE(b.trigger->next_deadline_us().has_value());
  EXPECT_EQ(*b.trigger->next_deadline_us(), 1250 * ms + 4 * ms + 350 * ms);
  b.run_until(2000 * ms);
  EXPECT_EQ(b.presses, std::vector<Press>{Press::short_press});
  EXPECT_EQ(b.trigger->bad_records(), 0u);
}

TEST(GpioButton, GlitchShorterThanDebounceIgnored) {
  PipeButton b;
  b.edge(false, 1100 * ms);
  b.edge(true, 1110 * ms);
  b.run_until(3000 * ms);
  EXPECT_TRUE(b.presses.empty());
}

TEST(GpioButton, LongPressFromTimerWhileHeld) {
  PipeButton b;
  b.bounce_press(1100 * ms);
  b.run_until(1500 * ms);
  EXPECT_TRUE(b.presses.empty());
  b.run_until(2000 * ms);  // 900 ms held
  EXPECT_EQ(b.presses, std::vector<Press>{Press::long_press});
  b.bounce_release(2500 * ms);
  b.run_until(4000 * ms);
  EXPECT_EQ(b.presses.size(), 1u);
}

TEST(GpioButton, DoublePress) {
  PipeButton b;
  b.bounce_press(1100 * ms);
  b.bounce_release(1200 * ms);
  b.bounce_press(1400 * ms);
  b.bounce_release(1500 * ms);
  b.run_until(3000 * ms);
  EXPECT_EQ(b.presses, std::vector<Press>{Press::double_press});
}

TEST(GpioButton, TimingFromConfigIsUsed) {
  GpioButtonTiming t;
  t.debounce_ms = 50;
  t.double_press_ms = 0;
  PipeButton b(t);
  b.edge(false, 1100 * ms);
  b.edge(true, 1140 * ms);  // 40 ms < 50 ms debounce
  b.run_until(2000 * ms);
  EXPECT_TRUE(b.presses.empty());
  b.edge(false, 2100 * ms);
  b.edge(true, 2200 * ms);
  b.run_until(2300 * ms);  // no double window: reported right after the release
  EXPECT_EQ(b.presses, std::vector<Press>{Press::short_press});
}

TEST(GpioButton, TruncatedRecordStopsTheStreamCleanly) {
  PipeButton b;
  b.bounce_press(1100 * ms);
  b.run_until(1200 * ms);
  // Half a record: libgpiod's reader reports EIO; the binding logs it, counts
  // it and stops watching the descriptor instead of spinning on it.
  gpioevent_data half{};
  ASSERT_EQ(::write(b.wr, &half, 8), 8);
  b.run_until(1300 * ms);
  EXPECT_EQ(b.trigger->bad_records(), 1u);
  EXPECT_EQ(b.trigger->fd(), -1);
  // What was already debounced still completes: the button was held.
  b.run_until(2500 * ms);
  EXPECT_EQ(b.presses, std::vector<Press>{Press::long_press});
}

TEST(GpioButton, ClosedEventSourceDisablesButtonWithoutCrash) {
  PipeButton b;
  ::close(b.wr);
  b.wr = -1;
  b.trigger->on_readable();
  EXPECT_EQ(b.trigger->fd(), -1);
  b.trigger->on_readable();  // harmless afterwards
}

TEST(GpioButton, OwnThreadDeliversPresses) {
  int p[2];
  ASSERT_EQ(::pipe(p), 0);
  auto trigger = GpioTrigger::from_event_fd(p[0], true, 0, {});
  std::promise<Press> got;
  std::atomic<bool> once{false};
  trigger->on_press = [&](Press pr) {
    if (!once.exchange(true)) got.set_value(pr);
  };
  ASSERT_TRUE(trigger->start().ok());
  uint64_t t0 = monotonic_us();
  gpioevent_data ev{};
  ev.timestamp = t0 * 1000;
  ev.id = GPIOEVENT_EVENT_FALLING_EDGE;
  ASSERT_EQ(::write(p[1], &ev, sizeof ev), ssize_t(sizeof ev));
  auto f = got.get_future();
  ASSERT_EQ(f.wait_for(std::chrono::seconds(10)), std::future_status::ready);
  EXPECT_EQ(f.get(), Press::long_press);  // held (no release sent) → long
  trigger->stop();
  ::close(p[1]);
}

// gpio-sim: a simulated chip through configfs (needs Linux 5.17+, the module, root).
TEST(GpioButton, GpioSimChip) {
  namespace fs = std::filesystem;
  const fs::path root = "/sys/kernel/config/gpio-sim";
  if (!fs::exists(root))
    GTEST_SKIP() << "gpio-sim not available (" << root << " missing: no configfs or gpio-sim module); "
                 << "the pipe tests above cover decoding and debounce";
  std::error_code ec;
  fs::path dev = root / ("veneer-test-" + std::to_string(::getpid()));
  if (!fs::create_directory(dev, ec)) GTEST_SKIP() << "cannot create " << dev << ": " << ec.message() << " (needs root)";
  auto put = [](const fs::path& p, const std::string& v) {
    std::ofstream f(p);
    f << v;
    return bool(f.flush());
  };
  fs::create_directory(dev / "bank0");
  fs::create_directory(dev / "bank0" / "line0");
  bool ok = put(dev / "bank0" / "num_lines", "4") && put(dev / "bank0" / "line0" / "name", "VENEER_BTN") &&
            put(dev / "live", "1");
  auto cleanup = [&] {
    put(dev / "live", "0");
    fs::remove(dev / "bank0" / "line0", ec);
    fs::remove(dev / "bank0", ec);
    fs::remove(dev, ec);
  };
  if (!ok) {
    cleanup();
    GTEST_SKIP() << "gpio-sim refused the test chip";
  }
  std::string chip, devname;
  std::ifstream(dev / "bank0" / "chip_name") >> chip;
  std::ifstream(dev / "dev_name") >> devname;
  fs::path pull = fs::path("/sys/devices/platform") / devname / chip / "sim_gpio0" / "pull";
  put(pull, "pull-up");  // released (active low)
  GpioLineConfig line;
  line.line = "VENEER_BTN";
  GpioButtonTiming timing;
  timing.double_press_ms = 0;
  auto trigger = GpioTrigger::open(line, timing);
  ASSERT_TRUE(trigger.ok()) << trigger.message();
  std::promise<Press> got;
  (*trigger)->on_press = [&](Press p) { got.set_value(p); };
  ASSERT_TRUE((*trigger)->start().ok());
  put(pull, "pull-down");
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  put(pull, "pull-up");
  auto f = got.get_future();
  EXPECT_EQ(f.wait_for(std::chrono::seconds(10)), std::future_status::ready);
  if (f.valid()) {
    EXPECT_EQ(f.get(), Press::short_press);
  }
  (*trigger)->stop();
  trigger->reset();
  cleanup();
}

TEST(GpioButton, MissingLineNamesWhatExists) {
  GpioLineConfig line;
  line.line = "GPIO17";
  auto t = GpioTrigger::open(line, {});
  if (!list_gpio_chips().empty() && t.ok()) GTEST_SKIP() << "this machine has a line named GPIO17";
  ASSERT_FALSE(t.ok());
  EXPECT_NE(t.message().find("GPIO17"), std::string::npos) << t.message();
  GpioLineConfig chip;
  chip.chip = "gpiochip-nonexistent";
  chip.offset = 3;
  auto c = GpioTrigger::open(chip, {});
  ASSERT_FALSE(c.ok());
  EXPECT_NE(c.message().find("gpiochip-nonexistent"), std::string::npos) << c.message();
}

TEST(GpioConfig, LineSectionErrorsNameTheField) {
  using nlohmann::json;
  auto name = parse_gpio_line(json{{"backend", "gpio"}, {"line", "GPIO17"}}, "trigger");
  ASSERT_TRUE(name.ok());
  EXPECT_EQ(name->line, "GPIO17");
  EXPECT_TRUE(name->active_low);
  auto alt = parse_gpio_line(json{{"chip", "gpiochip0"}, {"button_line", 17}}, "trigger", "button_line");
  ASSERT_TRUE(alt.ok()) << alt.message();
  EXPECT_EQ(alt->offset, 17);
  auto missing = parse_gpio_line(json{{"backend", "gpio"}}, "trigger");
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.message().find("trigger.line: missing"), std::string::npos) << missing.message();
  auto no_chip = parse_gpio_line(json{{"line", 17}}, "led");
  ASSERT_FALSE(no_chip.ok());
  EXPECT_NE(no_chip.message().find("needs \"chip\""), std::string::npos) << no_chip.message();
  auto range = parse_gpio_line(json{{"chip", "gpiochip0"}, {"line", 5000}}, "led");
  ASSERT_FALSE(range.ok());
  EXPECT_NE(range.message().find("led.line: offset 5000 out of range"), std::string::npos) << range.message();
  auto type = parse_gpio_line(json{{"line", true}}, "led");
  ASSERT_FALSE(type.ok());
  auto timing = parse_gpio_timing(json{{"debounce_ms", 0}}, "trigger");
  ASSERT_FALSE(timing.ok());
  EXPECT_NE(timing.message().find("trigger.debounce_ms"), std::string::npos) << timing.message();
  auto order = parse_gpio_timing(json{{"debounce_ms", 500}, {"long_press_ms", 400}}, "trigger");
  ASSERT_FALSE(order.ok());
}

TEST(GpioLed, PatternDrivenByTicks) {
  std::vector<int> levels;
  uint64_t now = 0;
  auto led = GpioLed::with_sink([&](int l) { levels.push_back(l); }, [&] { return now; });
  led->tick();
  EXPECT_EQ(levels, std::vector<int>{1});  // idle: steady on
  EXPECT_FALSE(led->tick().has_value());
  led->show(LedState::capturing);
  std::string trace;
  for (int i = 0; i < 8; ++i) {
    auto next = led->tick();
    ASSERT_TRUE(next.has_value());
    trace += char('0' + levels.back());
    now = *next;
  }
  EXPECT_EQ(trace, "10101010");
  EXPECT_EQ(now, 4 * 500 * ms);  // 2 Hz: a change every 250 ms
  led->show(LedState::no_camera);
  auto next = led->tick();
  ASSERT_TRUE(next.has_value());
  EXPECT_EQ(*next - now, 1000 * ms);
  EXPECT_EQ(led->state(), LedState::no_camera);
}

TEST(GpioLed, ThreadRunsAndGoesDarkOnStop) {
  std::mutex mu;
  std::vector<int> levels;
  auto led = GpioLed::with_sink([&](int l) {
    std::lock_guard<std::mutex> g(mu);
    levels.push_back(l);
  });
  ASSERT_TRUE(led->start().ok());
  led->show(LedState::error);
  for (int i = 0; i < 200; ++i) {
    {
      std::lock_guard<std::mutex> g(mu);
      if (levels.size() >= 3) break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  led->stop();
  std::lock_guard<std::mutex> g(mu);
  ASSERT_GE(levels.size(), 3u);
  EXPECT_EQ(levels.back(), 0);
}

}  // namespace
}  // namespace veneerd::hw
