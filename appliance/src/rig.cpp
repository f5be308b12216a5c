#include "veneerd/rig.hpp"

#include <chrono>
#include <fstream>

#include "veneer/io/image_io.hpp"
#include "veneer/util/log.hpp"
#include "veneer/util/utc_time.hpp"
#include "veneerd/sequencer.hpp"

namespace veneerd {

using veneer::make_error;

namespace {

double unix_now() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

// Width and height from a JPEG's start-of-frame marker (0 when not found).
void jpeg_size(const std::vector<unsigned char>& j, int& w, int& h) {
  size_t i = 2;
  while (i + 9 < j.size()) {
    if (j[i] != 0xFF) return;
    unsigned char marker = j[i + 1];
    size_t len = (static_cast<size_t>(j[i + 2]) << 8) | j[i + 3];
    if (marker >= 0xC0 && marker <= 0xCF && marker != 0xC4 && marker != 0xC8 && marker != 0xCC) {
      h = (j[i + 5] << 8) | j[i + 6];
      w = (j[i + 7] << 8) | j[i + 8];
      return;
    }
    i += 2 + len;
  }
}

}  // namespace

Rig::Rig(RigDevices devices, Store& store, RigOptions options)
    : dev_(std::move(devices)), store_(store), options_(std::move(options)) {}

Rig::~Rig() { stop(); }

void Rig::emit(RigEvent event) {
  if (on_event) on_event(event);
}

void Rig::post(std::function<void()> job) {
  {
    std::lock_guard lock(jobs_mutex_);
    jobs_.push_back(std::move(job));
  }
  jobs_cv_.notify_one();
}

void Rig::start() {
  auto log = veneer::log::get("Rig");
  if (dev_.camera) {
    dev_.camera->on_connection_change = [this](bool connected) {
      std::string model;
      {
        std::lock_guard lock(mutex_);
        camera_connected_ = connected;
        model = camera_model_;
      }
      RigEvent e;
      e.kind = connected ? RigEvent::Kind::camera_connected : RigEvent::Kind::camera_lost;
      e.camera_model = model;
      if (!connected) e.reason = "camera disconnected";
      if (dev_.led) dev_.led->show(connected ? LedState::idle : LedState::no_camera);
      emit(e);
    };
  }
  if (dev_.trigger) dev_.trigger->on_press = [this](Press p) { handle_press(p); };
  worker_ = std::thread([this] { worker_loop(); });
  live_ = std::thread([this] { live_loop(); });
  post([this, log] {
    if (dev_.camera) {
      std::lock_guard cam(camera_mutex_);
      if (auto s = dev_.camera->open(); !s) {
        VLOG_WARN("Camera", "camera not ready: {}", s.message());
      } else {
        std::string model = dev_.camera->name();
        if (auto d = dev_.camera->describe(); d && !d->model.empty()) model = d->model;
        std::lock_guard lock(mutex_);
        camera_model_ = model;
        camera_connected_ = dev_.camera->connected();
      }
    }
    // The lamps are left as their owner has them; only what an interrupted
    // run took (a crash, a power loss) goes back.
    if (dev_.lamps) {
      std::error_code ec;
      if (!options_.owner_state_file.empty() && std::filesystem::exists(options_.owner_state_file, ec)) {
        owner_saved_ = true;
        give_back_owner("at start, after an interrupted run");
      }
      refresh_lamps();
    }
    std::string problem, camera;
    bool connected = false;
    {
      std::lock_guard lock(mutex_);
      problem = lamps_problem_;
      camera = camera_model_;
      connected = camera_connected_;
    }
    if (!connected) problem += std::string(problem.empty() ? "" : "; ") + "camera: not connected";
    if (dev_.led) dev_.led->show(problem.empty() ? LedState::idle : LedState::error);
    if (problem.empty()) {
      log->info("rig '{}' ready: {} lamps, camera {}", options_.name, dev_.lamps ? dev_.lamps->count() : 0,
                camera.empty() ? "(none)" : camera);
    } else {
      log->error("rig '{}' NOT ready: {}", options_.name, problem);
    }
  });
}

void Rig::stop() {
  if (stopping_.exchange(true)) return;
  cancel_ = true;
  jobs_cv_.notify_all();
  live_cv_.notify_all();
  if (worker_.joinable()) worker_.join();
  if (live_.joinable()) live_.join();
  // Lamps a client switched (or a capture could not give back) go back to
  // their owner; the others are left as they are.
  if (dev_.lamps && owner_saved_) give_back_owner("at exit");
  if (dev_.trigger) dev_.trigger->on_press = nullptr;
  if (dev_.camera) dev_.camera->on_connection_change = nullptr;
}

void Rig::worker_loop() {
  for (;;) {
    std::function<void()> job;
    {
      std::unique_lock lock(jobs_mutex_);
      if (pending_restore_.needed) {
        // The bridge was down when a capture ended: try again every second.
        jobs_cv_.wait_for(lock, std::chrono::seconds(1), [&] { return stopping_ || !jobs_.empty(); });
      } else if (options_.lamp_poll_s > 0 && dev_.lamps) {
        // Idle: read the bridge now and then, so the status shows the lamps as they are.
        jobs_cv_.wait_for(lock, std::chrono::duration<double>(options_.lamp_poll_s),
                          [&] { return stopping_ || !jobs_.empty(); });
      } else {
        jobs_cv_.wait(lock, [&] { return stopping_ || !jobs_.empty(); });
      }
      if (stopping_) return;
      if (!jobs_.empty()) {
        job = std::move(jobs_.front());
        jobs_.pop_front();
      }
    }
    if (job) {
      job();
    } else if (pending_restore_.needed) {
      retry_restore();
    } else {
      refresh_lamps();
    }
  }
}

void Rig::retry_restore() {
  if (!pending_restore_.needed || !dev_.lamps) return;
  if (auto s = dev_.lamps->restore(pending_restore_.states); !s) {
    VLOG_DEBUG("Lamps", "restoring the lamps still fails: {}", s.message());
    return;
  }
  pending_restore_.needed = false;
  if (owner_by_capture_) drop_owner();
  VLOG_INFO("Lamps", "the bridge answers again: lamps restored to their state before the capture");
  refresh_lamps();
}

void Rig::note_lamps(const veneer::Expected<std::vector<LampState>>& reading) {
  std::lock_guard lock(mutex_);
  if (reading) {
    lamps_now_ = *reading;
    lamps_read_at_ = std::chrono::steady_clock::now();
    lamps_problem_.clear();
  } else {
    lamps_problem_ = "lamps: " + reading.message();
  }
}

void Rig::refresh_lamps() {
  if (!dev_.lamps) return;
  auto reading = dev_.lamps->read();
  std::string before;
  {
    std::lock_guard lock(mutex_);
    before = lamps_problem_;
  }
  note_lamps(reading);
  if (!reading && before != "lamps: " + reading.message()) VLOG_ERROR("Lamps", "{}", reading.message());
  if (reading && !before.empty()) VLOG_INFO("Lamps", "the lamps answer again");
}

veneer::Status Rig::save_owner(const std::vector<LampState>& states) {
  if (options_.owner_state_file.empty()) {
    owner_saved_ = true;  // kept in memory only
    return {};
  }
  nlohmann::json doc;
  doc["format"] = "veneer-lamp-owner/1";
  doc["saved"] = veneer::utc_now();
  doc["lamps"] = nlohmann::json::array();
  for (std::size_t i = 0; i < states.size(); ++i) {
    nlohmann::json l = to_json(states[i]);
    l["id"] = i < options_.lamp_ids.size() ? options_.lamp_ids[i] : std::to_string(i + 1);
    doc["lamps"].push_back(l);
  }
  const auto& file = options_.owner_state_file;
  if (auto s = veneer::io::write_file_atomic(file, doc.dump(1) + "\n"); !s)
    return make_error("cannot write " + file.string() + " (disk full?): " + s.message());
  owner_saved_ = true;
  return {};
}

veneer::Expected<std::vector<LampState>> Rig::load_owner() {
  const auto& file = options_.owner_state_file;
  std::ifstream in(file);
  if (!in) return make_error("cannot read " + file.string());
  nlohmann::json doc = nlohmann::json::parse(in, nullptr, false);
  if (doc.is_discarded() || !doc.is_object() || !doc.contains("lamps") || !doc["lamps"].is_array())
    return make_error(file.string() + " is not a saved lamp state");
  const int count = dev_.lamps->count();
  if (static_cast<int>(doc["lamps"].size()) != count)
    return make_error(file.string() + " holds " + std::to_string(doc["lamps"].size()) + " lamps, the rig has " +
                      std::to_string(count));
  std::vector<LampState> out;
  for (const auto& l : doc["lamps"]) {
    auto s = lamp_state_from_json(l);
    if (!s) return make_error(file.string() + ": " + s.message());
    out.push_back(*s);
  }
  return out;
}

void Rig::drop_owner() {
  owner_saved_ = false;
  owner_by_capture_ = false;
  if (options_.owner_state_file.empty()) return;
  std::error_code ec;
  std::filesystem::remove(options_.owner_state_file, ec);
}

void Rig::give_back_owner(const char* when) {
  if (!owner_saved_ || !dev_.lamps) return;
  if (options_.owner_state_file.empty()) {  // nothing kept on disk: only a pending restore can be retried
    retry_restore();
    drop_owner();
    return;
  }
  auto states = load_owner();
  if (!states) {
    VLOG_ERROR("Lamps", "{}: {}; the owner's lamp states are lost, the file is kept for inspection", when,
               states.message());
    std::error_code ec;
    std::filesystem::rename(options_.owner_state_file, options_.owner_state_file.string() + ".bad", ec);
    owner_saved_ = false;
    return;
  }
  if (auto s = dev_.lamps->restore(*states); !s) {
    VLOG_ERROR("Lamps", "{}: giving the lamps back to their owner failed: {}; kept in {} for the next start", when,
               s.message(), options_.owner_state_file.string());
    return;
  }
  VLOG_INFO("Lamps", "{}: the lamps are back as their owner had them (from {})", when,
            options_.owner_state_file.string());
  pending_restore_.needed = false;
  drop_owner();
}

veneer::Expected<std::string> Rig::capture(const CaptureRequest& request) {
  if (!dev_.lamps || !dev_.camera) return make_error("the rig has no lamps or no camera");
  CaptureRequest req = request;
  std::string id;
  {
    std::lock_guard lock(mutex_);
    if (capturing_) return make_error("a capture is already running (" + capture_id_ + ")");
    if (req.role == veneer::io::Role::unknown) req.role = next_role_;
    if (req.object.empty() && options_.simulated && options_.sim.scenes.size() >= 2) {
      req.object = options_.sim.scenes[req.role == veneer::io::Role::source ? 1 : 0];
    }
    id = store_.new_id(req.role, req.object);
    capturing_ = true;
    capture_id_ = id;
    cancel_ = false;
  }
  post([this, id, req] { run_capture_job(id, req); });
  return id;
}

veneer::Status Rig::cancel() {
  std::lock_guard lock(mutex_);
  if (!capturing_) return make_error("no capture is running");
  cancel_ = true;
  return {};
}

void Rig::press(Press p) {
  if (dev_.trigger) {
    dev_.trigger->press(p);  // the simulated button counts it, then calls on_press
  } else {
    handle_press(p);
  }
}

void Rig::handle_press(Press p) {
  if (stopping_) return;
  RigEvent e;
  e.kind = RigEvent::Kind::button_pressed;
  e.long_press = p == Press::long_press;
  emit(e);
  if (p == Press::long_press) {
    if (auto s = cancel(); !s) VLOG_INFO("Trigger", "long press: {}", s.message());
    return;
  }
  if (auto id = capture({}); !id) VLOG_INFO("Trigger", "press ignored: {}", id.message());
}

void Rig::run_capture_job(const std::string& id, CaptureRequest req) {
  auto log = veneer::log::get("Rig");
  if (dev_.led) dev_.led->show(LedState::capturing);
  const int n = dev_.lamps->count() + 1;

  CapturePlan plan;
  plan.set_id = id;
  plan.role = req.role;
  plan.object = req.object.empty() ? veneer::io::role_name(req.role) : req.object;
  plan.exposure = req.exposure;
  if (plan.exposure.shutter_s <= 0) plan.exposure.shutter_s = options_.exposure.shutter_s;
  if (plan.exposure.aperture <= 0) plan.exposure.aperture = options_.exposure.aperture;
  if (plan.exposure.iso <= 0) plan.exposure.iso = options_.exposure.iso;
  plan.lamp_ids = options_.lamp_ids;
  plan.lamp_positions = options_.lamp_positions;
  plan.ambient_warning = options_.ambient_warning;
  {
    std::lock_guard lock(mutex_);
    plan.expected_shot_s = mean_step_s_ > 0 ? mean_step_s_ : options_.settle_ms / 1000.0 + plan.exposure.shutter_s + 0.2;
  }
  if (options_.simulated && options_.sim.scenes.size() >= 2) {
    plan.scene = options_.sim.scenes[req.role == veneer::io::Role::source ? 1 : 0];
    if (options_.sim.select_scene) options_.sim.select_scene(req.role, plan.scene);
  }

  RigEvent started;
  started.kind = RigEvent::Kind::capture_started;
  started.set_id = id;
  started.role = req.role;
  started.object = plan.object;
  started.n = n;
  emit(started);
  log->info("capture {} started: {} '{}', {} shots", id, veneer::io::role_name(req.role), plan.object, n);

  CaptureHooks hooks;
  hooks.cancel = &cancel_;
  hooks.save_owner_state = [this](const std::vector<LampState>& states) -> veneer::Status {
    if (owner_saved_) return {};  // a client's lamp change holds older owner states
    if (auto s = save_owner(states); !s) return s;
    owner_by_capture_ = true;
    return {};
  };
  hooks.on_shot = [&](int k, int total, double eta) {
    RigEvent e;
    e.kind = RigEvent::Kind::shot_taken;
    e.set_id = id;
    e.k = k;
    e.n = total;
    e.eta_s = eta;
    emit(e);
  };

  retry_restore();
  if (pending_restore_.needed) {
    RigEvent failed;
    failed.kind = RigEvent::Kind::capture_failed;
    failed.set_id = id;
    failed.reason = "lamps: the bridge does not answer (the lamps from the last capture are not restored yet)";
    {
      std::lock_guard lock(mutex_);
      capturing_ = false;
      capture_id_.clear();
    }
    if (dev_.led) dev_.led->show(LedState::error);
    emit(failed);
    return;
  }
  // Each frame goes into the store's temporary folder as it is taken (a
  // full-resolution set as float is 2 GiB; the board holds one frame).
  veneer::Expected<CaptureResult> result = make_error("not run");
  std::unique_ptr<SetWriter> writer;
  if (auto w = store_.begin(id, options_.simulated); w) {
    writer = std::move(*w);
    hooks.on_frame = [&writer](int k, int shots, const cv::Mat& photo, const veneer::io::ImageSet::RawFile& raw,
                               const veneer::io::ImageSet::RawFile& developed) {
      return writer->add_frame(k, photo, raw, shots, developed);
    };
  } else {
    result = w.error();
  }
  if (writer) {
    std::lock_guard cam(camera_mutex_);
    result = run_capture(*dev_.lamps, *dev_.camera, plan, hooks, &pending_restore_);
  }
  if (owner_by_capture_ && !pending_restore_.needed) drop_owner();
  refresh_lamps();
  veneer::Status stored;
  if (result) {
    veneer::io::ImageSet& set = result->set;
    if (options_.simulated && options_.sim.finish_set) options_.sim.finish_set(set);
    if (cancel_) {
      stored = make_error("cancelled");
    } else {
      stored = writer->commit(set);
    }
  } else {
    stored = result.error();
  }
  writer.reset();  // a set not stored leaves nothing

  RigEvent done;
  done.set_id = id;
  {
    std::lock_guard lock(mutex_);
    capturing_ = false;
    capture_id_.clear();
    if (stored) {
      next_role_ = req.role == veneer::io::Role::destination ? veneer::io::Role::source : veneer::io::Role::destination;
      mean_step_s_ = result->mean_step_s;
    }
  }
  if (stored) {
    done.kind = RigEvent::Kind::set_stored;
    done.role = req.role;
    done.warnings = result->set.warnings;
    log->info("set {} stored ({:.2f} s, {:.3f} s per shot)", id, result->seconds, result->mean_step_s);
    if (dev_.led) dev_.led->show(LedState::done);
  } else {
    done.kind = RigEvent::Kind::capture_failed;
    done.reason = stored.message();
    done.cancelled = stored.message() == "cancelled";
    if (done.cancelled) {
      log->info("capture {} cancelled", id);
    } else {
      log->error("capture {} failed: {}", id, done.reason);
    }
    if (dev_.led) dev_.led->show(done.cancelled ? LedState::idle : LedState::error);
  }
  emit(done);
}

void Rig::set_lamps(std::vector<bool> on, int brightness, std::function<void(veneer::Status)> done) {
  {
    std::lock_guard lock(mutex_);
    if (capturing_) {
      if (done) done(make_error("a capture is running; the lamps belong to it"));
      return;
    }
  }
  post([this, on = std::move(on), brightness, done = std::move(done)]() mutable {
    const int count = dev_.lamps ? dev_.lamps->count() : 0;
    if (static_cast<int>(on.size()) > count) {
      if (done) done(make_error("the rig has " + std::to_string(count) + " lamps, " + std::to_string(on.size()) + " given"));
      return;
    }
    on.resize(count, false);
    if (!owner_saved_) {
      // The owner's states go back at exit: saved before the first change.
      auto owner = dev_.lamps->read();
      veneer::Status saved = owner ? save_owner(*owner) : veneer::Status(owner.error());
      if (!saved) {
        note_lamps(owner);
        if (done) done(make_error("lamps: cannot save their owner's state before changing them: " + saved.message()));
        return;
      }
    }
    owner_by_capture_ = false;  // the client's lamps stay until exit
    veneer::Status s = dev_.lamps->set(on, brightness);
    refresh_lamps();
    if (!s) VLOG_WARN("Lamps", "set lamps failed: {}", s.message());
    // The answer first, then the event it causes (the contract's order; both
    // reach the server's thread in the order they are handed over).
    if (done) done(s);
    if (s) {
      pending_restore_.needed = false;  // the controller's own setting wins
      RigEvent e;
      e.kind = RigEvent::Kind::lamp_state;
      e.lamps_on = on;
      e.brightness = brightness;
      emit(e);
    }
  });
}

veneer::Status Rig::move_hand_lamp(const cv::Vec3d& position) {
  if (!options_.simulated || !options_.sim.move_hand_lamp) return make_error("only the simulated rig has a hand-held lamp");
  options_.sim.move_hand_lamp(position);
  return {};
}

namespace {
// An event about one stored set (deleted, restored).
RigEvent set_event(RigEvent::Kind kind, const std::string& id) {
  RigEvent e;
  e.kind = kind;
  e.set_id = id;
  return e;
}
}  // namespace

veneer::Status Rig::delete_set(const std::string& id) {
  {
    std::lock_guard lock(mutex_);
    if (capturing_ && capture_id_ == id) return make_error("set " + id + " is being captured");
  }
  if (auto s = store_.remove(id); !s) return s;
  emit(set_event(RigEvent::Kind::set_deleted, id));
  return {};
}

veneer::Status Rig::restore_set(const std::string& id) {
  if (auto s = store_.restore(id); !s) return s;
  emit(set_event(RigEvent::Kind::set_restored, id));
  return {};
}

void Rig::set_live_fps(double fps) {
  {
    std::lock_guard lock(live_mutex_);
    live_fps_ = fps;
    ++live_plan_;
  }
  live_cv_.notify_all();
}

// The camera's next frame is due one period of the fastest current watcher
// after the last one was due, and is planned again whenever the rate changes:
// a watcher that comes or goes is served at the new rate at once (a 10 fps
// watcher arriving just after a 0.1 fps one left does not wait out the slow
// one's 10 s period).
void Rig::live_loop() {
  using Clock = std::chrono::steady_clock;
  Clock::time_point last{};  // when the last frame was due (the epoch: none yet)
  for (;;) {
    Clock::time_point due;
    {
      std::unique_lock lock(live_mutex_);
      for (;;) {
        live_cv_.wait(lock, [&] { return stopping_ || live_fps_ > 0; });
        if (stopping_) return;
        const auto period =
            std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / live_fps_));
        due = last + period;
        const auto now = Clock::now();
        if (due < now - period) due = now;  // fell behind (or the rate rose): now, but do not burst
        const uint64_t plan = live_plan_;
        if (!live_cv_.wait_until(lock, due, [&] { return stopping_.load() || live_plan_ != plan; })) break;
        if (stopping_) return;
        // The rate changed while waiting: plan the frame again.
      }
    }
    last = due;
    std::unique_lock cam(camera_mutex_, std::try_to_lock);
    if (!cam.owns_lock() || !dev_.camera) continue;  // a capture holds the camera
    auto jpeg = dev_.camera->preview();
    cam.unlock();
    if (!jpeg) {
      VLOG_DEBUG("Camera", "live view frame failed: {}", jpeg.message());
      continue;
    }
    auto frame = std::make_shared<LiveFrameData>();
    frame->jpeg = std::move(*jpeg);
    frame->seq = ++live_seq_;
    frame->ts = unix_now();
    jpeg_size(frame->jpeg, frame->width, frame->height);
    if (on_live_frame) on_live_frame(frame);
  }
}

RigState Rig::state() const {
  RigState s;
  s.name = options_.name;
  s.simulated = options_.simulated;
  s.lamp_count = dev_.lamps ? dev_.lamps->count() : 0;
  std::lock_guard lock(mutex_);
  s.camera_connected = camera_connected_;
  s.camera_model = camera_model_;
  s.lamps = lamps_now_;
  for (const auto& l : lamps_now_) s.lamps_on.push_back(l.on && l.reachable);
  s.lamp_ids = options_.lamp_ids;
  if (lamps_read_at_ != std::chrono::steady_clock::time_point{})
    s.lamps_age_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - lamps_read_at_).count();
  s.lamps_problem = lamps_problem_;
  s.holds_lamps = owner_saved_;
  s.capturing = capturing_;
  s.next_role = next_role_;
  return s;
}

}  // namespace veneerd
