#pragma once
// Camera backend "simulated": asks the (emulated) Hue bridge which lamps are on
// and at what brightness — through the same libcurl Hue client as the real
// rig — and renders the current scene under exactly those lamps with the scene
// simulator (lamp at ring position i = veneer::sim::thesis_rig()[i]).
// Live view renders the source scene under a movable "hand-held lamp".
//
// Config section (JSON): the "hue" lamps section (bridge, key, lamps, ...) plus
//   {"scene": "bull", "preview_scene": "stone", "size": [1024, 680],
//    "preview_size": [1024, 680], "noise_sigma": 0.002, "preview_quality": 80,
//    "preview_render": "fast" | "full"}
// Exposure: gain = (shutter / (1/30 s)) * (8 / f-number)^2 * (ISO / 100), so
// 1/30 s, f/8, ISO 100 is the simulator's well-exposed shot (gain 1).
#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "veneer/io/imageset.hpp"
#include "veneer/sim/simulator.hpp"
#include "veneer/util/expected.hpp"
#include "veneerd/devices/camera.hpp"
#include "veneerd/hw/hue_lamps.hpp"

namespace veneerd {

class FaultPlan;

struct SimulatedCameraOptions {
  hw::HueLampsOptions bridge;            // where to read the lamps from (settle/pacing unused)
  std::string scene = "bull";        // what capture() sees
  std::string preview_scene = "stone";  // what preview() sees (the source object)
  cv::Size size{1024, 680};          // still size [px]
  cv::Size preview_size{1024, 680};  // live-view size [px]
  double noise_sigma = 0.002;        // sensor noise, fraction of full scale
  int preview_quality = 80;          // JPEG quality 1..100
  // Live view: "fast" shades a cached G-buffer of the preview scene (the
  // object's truth plus the table as a plane; diffuse, attached shadows, 1/r^2;
  // no cast shadows or highlights) so 1024x680 frames keep up with 15 fps;
  // "full" runs the simulator's renderer per frame.
  bool preview_full_render = false;
  // Live view in motion (issue 27): the same SPEC as `veneer simulate
  // --motion` (shift, rotate, scale, turn, lamp=sweep; not view: that is
  // preview_size), played back and forth over preview_motion_frames frames.
  // The whole picture moves (the tripod nudged, the object with its table);
  // lamp=sweep moves the hand lamp as simulate does. Empty = still.
  std::string preview_motion;
  int preview_motion_frames = 60;
  // Each still also as the camera's RAW file, as a body set to RAW+JPEG
  // delivers it: a DNG of the linear render (Bayer mosaic, 14-bit, black and
  // white levels, as-shot white balance; veneer/io/dng.hpp), which the set
  // keeps beside its photo and the viewer decodes by default. Config "raw".
  bool raw = true;
  // Each still also as the camera's developed JPEG (sRGB, 8-bit, quality 95;
  // veneer/io/camera_files.hpp), which the set stores as the photo instead of
  // a 16-bit PNG of the render, as a RAW+JPEG body's. Config "jpeg".
  bool jpeg = true;
  veneer::Status check() const;
  static veneer::Expected<SimulatedCameraOptions> from_json(const nlohmann::json& section);
  nlohmann::json to_json() const;
};

class SimulatedCamera : public Camera {
 public:
  static veneer::Expected<std::unique_ptr<SimulatedCamera>> create(const SimulatedCameraOptions& options);
  ~SimulatedCamera() override;

  std::string name() const override { return "simulated"; }
  veneer::Status open() override;
  bool connected() const override;
  veneer::Expected<CameraDescription> describe() override;
  veneer::Status set_exposure(const Exposure& exposure) override;
  veneer::Expected<Still> capture() override;
  veneer::Expected<std::vector<unsigned char>> preview() override;

  // --- simulated-rig controls (thread-safe) -------------------------------
  veneer::Status set_scene(const std::string& name);          // capture() scene
  veneer::Status set_preview_scene(const std::string& name);  // preview() scene
  std::string scene() const;
  std::string preview_scene() const;
  // Position of the hand-held lamp for preview(), rig frame [m].
  void set_hand_lamp(const cv::Vec3d& position_m, float brightness = 1.0f);
  cv::Vec3d hand_lamp() const;

  // Faults: capture number k (1-based, counted from now) fails.
  void fail_on_shot(int k);
  // Unplug / plug the camera; fires on_connection_change.
  void disconnect();
  void reconnect();
  // Unplugs the camera now and plugs it in again `gone` later (a USB drop).
  void unplug_for(std::chrono::milliseconds gone);
  // Faults drawn per shot from `plan` (camera.gone, clock.step; fault_plan.hpp); null = none.
  void set_fault_plan(std::shared_ptr<FaultPlan> plan);

  // What the camera has done and would do.
  uint64_t shots() const;                          // captures so far
  double gain() const;                             // exposure -> render gain
  // The render options of the next still (size, gain, noise, seed = shot count + 1).
  veneer::sim::RenderOptions still_options() const;
  // The lamps the last capture rendered (ring order, brightness 0 = off).
  std::vector<veneer::sim::Lamp> last_lamps() const;
  // Ground truth of the current scene at the still size (for a set's truth/).
  veneer::Expected<veneer::io::Truth> truth();
  // Camera intrinsics/metadata for a set's manifest.
  veneer::io::CameraInfo camera_info() const;

 private:
  struct Impl;
  explicit SimulatedCamera(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

// The simulated camera behind `camera`, or nullptr if it is another backend.
SimulatedCamera* as_simulated(Camera* camera);

}  // namespace veneerd
