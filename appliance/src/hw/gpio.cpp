// GPIO button and status LED through libgpiod 1.6, with the logic from firmware/.
#include "veneerd/hw/gpio.hpp"

#include <fcntl.h>
#include <gpiod.h>
#include <poll.h>
#include <time.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <memory>
#include <utility>

#include "button.h"
#include "led.h"
#include "veneer/util/log.hpp"

namespace veneerd::hw {

namespace {

constexpr const char* kConsumer = "veneerd";

uint64_t clock_us(clockid_t id) {
  timespec ts{};
  clock_gettime(id, &ts);
  return uint64_t(ts.tv_sec) * 1000000u + uint64_t(ts.tv_nsec) / 1000u;
}

std::string chip_list_text() {
  std::string out;
  for (const auto& c : list_gpio_chips()) out += (out.empty() ? "" : ", ") + c.name + " (" + c.label + ")";
  return out.empty() ? "none: no /dev/gpiochip* on this machine" : out;
}

std::string errno_text(int e) { return std::strerror(e); }

// An open GPIO chip and one of its lines, owned: the line's request is
// released, then the chip closed (which frees the line object), when the
// handle is destroyed or reset. Moves, never copies.
class LineHandle {
 public:
  LineHandle() = default;
  LineHandle(LineHandle&& o) noexcept : chip(std::exchange(o.chip, nullptr)), line(std::exchange(o.line, nullptr)) {}
  LineHandle& operator=(LineHandle&& o) noexcept {
    if (this != &o) {
      reset();
      chip = std::exchange(o.chip, nullptr);
      line = std::exchange(o.line, nullptr);
    }
    return *this;
  }
  LineHandle(const LineHandle&) = delete;
  LineHandle& operator=(const LineHandle&) = delete;
  ~LineHandle() { reset(); }
  void reset() {
    if (line) gpiod_line_release(line);  // a no-op when the line was not requested
    if (chip) gpiod_chip_close(chip);
    line = nullptr;
    chip = nullptr;
  }

  gpiod_chip* chip = nullptr;  // owned
  gpiod_line* line = nullptr;  // belongs to `chip`
};

veneer::Expected<LineHandle> find_line(const GpioLineConfig& cfg) {
  LineHandle h;  // every return below closes what was opened
  if (!cfg.chip.empty()) {
    h.chip = gpiod_chip_open_lookup(cfg.chip.c_str());
    if (!h.chip) {
      int e = errno;
      if (e == EACCES || e == EPERM)
        return veneer::make_error("GPIO chip '" + cfg.chip + "': permission denied; add the daemon's user to group gpio (firmware/board/INSTALL.md)");
      return veneer::make_error("GPIO chip '" + cfg.chip + "' not found (chips: " + chip_list_text() + ")");
    }
    if (cfg.offset >= 0) {
      unsigned n = gpiod_chip_num_lines(h.chip);
      if (unsigned(cfg.offset) >= n) {
        std::string name = gpiod_chip_name(h.chip);
        return veneer::make_error("GPIO line offset " + std::to_string(cfg.offset) + " out of range: " + name + " has " +
                                  std::to_string(n) + " lines (0.." + std::to_string(n ? n - 1 : 0) + ")");
      }
      h.line = gpiod_chip_get_line(h.chip, unsigned(cfg.offset));
    } else {
      h.line = gpiod_chip_find_line(h.chip, cfg.line.c_str());
      if (!h.line) {
        std::string name = gpiod_chip_name(h.chip);
        return veneer::make_error("no GPIO line named '" + cfg.line + "' on " + name);
      }
    }
  } else {
    h.line = gpiod_line_find(cfg.line.c_str());
    if (!h.line) return veneer::make_error("no GPIO line named '" + cfg.line + "' on any chip (chips: " + chip_list_text() + ")");
    h.chip = gpiod_line_get_chip(h.line);  // opened by gpiod_line_find: ours to close
  }
  if (!h.line) {
    return veneer::make_error("cannot get GPIO line " + cfg.describe() + ": " + errno_text(errno));
  }
  return h;
}

veneer::Status request_error(LineHandle& h, const GpioLineConfig& cfg, int e) {
  std::string msg;
  if (e == EBUSY) {
    const char* who = gpiod_line_consumer(h.line);
    msg = "GPIO line " + cfg.describe() + " is in use by " + (who ? std::string("'") + who + "'" : "another program");
  } else {
    msg = "cannot request GPIO line " + cfg.describe() + ": " + errno_text(e);
  }
  h.reset();
  return veneer::make_error(msg);
}

}  // namespace

uint64_t monotonic_us() { return clock_us(CLOCK_MONOTONIC); }

std::string GpioLineConfig::describe() const {
  std::string where = chip.empty() ? "" : chip + ":";
  return offset >= 0 ? where + std::to_string(offset) : where + line;
}

veneer::Expected<GpioLineConfig> parse_gpio_line(const nlohmann::json& s, const std::string& where,
                                                 const char* alt_key) {
  if (!s.is_object()) return veneer::make_error(where + ": expected an object");
  GpioLineConfig c;
  if (s.contains("chip")) {
    if (!s["chip"].is_string()) return veneer::make_error(where + ".chip: expected a string like \"gpiochip0\"");
    c.chip = s["chip"].get<std::string>();
  }
  std::string key = "line";
  if (!s.contains("line") && alt_key && s.contains(alt_key)) key = alt_key;
  if (!s.contains(key))
    return veneer::make_error(where + ".line: missing (a line name like \"GPIO17\", or an offset together with \"chip\")");
  const auto& l = s[key];
  const std::string field = where + "." + key;
  if (l.is_string()) {
    c.line = l.get<std::string>();
    if (c.line.empty()) return veneer::make_error(field + ": empty line name");
  } else if (l.is_number_integer()) {
    long long v = l.get<long long>();
    if (v < 0 || v > 1023) return veneer::make_error(field + ": offset " + std::to_string(v) + " out of range (0..1023)");
    if (c.chip.empty()) return veneer::make_error(field + ": offset " + std::to_string(v) + " needs \"chip\" (or give the line's name)");
    c.offset = int(v);
  } else {
    return veneer::make_error(field + ": expected a line name (string) or an offset (integer)");
  }
  if (s.contains("active_low")) {
    if (!s["active_low"].is_boolean()) return veneer::make_error(where + ".active_low: expected true or false");
    c.active_low = s["active_low"].get<bool>();
  }
  return c;
}

veneer::Expected<GpioButtonTiming> parse_gpio_timing(const nlohmann::json& s, const std::string& where) {
  GpioButtonTiming t;
  struct Field {
    const char* key;
    uint32_t* value;
    long long lo, hi;
  } fields[] = {{"debounce_ms", &t.debounce_ms, 1, 1000},
                {"long_press_ms", &t.long_press_ms, 100, 20000},
                {"double_press_ms", &t.double_press_ms, 0, 5000}};
  for (auto& f : fields) {
    if (!s.contains(f.key)) continue;
    const auto& v = s[f.key];
    if (!v.is_number_integer()) return veneer::make_error(where + "." + f.key + ": expected an integer (milliseconds)");
    long long x = v.get<long long>();
    if (x < f.lo || x > f.hi)
      return veneer::make_error(where + "." + f.key + ": " + std::to_string(x) + " out of range (" + std::to_string(f.lo) +
                                ".." + std::to_string(f.hi) + ")");
    *f.value = uint32_t(x);
  }
  if (t.long_press_ms <= t.debounce_ms)
    return veneer::make_error(where + ".long_press_ms: must be longer than debounce_ms");
  return t;
}

std::vector<GpioChipInfo> list_gpio_chips() {
  std::vector<GpioChipInfo> out;
  // The iterator owns the chip it is at (closed when it moves on or is freed).
  struct IterFree {
    void operator()(gpiod_chip_iter* i) const { gpiod_chip_iter_free(i); }
  };
  std::unique_ptr<gpiod_chip_iter, IterFree> iter(gpiod_chip_iter_new());
  if (!iter) return out;
  gpiod_chip_iter* it = iter.get();
  gpiod_chip* chip;
  gpiod_foreach_chip(it, chip) {
    GpioChipInfo info;
    info.name = gpiod_chip_name(chip);
    info.label = gpiod_chip_label(chip);
    info.path = "/dev/" + info.name;
    info.lines = gpiod_chip_num_lines(chip);
    for (unsigned i = 0; i < info.lines; ++i) {
      gpiod_line* l = gpiod_chip_get_line(chip, i);
      const char* n = l ? gpiod_line_name(l) : nullptr;
      info.line_names.push_back(n ? n : "");
    }
    out.push_back(std::move(info));
  }
  return out;
}

// ---------------------------------------------------------------- trigger

struct GpioTrigger::Impl {
  LineHandle handle;
  int fd = -1;
  bool own_fd = false;
  bool active_low = true;
  std::atomic<bool> dead{false};  // read by fd() from the polling thread
  bool real_clock = true;
  std::function<uint64_t()> clock;
  vf_button button{};
  ~Impl() {
    if (own_fd && fd >= 0) ::close(fd);
  }
};

GpioTrigger::GpioTrigger(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

GpioTrigger::~GpioTrigger() { stop(); }

static vf_button_config to_firmware(const GpioButtonTiming& t) {
  vf_button_config c;
  c.debounce_us = t.debounce_ms * 1000u;
  c.long_press_us = t.long_press_ms * 1000u;
  c.double_gap_us = t.double_press_ms * 1000u;
  return c;
}

veneer::Expected<std::unique_ptr<GpioTrigger>> GpioTrigger::open(const GpioLineConfig& cfg,
                                                                   const GpioButtonTiming& timing) {
  auto found = find_line(cfg);
  if (!found) return found.error();
  auto impl = std::make_unique<Impl>();
  impl->handle = std::move(*found);
  // The line is requested active-high; the inversion for active-low buttons is
  // done here so edge directions mean the same on every kernel.
  int flags = cfg.active_low ? GPIOD_LINE_REQUEST_FLAG_BIAS_PULL_UP : GPIOD_LINE_REQUEST_FLAG_BIAS_PULL_DOWN;
  if (gpiod_line_request_both_edges_events_flags(impl->handle.line, kConsumer, flags) < 0) {
    // Older kernels reject bias flags; an external resistor does the job then.
    int e = errno;
    if (e == EBUSY || gpiod_line_request_both_edges_events(impl->handle.line, kConsumer) < 0)
      return request_error(impl->handle, cfg, e == EBUSY ? e : errno).error();
  }
  impl->fd = gpiod_line_event_get_fd(impl->handle.line);
  impl->own_fd = false;
  impl->active_low = cfg.active_low;
  impl->clock = monotonic_us;
  int raw = gpiod_line_get_value(impl->handle.line);
  int level = raw < 0 ? 0 : (cfg.active_low ? !raw : raw);
  vf_button_config bc = to_firmware(timing);
  vf_button_init(&impl->button, &bc, level, impl->clock());
  ::fcntl(impl->fd, F_SETFL, ::fcntl(impl->fd, F_GETFL) | O_NONBLOCK);
  VLOG_INFO("Trigger", "button on GPIO line {} ({}), level {}", cfg.describe(),
            cfg.active_low ? "active low" : "active high", level ? "pressed" : "released");
  return std::unique_ptr<GpioTrigger>(new GpioTrigger(std::move(impl)));
}

std::unique_ptr<GpioTrigger> GpioTrigger::from_event_fd(int fd, bool active_low, int initial_level,
                                                        const GpioButtonTiming& timing,
                                                        std::function<uint64_t()> clock) {
  auto impl = std::make_unique<Impl>();
  impl->fd = fd;
  impl->own_fd = true;
  impl->active_low = active_low;
  impl->real_clock = false;
  impl->clock = std::move(clock);
  vf_button_config bc = to_firmware(timing);
  vf_button_init(&impl->button, &bc, initial_level, impl->clock());
  ::fcntl(fd, F_SETFL, ::fcntl(fd, F_GETFL) | O_NONBLOCK);
  return std::unique_ptr<GpioTrigger>(new GpioTrigger(std::move(impl)));
}

int GpioTrigger::fd() const { return impl_->dead ? -1 : impl_->fd; }

uint64_t GpioTrigger::to_monotonic(uint64_t event_us) {
  if (!impl_->real_clock) return event_us;
  // Kernels before 5.7 stamp events with CLOCK_REALTIME: move those onto the
  // monotonic clock the deadlines use.
  uint64_t mono = clock_us(CLOCK_MONOTONIC);
  if (event_us > mono + 3600ull * 1000000ull) {
    uint64_t real = clock_us(CLOCK_REALTIME);
    return event_us - (real - mono);
  }
  return event_us;
}

void GpioTrigger::on_readable() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (impl_->dead) return;
    for (;;) {
      gpiod_line_event ev{};
      if (gpiod_line_event_read_fd(impl_->fd, &ev) < 0) {
        if (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR) break;
        // A short or failed read: the event source is gone (EOF) or broken.
        bad_records_++;
        impl_->dead = true;
        VLOG_ERROR("Trigger", "GPIO event stream failed ({}); button disabled", errno_text(errno));
        break;
      }
      uint64_t t = to_monotonic(uint64_t(ev.ts.tv_sec) * 1000000u + uint64_t(ev.ts.tv_nsec) / 1000u);
      int phys;
      if (ev.event_type == GPIOD_LINE_EVENT_RISING_EDGE) {
        phys = 1;
      } else if (ev.event_type == GPIOD_LINE_EVENT_FALLING_EDGE) {
        phys = 0;
      } else {
        bad_records_++;
        continue;
      }
      int level = impl_->active_low ? !phys : phys;
      VLOG_DEBUG("Trigger", "edge {} at {} us", level ? "down" : "up", t);
      vf_button_edge(&impl_->button, level, t);
    }
    vf_button_update(&impl_->button, impl_->clock());
  }
  deliver();
}

std::optional<uint64_t> GpioTrigger::next_deadline_us() const {
  std::lock_guard<std::mutex> lock(mu_);
  uint64_t t;
  if (vf_button_next_deadline(&impl_->button, &t)) return t;
  return std::nullopt;
}

void GpioTrigger::on_timer() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    vf_button_update(&impl_->button, impl_->clock());
  }
  deliver();
}

void GpioTrigger::deliver() {
  std::vector<Press> presses;
  {
    std::lock_guard<std::mutex> lock(mu_);
    vf_button_event e;
    while (vf_button_pop(&impl_->button, &e)) {
      switch (e.press) {
        case VF_PRESS_SHORT: presses.push_back(Press::short_press); break;
        case VF_PRESS_LONG: presses.push_back(Press::long_press); break;
        case VF_PRESS_DOUBLE: presses.push_back(Press::double_press); break;
        default: break;
      }
    }
  }
  for (Press p : presses) {
    VLOG_INFO("Trigger", "{} press", p == Press::short_press ? "short" : p == Press::long_press ? "long" : "double");
    if (on_press) on_press(p);
  }
}

veneer::Status GpioTrigger::start() {
  if (thread_.joinable()) return {};
  if (::pipe2(wake_, O_CLOEXEC | O_NONBLOCK) < 0) return veneer::make_error("cannot create wake pipe: " + errno_text(errno));
  thread_ = std::thread([this] {
    for (;;) {
      pollfd fds[2] = {{fd(), POLLIN, 0}, {wake_[0], POLLIN, 0}};
      int timeout = -1;
      if (auto dl = next_deadline_us()) {
        uint64_t now = impl_->clock();
        timeout = *dl <= now ? 0 : int((*dl - now + 999) / 1000);
      }
      int r = ::poll(fds, 2, timeout);
      if (r < 0 && errno != EINTR) break;
      if (fds[1].revents) break;
      if (fds[0].revents) on_readable();
      on_timer();
    }
  });
  return {};
}

void GpioTrigger::stop() {
  if (thread_.joinable()) {
    char c = 1;
    (void)!::write(wake_[1], &c, 1);
    thread_.join();
  }
  for (int& f : wake_) {
    if (f >= 0) ::close(f);
    f = -1;
  }
}

// ---------------------------------------------------------------- LED

struct GpioLed::Impl {
  LineHandle handle;
  bool active_low = false;
  std::function<void(int)> sink;
  std::function<uint64_t()> clock;
  LedState state = LedState::idle;
  uint64_t since = 0;
  int last = -1;
};

GpioLed::GpioLed(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
GpioLed::~GpioLed() {
  stop();
}

veneer::Expected<std::unique_ptr<GpioLed>> GpioLed::open(const GpioLineConfig& cfg) {
  auto found = find_line(cfg);
  if (!found) return found.error();
  auto impl = std::make_unique<Impl>();
  impl->handle = std::move(*found);
  int flags = cfg.active_low ? GPIOD_LINE_REQUEST_FLAG_ACTIVE_LOW : 0;
  if (gpiod_line_request_output_flags(impl->handle.line, kConsumer, flags, 0) < 0)
    return request_error(impl->handle, cfg, errno).error();
  gpiod_line* line = impl->handle.line;
  impl->sink = [line](int level) { gpiod_line_set_value(line, level); };
  impl->clock = monotonic_us;
  impl->since = impl->clock();
  VLOG_INFO("Led", "status LED on GPIO line {}", cfg.describe());
  return std::unique_ptr<GpioLed>(new GpioLed(std::move(impl)));
}

std::unique_ptr<GpioLed> GpioLed::with_sink(std::function<void(int)> sink, std::function<uint64_t()> clock) {
  auto impl = std::make_unique<Impl>();
  impl->sink = std::move(sink);
  impl->clock = std::move(clock);
  impl->since = impl->clock();
  return std::unique_ptr<GpioLed>(new GpioLed(std::move(impl)));
}

static vf_led_state to_firmware(LedState s) {
  switch (s) {
    case LedState::idle: return VF_LED_IDLE;
    case LedState::capturing: return VF_LED_CAPTURING;
    case LedState::done: return VF_LED_DONE;
    case LedState::error: return VF_LED_ERROR;
    case LedState::no_camera: return VF_LED_NO_CAMERA;
  }
  return VF_LED_ERROR;
}

void GpioLed::show(LedState state) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (state == impl_->state && impl_->last >= 0) return;
    impl_->state = state;
    impl_->since = impl_->clock();
  }
  if (wake_[1] >= 0) {
    char c = 1;
    (void)!::write(wake_[1], &c, 1);
  }
}

LedState GpioLed::state() const {
  std::lock_guard<std::mutex> lock(mu_);
  return impl_->state;
}

std::optional<uint64_t> GpioLed::tick() {
  std::lock_guard<std::mutex> lock(mu_);
  uint64_t now = impl_->clock();
  vf_led_state s = to_firmware(impl_->state);
  int level = vf_led_level(s, impl_->since, now);
  if (level != impl_->last) {
    impl_->sink(level);
    impl_->last = level;
  }
  uint64_t at;
  if (vf_led_next_change(s, impl_->since, now, &at)) return at;
  return std::nullopt;
}

veneer::Status GpioLed::start() {
  if (thread_.joinable()) return {};
  if (::pipe2(wake_, O_CLOEXEC | O_NONBLOCK) < 0) return veneer::make_error("cannot create wake pipe: " + errno_text(errno));
  stopping_ = false;
  thread_ = std::thread([this] {
    for (;;) {
      auto next = tick();
      int timeout = -1;
      if (next) {
        uint64_t now = impl_->clock();
        timeout = *next <= now ? 0 : int((*next - now + 999) / 1000);
      }
      pollfd p{wake_[0], POLLIN, 0};
      int r = ::poll(&p, 1, timeout);
      if (r > 0) {
        char buf[64];
        while (::read(wake_[0], buf, sizeof buf) > 0) {
        }
      }
      std::lock_guard<std::mutex> lock(mu_);
      if (stopping_) break;
    }
  });
  return {};
}

void GpioLed::stop() {
  if (thread_.joinable()) {
    {
      std::lock_guard<std::mutex> lock(mu_);
      stopping_ = true;
    }
    char c = 1;
    (void)!::write(wake_[1], &c, 1);
    thread_.join();
    std::lock_guard<std::mutex> lock(mu_);
    impl_->sink(0);  // dark when the daemon stops
    impl_->last = 0;
  }
  for (int& f : wake_) {
    if (f >= 0) ::close(f);
    f = -1;
  }
}

}  // namespace veneerd::hw
