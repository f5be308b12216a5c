#pragma once
// The capture sequence: read the owner's lamp states (and have them saved),
// all lamps off -> ambient frame, then for each ring position only that lamp
// on (full white, same exposure) -> one shot, and finally restore the owner's
// states — also when a step fails or the capture is cancelled.
//
// The lamps are shared with their owner's apps, so each step's lamp state is
// proven, not assumed: commanded from a reading of the bridge and read back
// before the exposure (Lamps::ensure), and read again after it; a frame
// during which another client changed a lamp is taken again, and a set whose
// lamps will not hold still fails. A lamp or camera fault fails the whole
// capture: a set is never short and never silently wrong.
#include <atomic>
#include <functional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/io/imageset.hpp"
#include "veneer/util/expected.hpp"
#include "veneerd/devices/camera.hpp"
#include "veneerd/devices/lamps.hpp"

namespace veneerd {

struct CapturePlan {
  std::string set_id;
  veneer::io::Role role = veneer::io::Role::unknown;
  std::string object;
  std::string scene;                      // simulator scene (simulated rig), else empty
  Exposure exposure;
  std::vector<std::string> lamp_ids;      // per ring position (manifest)
  std::vector<cv::Vec3d> lamp_positions;  // per ring position, rig frame [m]
  double ambient_warning = 0.05;          // ambient mean (of full scale) that warns
  double expected_shot_s = 1.0;           // first guess of one step's duration, for the ETA
  int lamp_attempts = 3;                  // commands + read-backs per step before the lamps count as taken over
  int shot_attempts = 3;                  // exposures per step while another client keeps changing a lamp
};

struct CaptureHooks {
  // k of n shots done (the ambient frame is shot 1), estimated seconds left.
  std::function<void(int k, int n, double eta_s)> on_shot;
  const std::atomic<bool>* cancel = nullptr;
  // Called with the owner's lamp states before any lamp is touched, to keep
  // them where a crash cannot lose them; an error stops the capture.
  std::function<veneer::Status(const std::vector<LampState>&)> save_owner_state;
  // When set, each frame goes here as soon as it is taken (k = 0 the ambient
  // frame, k >= 1 lit by lamp k - 1; `raw` the camera's RAW file, `developed`
  // its JPEG, either may be empty) and is not kept: the result's set then holds no photos (images and
  // ambient empty, raw empty), only what set.json needs besides them. A
  // full-resolution set is 2 GiB as float; a rig board holds one frame at a
  // time. An error stops the capture.
  std::function<veneer::Status(int k, int shots, const cv::Mat& photo, const veneer::io::ImageSet::RawFile& raw,
                               const veneer::io::ImageSet::RawFile& developed)>
      on_frame;
};

struct CaptureResult;

// What run_capture leaves to its caller when it could not give the lamps back
// (the bridge is down): the states to restore once the bridge answers again.
struct PendingRestore {
  std::vector<LampState> states;
  bool needed = false;
};

struct CaptureResult {
  veneer::io::ImageSet set;      // lights, images, ambient, camera info, warnings; no truth
  double seconds = 0;        // wall time of the whole sequence
  double mean_step_s = 0;    // mean time of one lamp step (switch + settle + shot)
  int retakes = 0;           // frames taken again because another client changed a lamp
  bool restored = false;     // the owner's lamp states are back (proven)
};

// Runs the sequence. Errors name the step ("lamp 3 (Hue id 5): ...",
// "camera, shot 4 of 8: ..."); "cancelled" when the cancel flag was raised.
// When the lamps cannot be restored at the end, `pending` (if given) receives
// the owner's states so the caller can restore them later.
veneer::Expected<CaptureResult> run_capture(Lamps& lamps, Camera& camera, const CapturePlan& plan,
                                            const CaptureHooks& hooks = {}, PendingRestore* pending = nullptr);

// The mean linear level of a photo (all channels), used for the ambient check.
double mean_level(const cv::Mat& linear);

}  // namespace veneerd
