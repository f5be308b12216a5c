// Camera backend "simulated" (see simulated_camera.hpp).
#include "veneerd/sim/simulated_camera.hpp"

#include <algorithm>
#include <cmath>
#include <array>
#include <chrono>
#include <condition_variable>
#include <map>
#include <mutex>
#include <optional>
#include <thread>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "veneer/sim/motion.hpp"
#include "veneer/io/camera_files.hpp"
#include "veneer/io/dng.hpp"

#include "veneer/util/log.hpp"
#include "veneer/util/utc_time.hpp"
#include "veneerd/sim/fault_plan.hpp"

namespace veneerd {

using json = nlohmann::json;
using Clock = std::chrono::steady_clock;

namespace {

constexpr const char* kLog = "Camera";
constexpr double kRefShutter = 1.0 / 30, kRefAperture = 8.0, kRefIso = 100.0;

const std::vector<std::pair<std::string, double>> kShutters = {
    {"1/500", 1.0 / 500}, {"1/250", 1.0 / 250}, {"1/125", 1.0 / 125}, {"1/60", 1.0 / 60}, {"1/30", 1.0 / 30},
    {"1/15", 1.0 / 15},   {"1/8", 1.0 / 8},     {"1/4", 0.25},        {"1/2", 0.5},       {"1", 1.0}};
const std::vector<std::string> kApertures = {"2.8", "4", "5.6", "8", "11", "16", "22"};
const std::vector<std::string> kIsos = {"100", "200", "400", "800", "1600", "3200"};

// Hue CIE xy -> [r, g, b] relative to the rig white (which maps to 1, 1, 1),
// the strongest channel scaled to 1.
cv::Vec3f xy_to_rgb(double x, double y) {
  auto rgb = [](double x, double y) {
    y = std::max(y, 1e-4);
    double X = x / y, Y = 1.0, Z = (1.0 - x - y) / y;
    return cv::Vec3d{std::max(0.0, 3.2406 * X - 1.5372 * Y - 0.4986 * Z),
                     std::max(0.0, -0.9689 * X + 1.8758 * Y + 0.0415 * Z),
                     std::max(0.0, 0.0557 * X - 0.2040 * Y + 1.0570 * Z)};
  };
  cv::Vec3d white = rgb(0.3227, 0.329), c = rgb(x, y);
  cv::Vec3d rel{c[0] / white[0], c[1] / white[1], c[2] / white[2]};
  double m = std::max({rel[0], rel[1], rel[2]});
  if (!(m > 0)) return {1, 1, 1};
  return cv::Vec3f(static_cast<float>(rel[0] / m), static_cast<float>(rel[1] / m), static_cast<float>(rel[2] / m));
}

veneer::Status check_scene(const std::string& name) {
  auto names = veneer::sim::scene_names();
  if (std::find(names.begin(), names.end(), name) != names.end()) return {};
  std::string known;
  for (const auto& n : names) {
    if (!known.empty()) known += ", ";
    known += n;
  }
  return veneer::make_error("simulated camera: unknown scene '" + name + "' (known: " + known + ")");
}

veneer::Status check_size(const cv::Size& s, const char* what) {
  if (s.width < 8 || s.height < 8 || s.width > 8192 || s.height > 8192)
    return veneer::make_error(std::string("simulated camera: ") + what + " " + std::to_string(s.width) + "x" +
                              std::to_string(s.height) + " is outside 8x8 .. 8192x8192");
  return {};
}

}  // namespace

// --- options ---------------------------------------------------------------

veneer::Status SimulatedCameraOptions::check() const {
  if (auto st = bridge.check(); !st) return st;
  if (auto st = check_scene(scene); !st) return st;
  if (auto st = check_scene(preview_scene); !st) return st;
  if (auto st = check_size(size, "size"); !st) return st;
  if (auto st = check_size(preview_size, "preview_size"); !st) return st;
  if (!(noise_sigma >= 0 && noise_sigma <= 0.2)) return veneer::make_error("simulated camera: noise_sigma must be in [0, 0.2]");
  if (preview_quality < 1 || preview_quality > 100) return veneer::make_error("simulated camera: preview_quality must be 1..100");
  if (!preview_motion.empty()) {
    auto m = veneer::sim::parse_motion(preview_motion);
    if (!m) return veneer::make_error("simulated camera: preview_motion: " + m.message());
    if (m->view.area() > 0)
      return veneer::make_error("simulated camera: preview_motion '" + preview_motion +
                                "': the live view's framing is preview_size, not view=");
  }
  if (preview_motion_frames < 2 || preview_motion_frames > 100000)
    return veneer::make_error("simulated camera: preview_motion_frames must be 2..100000");
  return {};
}

veneer::Expected<SimulatedCameraOptions> SimulatedCameraOptions::from_json(const json& s) {
  if (!s.is_object()) return veneer::make_error("simulated camera: config section must be a JSON object");
  SimulatedCameraOptions o;
  auto bridge = hw::HueLampsOptions::from_json(s);
  if (!bridge) return veneer::make_error("simulated camera: " + bridge.message());
  o.bridge = *bridge;
  auto get_size = [&](const char* key, cv::Size& out) -> veneer::Status {
    if (!s.contains(key)) return {};
    const json& v = s[key];
    if (!v.is_array() || v.size() != 2 || !v[0].is_number_integer() || !v[1].is_number_integer())
      return veneer::make_error(std::string("simulated camera: '") + key + "' must be [width, height]");
    out = cv::Size(static_cast<int>(std::clamp<int64_t>(v[0].get<int64_t>(), 0, 1 << 20)),
                   static_cast<int>(std::clamp<int64_t>(v[1].get<int64_t>(), 0, 1 << 20)));
    return {};
  };
  if (auto st = get_size("size", o.size); !st) return st.error();
  if (auto st = get_size("preview_size", o.preview_size); !st) return st.error();
  for (const char* key : {"scene", "preview_scene"}) {
    if (!s.contains(key)) continue;
    if (!s[key].is_string()) return veneer::make_error(std::string("simulated camera: '") + key + "' must be a scene name");
    (std::string(key) == "scene" ? o.scene : o.preview_scene) = s[key].get<std::string>();
  }
  if (s.contains("noise_sigma")) {
    if (!s["noise_sigma"].is_number()) return veneer::make_error("simulated camera: 'noise_sigma' must be a number");
    o.noise_sigma = s["noise_sigma"].get<double>();
  }
  if (s.contains("preview_quality")) {
    if (!s["preview_quality"].is_number_integer())
      return veneer::make_error("simulated camera: 'preview_quality' must be an integer");
    o.preview_quality = static_cast<int>(std::clamp<int64_t>(s["preview_quality"].get<int64_t>(), -1, 1000));
  }
  if (s.contains("preview_motion")) {
    if (!s["preview_motion"].is_string())
      return veneer::make_error("simulated camera: 'preview_motion' must be a motion SPEC string, e.g. \"shift=30:0,rotate=5\"");
    o.preview_motion = s["preview_motion"].get<std::string>();
  }
  if (s.contains("preview_motion_frames")) {
    if (!s["preview_motion_frames"].is_number_integer())
      return veneer::make_error("simulated camera: 'preview_motion_frames' must be an integer");
    o.preview_motion_frames = static_cast<int>(std::clamp<int64_t>(s["preview_motion_frames"].get<int64_t>(), -1, 1 << 30));
  }
  if (s.contains("preview_render")) {
    const json& v = s["preview_render"];
    if (!v.is_string() || (v.get<std::string>() != "fast" && v.get<std::string>() != "full"))
      return veneer::make_error("simulated camera: 'preview_render' must be \"fast\" or \"full\"");
    o.preview_full_render = v.get<std::string>() == "full";
  }
  if (s.contains("jpeg")) {
    if (!s["jpeg"].is_boolean()) return veneer::make_error("simulated camera: 'jpeg' must be true or false");
    o.jpeg = s["jpeg"].get<bool>();
  }
  if (s.contains("raw")) {
    if (!s["raw"].is_boolean()) return veneer::make_error("simulated camera: 'raw' must be true or false");
    o.raw = s["raw"].get<bool>();
  }
  if (auto st = o.check(); !st) return st.error();
  return o;
}

json SimulatedCameraOptions::to_json() const {
  json j = bridge.to_json();
  j["scene"] = scene;
  j["preview_scene"] = preview_scene;
  j["size"] = {size.width, size.height};
  j["preview_size"] = {preview_size.width, preview_size.height};
  j["noise_sigma"] = noise_sigma;
  j["preview_quality"] = preview_quality;
  j["preview_render"] = preview_full_render ? "full" : "fast";
  if (!preview_motion.empty()) {
    j["preview_motion"] = preview_motion;
    j["preview_motion_frames"] = preview_motion_frames;
  }
  j["raw"] = raw;
  j["jpeg"] = jpeg;
  return j;
}

// --- the camera ------------------------------------------------------------

// What the fast live view shades from: per pixel of the object, its position
// in the rig frame, normal and albedo (from the simulator's truth).
struct PreviewBuffer {
  std::string scene;
  cv::Size size;
  std::vector<int> index;            // pixel index of each object pixel
  std::vector<cv::Vec3f> position;   // rig frame [m]
  std::vector<cv::Vec3f> normal;
  std::vector<cv::Vec3f> albedo;     // BGR
};

std::shared_ptr<const PreviewBuffer> make_preview_buffer(const veneer::sim::Scene& scene, const std::string& name,
                                                         const veneer::sim::RenderOptions& r) {
  veneer::io::Truth t = veneer::sim::render_truth(scene, r);
  auto b = std::make_shared<PreviewBuffer>();
  b->scene = name;
  b->size = r.size;
  if (!t.present()) return b;
  const double f = r.focal_px, cx = (r.size.width - 1) * 0.5, cy = (r.size.height - 1) * 0.5;
  for (int y = 0; y < r.size.height; ++y) {
    for (int x = 0; x < r.size.width; ++x) {
      if (!t.mask.at<uint8_t>(y, x)) continue;
      double d = t.depth.at<float>(y, x);  // along -z from the camera at z = 1
      b->index.push_back(y * r.size.width + x);
      b->position.emplace_back(static_cast<float>((x - cx) / f * d), static_cast<float>(-(y - cy) / f * d),
                               static_cast<float>(1.0 - d));
      b->normal.push_back(t.normals.at<cv::Vec3f>(y, x));
      b->albedo.push_back(t.albedo.at<cv::Vec3f>(y, x));
    }
  }
  // The table behind the object: a plane facing the camera, placed at the
  // object's deepest visible point. Its reflectance comes from one full render
  // under a lamp at the camera (which hides the object's shadow behind it).
  if (b->index.empty()) return b;
  float table_z = b->position.front()[2];
  for (const auto& p : b->position) table_z = std::min(table_z, p[2]);
  const cv::Vec3f head(0, 0, 1);
  veneer::sim::Lamp at_camera;
  at_camera.position_m = {0, 0, 1};
  veneer::sim::RenderOptions plain = r;
  plain.noise_sigma = 0;
  plain.exposure = 1;
  cv::Mat plate = veneer::sim::render(scene, {at_camera}, plain);
  if (plate.empty()) return b;
  const cv::Vec3d rig0 = veneer::sim::thesis_rig().front().position_m;
  const double d = 1.0 - table_z;
  for (int y = 0; y < r.size.height; ++y) {
    for (int x = 0; x < r.size.width; ++x) {
      if (t.mask.at<uint8_t>(y, x)) continue;
      cv::Vec3f p(static_cast<float>((x - cx) / f * d), static_cast<float>(-(y - cy) / f * d), table_z);
      cv::Vec3f L = head - p;
      float r2 = L.dot(L);
      float e0 = static_cast<float>(rig0.dot(rig0)) * L[2] / std::sqrt(r2) / r2;  // irradiance from the camera lamp
      cv::Vec3f c = plate.at<cv::Vec3f>(y, x);
      if (!(e0 > 0) || c == cv::Vec3f(0, 0, 0)) continue;
      b->index.push_back(y * r.size.width + x);
      b->position.push_back(p);
      b->normal.emplace_back(0.f, 0.f, 1.f);
      b->albedo.push_back(c / e0);
    }
  }
  return b;
}

// Linear [0, 1] -> display 8-bit (gamma 1/2.2), 4096 steps.
const std::array<uint8_t, 4096>& gamma_lut() {
  static const std::array<uint8_t, 4096> lut = [] {
    std::array<uint8_t, 4096> l{};
    for (int i = 0; i < 4096; ++i) l[i] = static_cast<uint8_t>(std::lround(255.0 * std::pow(i / 4095.0, 1.0 / 2.2)));
    return l;
  }();
  return lut;
}

struct SimulatedCamera::Impl {
  SimulatedCameraOptions options;
  std::unique_ptr<hw::HueLamps> bridge;  // reads lamp states only
  mutable std::mutex mutex;          // everything below
  std::mutex bridge_mutex;           // HueLamps is used by one thread at a time
  std::string scene, preview_scene;
  Exposure exposure{kRefShutter, kRefAperture, static_cast<int>(kRefIso)};
  cv::Vec3d hand_lamp{0.25, 0.3, 0.6};
  float hand_brightness = 1.0f;
  bool connected = true;
  uint64_t shots = 0;
  uint64_t fail_at = 0;  // shot number that fails; 0 = none
  std::shared_ptr<FaultPlan> faults;  // camera.gone, clock.step drawn per shot; null = none
  // A camera.gone fault plugs the camera in again from this thread.
  std::thread replug;
  std::condition_variable replug_cv;
  Clock::time_point replug_at{};
  bool replug_pending = false, closing = false;
  uint64_t previews = 0;
  std::vector<veneer::sim::Lamp> last_lamps;
  // Scenes keep their G-buffer for one size: stills and live view use separate
  // objects; each map holds the scene last used (scene_for).
  std::map<std::string, std::shared_ptr<const veneer::sim::Scene>> still_scenes, preview_scenes;
  std::shared_ptr<const PreviewBuffer> preview_buffer;  // fast live view of preview_scene

  double gain_locked() const {
    return (exposure.shutter_s / kRefShutter) * (kRefAperture / exposure.aperture) * (kRefAperture / exposure.aperture) *
           (exposure.iso / kRefIso);
  }

  veneer::sim::RenderOptions still_options_locked() const {
    veneer::sim::RenderOptions r;
    r.size = options.size;
    r.focal_px = 2.0 * options.size.width;
    r.exposure = gain_locked();
    r.noise_sigma = options.noise_sigma;
    r.seed = shots + 1;
    r.camera_optics();  // a band-limited image, as a real sensor sees (its DNG's demosaicing relies on it)
    return r;
  }

  // The scene `name` from `cache`, made when missing. A cache keeps one scene:
  // a scene's G-buffer at 5600x3750 is 1.5 GiB, and the rig's pair
  // (destination, source) is two scenes, too many for a 4 GiB board; the one
  // left is let go before the next is made, so they are never both held.
  veneer::Expected<std::shared_ptr<const veneer::sim::Scene>> scene_for(
      std::map<std::string, std::shared_ptr<const veneer::sim::Scene>>& cache, const std::string& name,
      const veneer::sim::RenderOptions& r) {
    {
      std::lock_guard lock(mutex);
      if (auto it = cache.find(name); it != cache.end()) return it->second;
      cache.clear();
    }
    auto made = veneer::sim::make_scene(name, r);
    if (!made) return made.error();
    std::lock_guard lock(mutex);
    return cache.emplace(name, *made).first->second;
  }
};

SimulatedCamera::SimulatedCamera(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
SimulatedCamera::~SimulatedCamera() {
  {
    std::lock_guard lock(impl_->mutex);
    impl_->closing = true;
  }
  impl_->replug_cv.notify_all();
  if (impl_->replug.joinable()) impl_->replug.join();
}

void SimulatedCamera::set_fault_plan(std::shared_ptr<FaultPlan> plan) {
  std::lock_guard lock(impl_->mutex);
  impl_->faults = std::move(plan);
}

void SimulatedCamera::unplug_for(std::chrono::milliseconds gone) {
  {
    std::lock_guard lock(impl_->mutex);
    impl_->replug_at = Clock::now() + gone;
    impl_->replug_pending = true;
    if (!impl_->replug.joinable()) {
      impl_->replug = std::thread([this] {
        std::unique_lock lock(impl_->mutex);
        for (;;) {
          if (impl_->closing) return;
          if (!impl_->replug_pending) {
            impl_->replug_cv.wait(lock);
            continue;
          }
          if (Clock::now() < impl_->replug_at) {
            impl_->replug_cv.wait_until(lock, impl_->replug_at);
            continue;
          }
          impl_->replug_pending = false;
          lock.unlock();
          reconnect();
          lock.lock();
        }
      });
    }
  }
  impl_->replug_cv.notify_all();
  disconnect();
}

veneer::Expected<std::unique_ptr<SimulatedCamera>> SimulatedCamera::create(const SimulatedCameraOptions& options) {
  if (auto st = options.check(); !st) return st.error();
  auto impl = std::make_unique<Impl>();
  impl->options = options;
  hw::HueLampsOptions reader = options.bridge;
  reader.settle_ms = 0;
  auto lamps = hw::HueLamps::create(reader);
  if (!lamps) return lamps.error();
  impl->bridge = std::move(*lamps);
  impl->scene = options.scene;
  impl->preview_scene = options.preview_scene;
  return std::unique_ptr<SimulatedCamera>(new SimulatedCamera(std::move(impl)));
}

veneer::Status SimulatedCamera::open() {
  std::lock_guard lock(impl_->mutex);
  if (!impl_->connected) return veneer::make_error("simulated camera: not connected (unplugged)");
  return {};
}

bool SimulatedCamera::connected() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->connected;
}

veneer::Expected<CameraDescription> SimulatedCamera::describe() {
  std::lock_guard lock(impl_->mutex);
  if (!impl_->connected) return veneer::make_error("simulated camera: not connected (unplugged)");
  CameraDescription d;
  d.model = "Veneer simulated camera (scene " + impl_->scene + ")";
  for (const auto& [n, v] : kShutters) d.shutter_values.push_back(n);
  d.aperture_values = kApertures;
  d.iso_values = kIsos;
  return d;
}

veneer::Status SimulatedCamera::set_exposure(const Exposure& e) {
  if (e.shutter_s < 0 || e.shutter_s > 30 || !std::isfinite(e.shutter_s))
    return veneer::make_error("simulated camera: shutter " + std::to_string(e.shutter_s) + " s is outside 0..30 s");
  if (e.aperture != 0 && (e.aperture < 1 || e.aperture > 32 || !std::isfinite(e.aperture)))
    return veneer::make_error("simulated camera: aperture f/" + std::to_string(e.aperture) + " is outside f/1..f/32");
  if (e.iso != 0 && (e.iso < 50 || e.iso > 25600))
    return veneer::make_error("simulated camera: ISO " + std::to_string(e.iso) + " is outside 50..25600");
  std::lock_guard lock(impl_->mutex);
  if (!impl_->connected) return veneer::make_error("simulated camera: not connected (unplugged)");
  if (e.shutter_s > 0) impl_->exposure.shutter_s = e.shutter_s;
  if (e.aperture > 0) impl_->exposure.aperture = e.aperture;
  if (e.iso > 0) impl_->exposure.iso = e.iso;
  return {};
}

veneer::Expected<Still> SimulatedCamera::capture() {
  veneer::sim::RenderOptions r;
  std::string scene_name;
  uint64_t shot = 0;
  std::chrono::milliseconds unplugging{0};
  uint64_t next_shot = 0;
  {
    std::lock_guard lock(impl_->mutex);
    if (!impl_->connected) return veneer::make_error("simulated camera: not connected (unplugged)");
    if (impl_->faults && impl_->faults->draw(Fault::clock_step)) {
      // NTP stepping the clock: the wall clock jumps, the steady clock goes on.
      const long long step = impl_->faults->sizes().clock_step_s;
      veneer::step_wall_clock(impl_->faults->pick(Fault::clock_step, 2) ? step : -step);
      VLOG_WARN(kLog, "the wall clock stepped (injected fault): now {}", veneer::utc_now());
    }
    if (impl_->faults && impl_->faults->draw(Fault::camera_gone)) {
      const auto gone = std::chrono::milliseconds(impl_->faults->sizes().camera_gone_ms);
      // unplug_for takes the mutex and calls the connection callback: not under it.
      unplugging = gone;
      next_shot = impl_->shots + 1;
    }
  }
  if (unplugging.count() > 0) {
    VLOG_WARN(kLog, "simulated camera: unplugged before shot {} for {} ms (injected fault: USB drop)", next_shot,
              unplugging.count());
    unplug_for(unplugging);
  }
  {
    std::lock_guard lock(impl_->mutex);
    if (!impl_->connected) return veneer::make_error("simulated camera: not connected (unplugged)");
    r = impl_->still_options_locked();
    shot = ++impl_->shots;
    scene_name = impl_->scene;
    if (impl_->fail_at == shot) {
      impl_->fail_at = 0;
      VLOG_WARN(kLog, "simulated camera: shot {} fails (injected fault)", shot);
      return veneer::make_error("simulated camera: shot " + std::to_string(shot) + " failed (injected fault: capture error)");
    }
  }
  // Which lamps are on, as the bridge reports them (the same HTTP path as a real rig).
  veneer::Expected<std::vector<LampState>> states = veneer::make_error("");
  {
    std::lock_guard lock(impl_->bridge_mutex);
    states = impl_->bridge->read();
  }
  if (!states) return veneer::make_error("simulated camera: cannot read the lamps from the bridge: " + states.message());
  std::vector<veneer::sim::Lamp> rig = veneer::sim::thesis_rig();
  std::vector<veneer::sim::Lamp> lit, all;
  for (std::size_t i = 0; i < states->size(); ++i) {
    veneer::sim::Lamp lamp;
    if (i < rig.size()) lamp.position_m = rig[i].position_m;
    const LampState& s = (*states)[i];
    lamp.brightness = (s.on && s.reachable && i < rig.size()) ? static_cast<float>(s.brightness) / 254.0f : 0.0f;
    lamp.color = xy_to_rgb(s.x, s.y);
    all.push_back(lamp);
    if (lamp.brightness > 0) lit.push_back(lamp);
  }
  auto scene = impl_->scene_for(impl_->still_scenes, scene_name, r);
  if (!scene) return veneer::make_error("simulated camera: " + scene.message());
  Still still;
  still.linear = veneer::sim::render(**scene, lit, r);
  if (still.linear.empty()) return veneer::make_error("simulated camera: the simulator rendered nothing for shot " + std::to_string(shot));
  bool raw = false, jpeg = false;
  {
    std::lock_guard lock(impl_->mutex);
    impl_->last_lamps = all;
    raw = impl_->options.raw;
    jpeg = impl_->options.jpeg;
  }
  if (raw && (still.linear.cols % 2 || still.linear.rows % 2)) {
    VLOG_WARN(kLog, "simulated shot {}: {}x{} is not whole Bayer cells; no RAW file", shot, still.linear.cols,
              still.linear.rows);
    raw = false;
  }
  if (raw || jpeg) {
    // What a RAW+JPEG body delivers: its developed JPEG and the DNG (a
    // lossless mosaic with a reduced preview), encoded side by side.
    veneer::io::CameraFileOptions files;
    files.raw = raw;
    files.dng.camera_model = "Veneer simulated camera";
    auto encoded = veneer::io::encode_camera_files(still.linear, files);
    if (!encoded) return veneer::make_error("simulated camera: shot " + std::to_string(shot) + ": " + encoded.message());
    if (raw) {
      char name[32];
      std::snprintf(name, sizeof name, "SIM_%04llu.DNG", static_cast<unsigned long long>(shot % 10000));
      still.original_name = name;
      still.original.assign(encoded->raw.bytes.begin(), encoded->raw.bytes.end());
    }
    if (jpeg) still.developed_jpeg.assign(encoded->developed.bytes.begin(), encoded->developed.bytes.end());
  }
  VLOG_DEBUG(kLog, "simulated shot {}: scene {}, {} lamp(s) on, gain {:.3f}", shot, scene_name, lit.size(), r.exposure);
  return still;
}

veneer::Expected<std::vector<unsigned char>> SimulatedCamera::preview() {
  veneer::sim::RenderOptions r;
  std::string scene_name;
  veneer::sim::Lamp hand;
  int quality = 80;
  std::optional<veneer::sim::MotionFrame> motion;
  {
    std::lock_guard lock(impl_->mutex);
    if (!impl_->connected) return veneer::make_error("simulated camera: not connected (unplugged)");
    r.size = impl_->options.preview_size;
    r.focal_px = 2.0 * r.size.width;
    r.exposure = impl_->gain_locked();
    r.noise_sigma = impl_->options.noise_sigma;
    r.seed = ++impl_->previews;
    scene_name = impl_->preview_scene;
    hand.position_m = impl_->hand_lamp;
    hand.brightness = impl_->hand_brightness;
    quality = impl_->options.preview_quality;
    if (!impl_->options.preview_motion.empty()) {
      // back and forth: 0 .. N-1 .. 1, 0 ..
      const uint64_t n = static_cast<uint64_t>(impl_->options.preview_motion_frames);
      uint64_t i = (impl_->previews - 1) % (2 * (n - 1));
      if (i >= n) i = 2 * (n - 1) - i;
      auto spec = veneer::sim::parse_motion(impl_->options.preview_motion);  // checked with the options
      if (spec) {
        motion = veneer::sim::motion_at(*spec, static_cast<int>(i), static_cast<int>(n),
                                        cv::Point2d((r.size.width - 1) / 2.0, (r.size.height - 1) / 2.0));
        if (spec->lamp_sweep) hand.position_m = motion->lamp_m;
      }
    }
  }
  auto scene = impl_->scene_for(impl_->preview_scenes, scene_name, r);
  if (!scene) return veneer::make_error("simulated camera: " + scene.message());
  cv::Mat bytes8;
  if (impl_->options.preview_full_render) {
    cv::Mat linear = veneer::sim::render(**scene, {hand}, r);
    if (linear.empty()) return veneer::make_error("simulated camera: the simulator rendered no live-view frame");
    bytes8.create(linear.size(), CV_8UC3);
    const auto& lut = gamma_lut();
    for (int y = 0; y < linear.rows; ++y) {
      const auto* in = linear.ptr<cv::Vec3f>(y);
      auto* out = bytes8.ptr<cv::Vec3b>(y);
      for (int x = 0; x < linear.cols; ++x)
        for (int c = 0; c < 3; ++c) out[x][c] = lut[static_cast<int>(std::clamp(in[x][c], 0.0f, 1.0f) * 4095.0f)];
    }
  } else {
    std::shared_ptr<const PreviewBuffer> buffer;
    {
      std::lock_guard lock(impl_->mutex);
      buffer = impl_->preview_buffer;
    }
    if (!buffer || buffer->scene != scene_name || buffer->size != r.size) {
      buffer = make_preview_buffer(**scene, scene_name, r);
      std::lock_guard lock(impl_->mutex);
      impl_->preview_buffer = buffer;
    }
    // The simulator's convention: a rig lamp at full white delivers irradiance 1
    // at the rig origin, i.e. radiant intensity |lamp|^2.
    const cv::Vec3d rig0 = veneer::sim::thesis_rig().front().position_m;
    const double radiant = rig0.dot(rig0) * hand.brightness * r.exposure;
    bytes8 = cv::Mat(r.size, CV_8UC3, cv::Scalar::all(0));
    uint8_t* out = bytes8.ptr<uint8_t>(0);
    const uint8_t* lut = gamma_lut().data();
    const float lx = static_cast<float>(hand.position_m[0]), ly = static_cast<float>(hand.position_m[1]),
                lz = static_cast<float>(hand.position_m[2]), k = static_cast<float>(radiant);
    const int n = static_cast<int>(buffer->index.size());
    const int* index = buffer->index.data();
    const float* pos = n ? &buffer->position[0][0] : nullptr;
    const float* nrm = n ? &buffer->normal[0][0] : nullptr;
    const float* alb = n ? &buffer->albedo[0][0] : nullptr;
    // Independent pixels, disjoint writes: shade in stripes on every core.
    if (n > 0) cv::parallel_for_(cv::Range(0, n), [&](const cv::Range& range) {
      for (int i = range.start; i < range.end; ++i) {
        const float* p = pos + 3 * i;
        const float* nn = nrm + 3 * i;
        float Lx = lx - p[0], Ly = ly - p[1], Lz = lz - p[2];
        float r2 = Lx * Lx + Ly * Ly + Lz * Lz;
        float ndl = nn[0] * Lx + nn[1] * Ly + nn[2] * Lz;
        if (!(ndl > 0)) continue;
        float e = k * ndl / (r2 * std::sqrt(r2)) * 4095.0f;
        const float* a = alb + 3 * i;
        uint8_t* px = out + 3 * static_cast<std::size_t>(index[i]);
        for (int c = 0; c < 3; ++c) px[c] = lut[static_cast<int>(std::min(a[c] * e, 4095.0f))];
      }
    }, 4);
  }
  if (motion) cv::warpAffine(bytes8, bytes8, cv::Mat(motion->still_to_frame), bytes8.size(), cv::INTER_LINEAR, cv::BORDER_REPLICATE);
  std::vector<unsigned char> jpeg;
  if (!cv::imencode(".jpg", bytes8, jpeg, {cv::IMWRITE_JPEG_QUALITY, quality}))
    return veneer::make_error("simulated camera: JPEG encoding of the live-view frame failed");
  return jpeg;
}

veneer::Status SimulatedCamera::set_scene(const std::string& name) {
  if (auto st = check_scene(name); !st) return st;
  std::lock_guard lock(impl_->mutex);
  impl_->scene = name;
  return {};
}

veneer::Status SimulatedCamera::set_preview_scene(const std::string& name) {
  if (auto st = check_scene(name); !st) return st;
  std::lock_guard lock(impl_->mutex);
  impl_->preview_scene = name;
  return {};
}

std::string SimulatedCamera::scene() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->scene;
}

std::string SimulatedCamera::preview_scene() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->preview_scene;
}

void SimulatedCamera::set_hand_lamp(const cv::Vec3d& position_m, float brightness) {
  std::lock_guard lock(impl_->mutex);
  impl_->hand_lamp = position_m;
  impl_->hand_brightness = std::clamp(brightness, 0.0f, 1.0f);
}

cv::Vec3d SimulatedCamera::hand_lamp() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->hand_lamp;
}

void SimulatedCamera::fail_on_shot(int k) {
  std::lock_guard lock(impl_->mutex);
  impl_->fail_at = k > 0 ? impl_->shots + static_cast<uint64_t>(k) : 0;
}

void SimulatedCamera::disconnect() {
  {
    std::lock_guard lock(impl_->mutex);
    if (!impl_->connected) return;
    impl_->connected = false;
  }
  VLOG_WARN(kLog, "simulated camera unplugged");
  if (on_connection_change) on_connection_change(false);
}

void SimulatedCamera::reconnect() {
  {
    std::lock_guard lock(impl_->mutex);
    if (impl_->connected) return;
    impl_->connected = true;
  }
  VLOG_INFO(kLog, "simulated camera plugged in");
  if (on_connection_change) on_connection_change(true);
}

uint64_t SimulatedCamera::shots() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->shots;
}

double SimulatedCamera::gain() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->gain_locked();
}

veneer::sim::RenderOptions SimulatedCamera::still_options() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->still_options_locked();
}

std::vector<veneer::sim::Lamp> SimulatedCamera::last_lamps() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->last_lamps;
}

veneer::Expected<veneer::io::Truth> SimulatedCamera::truth() {
  veneer::sim::RenderOptions r;
  std::string name;
  {
    std::lock_guard lock(impl_->mutex);
    r = impl_->still_options_locked();
    name = impl_->scene;
  }
  auto scene = impl_->scene_for(impl_->still_scenes, name, r);
  if (!scene) return veneer::make_error("simulated camera: " + scene.message());
  veneer::io::Truth t = veneer::sim::render_truth(**scene, r);
  if (!t.present()) return veneer::make_error("simulated camera: the simulator produced no truth for scene " + name);
  return t;
}

veneer::io::CameraInfo SimulatedCamera::camera_info() const {
  std::lock_guard lock(impl_->mutex);
  veneer::io::CameraInfo c;
  c.model = "Veneer simulated camera";
  c.exposure_s = impl_->exposure.shutter_s;
  c.aperture = impl_->exposure.aperture;
  c.iso = impl_->exposure.iso;
  c.focal_px = 2.0 * impl_->options.size.width;
  c.cx = (impl_->options.size.width - 1) * 0.5;
  c.cy = (impl_->options.size.height - 1) * 0.5;
  return c;
}

SimulatedCamera* as_simulated(Camera* camera) { return dynamic_cast<SimulatedCamera*>(camera); }

}  // namespace veneerd
