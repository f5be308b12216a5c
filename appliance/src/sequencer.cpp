#include "veneerd/sequencer.hpp"

#include <cctype>
#include <chrono>
#include <cmath>
#include <ctime>
#include <optional>
#include <sstream>

#include "veneer/io/raw.hpp"
#include "veneer/util/log.hpp"
#include "veneer/util/utc_time.hpp"

namespace veneerd {

using veneer::make_error;
using Clock = std::chrono::steady_clock;

double mean_level(const cv::Mat& linear) {
  if (linear.empty()) return 0;
  cv::Scalar m = cv::mean(linear);
  double sum = 0;
  for (int c = 0; c < linear.channels() && c < 4; ++c) sum += m[c];
  return sum / std::max(1, linear.channels());
}

namespace {

double seconds_since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

cv::Mat to_float_bgr(const cv::Mat& in) {
  if (in.type() == CV_32FC3) return in;
  cv::Mat out;
  double scale = in.depth() == CV_16U ? 1.0 / 65535 : in.depth() == CV_8U ? 1.0 / 255 : 1.0;
  in.convertTo(out, CV_MAKETYPE(CV_32F, in.channels()), scale);
  if (out.channels() == 1) cv::merge(std::vector<cv::Mat>{out, out, out}, out);
  return out;
}

}  // namespace

veneer::Expected<CaptureResult> run_capture(Lamps& lamps, Camera& camera, const CapturePlan& plan,
                                            const CaptureHooks& hooks, PendingRestore* pending) {
  auto log = veneer::log::get("Sequencer");
  const auto start = Clock::now();
  const int count = lamps.count();
  if (count <= 0) return make_error("the lamps back-end reports no lamps");
  if (plan.lamp_positions.size() != static_cast<size_t>(count)) {
    return make_error("the rig has " + std::to_string(count) + " lamps but " +
                      std::to_string(plan.lamp_positions.size()) + " lamp positions are configured");
  }
  auto cancelled = [&] { return hooks.cancel != nullptr && hooks.cancel->load(); };
  const int shots = count + 1;

  if (auto s = camera.open(); !s) return make_error("camera: " + s.message());
  // The owner's lamps as the bridge reports them now: what goes back afterwards.
  auto saved = lamps.read();
  if (!saved) return make_error("lamps: cannot read their state before the capture: " + saved.message());
  // Lamps already unreachable now would only fail later, after the ambient frame.
  for (int i = 0; i < count && i < static_cast<int>(saved->size()); ++i) {
    if (!(*saved)[i].reachable) return make_error(lamps.label(i) + " is unreachable; capture not started");
  }
  if (hooks.save_owner_state) {
    if (auto s = hooks.save_owner_state(*saved); !s)
      return make_error("lamps: cannot save their owner's state before touching them: " + s.message());
  }

  CaptureResult result;
  veneer::io::ImageSet& set = result.set;
  double ambient_level = 0, lit_level = 0;  // mean levels, for the ambient check
  int lit_frames = 0;
  set.id = plan.set_id;
  set.role = plan.role;
  set.object = plan.object;
  set.scene = plan.scene;
  set.created = veneer::utc_now();

  // Step k's lamps: the ambient frame (k = 0) all off, then ring lamp k - 1
  // alone, rig white at full brightness. A lamp that is off keeps its owner's
  // colour and level, so it comes back as it was when the owner next switches it on.
  // A lamp the owner had on gets its colour back with the restore's "on", so
  // it may go off in whatever colour it shows (`reading`): no extra command.
  auto want_for = [&](int k, const std::optional<std::vector<LampState>>& reading) {
    std::vector<LampState> want(count);
    for (int i = 0; i < count; ++i) {
      const bool shown = (*saved)[i].on && reading && static_cast<int>(reading->size()) == count;
      want[i] = shown ? (*reading)[i] : (*saved)[i];
      want[i].on = false;
      want[i].reachable = true;
    }
    if (k > 0) want[k - 1] = rig_white(254);
    return want;
  };

  auto sequence = [&]() -> veneer::Status {
    if (auto desc = camera.describe(); desc) set.camera.model = desc->model;
    if (auto s = camera.set_exposure(plan.exposure); !s) return make_error("camera: cannot set exposure: " + s.message());
    set.camera.exposure_s = plan.exposure.shutter_s;
    set.camera.aperture = plan.exposure.aperture;
    set.camera.iso = plan.exposure.iso;

    double step_total = 0;
    int steps_done = 0;
    auto eta = [&](int done) {
      double per = steps_done > 0 ? step_total / steps_done : plan.expected_shot_s;
      return per * (shots - done);
    };
    std::optional<std::vector<LampState>> reading = *saved;  // the bridge as last read
    for (int k = 0; k < shots; ++k) {
      if (cancelled()) return make_error("cancelled");
      const auto step_start = Clock::now();
      const std::vector<LampState> want = want_for(k, reading);
      const std::string step_name = k == 0 ? std::string("ambient frame (all lamps off)")
                                           : "shot " + std::to_string(k + 1) + " (" + lamps.label(k - 1) + " alone)";
      cv::Mat photo;
      veneer::io::ImageSet::RawFile raw, developed;
      for (int take = 1;; ++take) {
        // Proven before the exposure: commanded from the bridge's own reading, read back.
        auto proven = lamps.ensure(want, reading, plan.lamp_attempts);
        reading.reset();
        if (!proven) return make_error("lamps, " + step_name + ": " + proven.message());
        if (cancelled()) return make_error("cancelled");
        auto still = camera.capture();
        if (!still) {
          return make_error("camera, shot " + std::to_string(k + 1) + " of " + std::to_string(shots) + ": " +
                            still.message());
        }
        // ... and after it: a lamp switched by another client meanwhile spoils the frame.
        auto after = lamps.read();
        if (!after) return make_error("lamps, " + step_name + ": cannot read them after the exposure: " + after.message());
        std::vector<int> spoiled = lamps.differing(*after, want);
        if (spoiled.empty()) {
          photo = to_float_bgr(still->linear);
          // The camera's RAW file, when it delivered one, is kept beside the
          // photo (set.json's images[].raw / ambient_raw): the viewer reads
          // the set from it, linear, by default.
          raw = {};
          if (!still->original.empty() && veneer::io::is_raw_file_name(still->original_name)) {
            const std::string& n = still->original_name;
            raw.extension = n.substr(n.rfind('.') + 1);
            for (char& ch : raw.extension) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
            raw.bytes.assign(still->original.begin(), still->original.end());
          }
          developed = {};
          if (!still->developed_jpeg.empty() && still->linear.size() == photo.size())
            developed = {"jpg", std::string(still->developed_jpeg.begin(), still->developed_jpeg.end())};
          reading = std::move(*after);
          break;
        }
        std::string who;
        for (int i : spoiled) who += (who.empty() ? "" : ", ") + lamps.label(i) + " " + describe((*after)[i]);
        if (take >= plan.shot_attempts) {
          return make_error("lamps, " + step_name + ": another client changed the lamps during the exposure " +
                            std::to_string(take) + " times (" + who + "); the set is not stored");
        }
        ++result.retakes;
        log->warn("{}: {}: the lamps changed during the exposure ({}): taking it again", plan.set_id, step_name, who);
        reading = std::move(*after);
      }
      if (photo.empty()) return make_error("camera, shot " + std::to_string(k + 1) + ": empty image");
      if (set.size.area() == 0) set.size = photo.size();
      if (photo.size() != set.size) {
        return make_error("camera, shot " + std::to_string(k + 1) + ": size changed mid-set");
      }
      if (k == 0) {
        ambient_level = mean_level(photo);
      } else {
        lit_level += mean_level(photo);
        ++lit_frames;
      }
      if (hooks.on_frame) {
        if (auto s = hooks.on_frame(k, shots, photo, raw, developed); !s) return s;
      } else if (k == 0) {
        set.ambient = photo;
        set.ambient_raw = std::move(raw);
        set.ambient_developed = std::move(developed);
      } else {
        set.images.push_back(photo);
        set.raw.push_back(std::move(raw));
        set.developed.push_back(std::move(developed));
      }
      step_total += seconds_since(step_start);
      ++steps_done;
      log->debug("{}: shot {}/{} in {:.3f} s", plan.set_id, k + 1, shots, seconds_since(step_start));
      if (hooks.on_shot) hooks.on_shot(k + 1, shots, eta(k + 1));
    }
    result.mean_step_s = step_total / std::max(1, steps_done);
    return {};
  };

  veneer::Status outcome = sequence();

  // Whatever happened, give the owner's lamps back exactly (proven by reading back).
  if (auto s = lamps.restore(*saved); !s) {
    log->error("restoring the lamps after {} failed: {}; will retry", plan.set_id, s.message());
    if (pending) {
      pending->states = *saved;
      pending->needed = true;
    }
    if (outcome) outcome = make_error("lamps: restoring their state after the capture failed: " + s.message());
  } else {
    result.restored = true;
  }
  if (!outcome) return outcome.error();

  // Lights of the set: ring geometry, direction toward the object centre.
  for (int i = 0; i < count; ++i) {
    veneer::io::Light light;
    light.index = i;
    light.lamp_id = static_cast<size_t>(i) < plan.lamp_ids.size() ? plan.lamp_ids[i] : "lamp-" + std::to_string(i + 1);
    light.position_m = plan.lamp_positions[i];
    double n = cv::norm(plan.lamp_positions[i]);
    light.direction = n > 0 ? plan.lamp_positions[i] / n : cv::Vec3d(0, 0, 1);
    light.intensity = cv::Vec3f(1, 1, 1);
    set.lights.push_back(light);
  }

  const double ambient = ambient_level;
  const double lit = lit_level / std::max(1, lit_frames);
  if (ambient > plan.ambient_warning || (lit > 0 && ambient > 0.25 * lit)) {
    std::ostringstream w;
    w.precision(3);
    w << "bright ambient frame: mean level " << ambient << " of full scale (" << (lit > 0 ? 100.0 * ambient / lit : 0)
      << "% of a lit shot); room light reaches the object and biases photometric stereo";
    set.warnings.push_back(w.str());
    log->warn("{}: {}", plan.set_id, w.str());
  }
  result.seconds = seconds_since(start);
  return result;
}

}  // namespace veneerd
