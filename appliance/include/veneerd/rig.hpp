#pragma once
// The rig: its devices, the set store and the capture sequencer, driven from
// the API server and the capture button. Device work runs on one worker
// thread (the devices are serial anyway); live view on its own thread.
// Events and live frames go out through callbacks that must not block.
//
// The lamps belong to their owner (the Hue app, scenes, sensors). veneerd
// leaves them alone at start and at exit, except to give back what it took:
// before it first changes a lamp (a capture, or a client's lamp request) it
// writes the owner's states to `owner_state_file`; a capture restores the
// states it found when it ends (done, failed or cancelled); at exit the
// owner's states from that file go back, and the file is removed once the
// bridge confirms them; a file found at start (a crash or power loss while
// the rig had the lamps) is restored then. While idle the rig reads the
// bridge every few seconds, so the status shows the lamps as they are.
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <filesystem>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/io/imageset.hpp"
#include "veneer/util/expected.hpp"
#include "veneerd/devices/camera.hpp"
#include "veneerd/devices/lamps.hpp"
#include "veneerd/devices/trigger.hpp"
#include "veneerd/sequencer.hpp"
#include "veneerd/store.hpp"

namespace veneerd {

struct RigEvent {
  enum class Kind {
    button_pressed, capture_started, shot_taken, set_stored, capture_failed,
    lamp_state, camera_connected, camera_lost, set_deleted, set_restored,
  };
  Kind kind = Kind::button_pressed;
  std::string set_id;
  veneer::io::Role role = veneer::io::Role::unknown;
  std::string object;
  int k = 0, n = 0;                   // shot_taken; n also in capture_started
  double eta_s = 0;
  std::vector<std::string> warnings;  // set_stored
  std::string reason;                 // capture_failed, camera_lost
  bool cancelled = false;
  bool long_press = false;
  std::vector<bool> lamps_on;         // lamp_state
  int brightness = 0;
  std::string camera_model;           // camera_connected
};

struct LiveFrameData {
  std::vector<unsigned char> jpeg;
  uint64_t seq = 0;
  double ts = 0;  // Unix time [s]
  int width = 0, height = 0;
};

struct RigDevices {
  std::unique_ptr<Lamps> lamps;
  std::unique_ptr<Camera> camera;
  std::unique_ptr<Trigger> trigger;   // may be null
  std::unique_ptr<StatusLed> led;     // may be null
};

// What only the simulated rig has: scene choice per role, ground truth, the
// hand-held lamp of the live view.
struct SimulatedHooks {
  std::vector<std::string> scenes;  // [destination scene, source scene]
  std::function<void(veneer::io::Role role, const std::string& scene)> select_scene;
  // Completes a captured set before it is stored: ground truth, camera
  // intrinsics, the lamps' irradiance in image units.
  std::function<void(veneer::io::ImageSet& set)> finish_set;
  std::function<void(const cv::Vec3d& position)> move_hand_lamp;
};

struct RigOptions {
  std::string name = "veneer-rig";
  std::vector<std::string> lamp_ids;
  std::vector<cv::Vec3d> lamp_positions;
  Exposure exposure;
  double ambient_warning = 0.05;
  int settle_ms = 150;
  std::filesystem::path owner_state_file;  // the owner's lamp states while veneerd holds the lamps; empty = not kept
  double lamp_poll_s = 2.0;                // reading of the bridge while idle [s]; 0 = only around captures
  bool simulated = false;
  SimulatedHooks sim;
};

struct CaptureRequest {
  veneer::io::Role role = veneer::io::Role::unknown;  // unknown = the next role
  std::string object;                         // empty = scene or role name
  Exposure exposure;                          // zeros = the configured exposure
};

struct RigState {
  std::string name;
  bool simulated = false;
  bool camera_connected = false;
  std::string camera_model;
  int lamp_count = 0;
  std::vector<bool> lamps_on;          // as the bridge reported them (lamps_age_s ago)
  std::vector<LampState> lamps;        // the same reading, whole
  std::vector<std::string> lamp_ids;
  double lamps_age_s = -1;             // age of that reading [s]; -1 = never read
  std::string lamps_problem;           // why the lamps can't be used now (key refused, bridge down...); empty = fine
  bool holds_lamps = false;            // veneerd changed lamps that go back to their owner at exit
  bool capturing = false;
  veneer::io::Role next_role = veneer::io::Role::destination;
};

class Rig {
 public:
  Rig(RigDevices devices, Store& store, RigOptions options);
  ~Rig();
  Rig(const Rig&) = delete;
  Rig& operator=(const Rig&) = delete;

  // Set before start(); called from the rig's threads, must not block.
  std::function<void(const RigEvent&)> on_event;
  std::function<void(std::shared_ptr<const LiveFrameData>)> on_live_frame;

  // Opens the camera, switches every lamp off, starts the threads.
  void start();
  void stop();

  // Queues a capture; the id it will be stored under, or why not (busy, ...).
  veneer::Expected<std::string> capture(const CaptureRequest& request);
  veneer::Status cancel();
  // The capture button (physical, simulated or through the API).
  void press(Press press);
  // Sets lamps on the worker thread; `done` is called there when finished.
  void set_lamps(std::vector<bool> on, int brightness, std::function<void(veneer::Status)> done);
  veneer::Status move_hand_lamp(const cv::Vec3d& position);
  // Live view rate wanted by the clients (the highest); 0 stops it.
  void set_live_fps(double fps);
  // Deletes a stored set (not one being written).
  veneer::Status delete_set(const std::string& id);
  // Brings a set back from the store's trash; every client hears set_restored.
  veneer::Status restore_set(const std::string& id);

  RigState state() const;
  Store& store() { return store_; }
  const RigOptions& options() const { return options_; }

 private:
  void handle_press(Press press);
  void emit(RigEvent event);
  void post(std::function<void()> job);
  void worker_loop();
  void retry_restore();
  // Reads the bridge into lamps_now_ / lamps_problem_ (worker thread).
  void refresh_lamps();
  void note_lamps(const veneer::Expected<std::vector<LampState>>& reading);
  // The owner's states on disk before the first change (worker thread).
  veneer::Status save_owner(const std::vector<LampState>& states);
  void drop_owner();
  veneer::Expected<std::vector<LampState>> load_owner();
  void give_back_owner(const char* when);
  void live_loop();
  void run_capture_job(const std::string& id, CaptureRequest request);

  RigDevices dev_;
  Store& store_;
  RigOptions options_;

  mutable std::mutex mutex_;  // guards the fields below
  bool capturing_ = false;
  std::string capture_id_;
  veneer::io::Role next_role_ = veneer::io::Role::destination;
  std::vector<LampState> lamps_now_;
  std::chrono::steady_clock::time_point lamps_read_at_{};
  std::string lamps_problem_;
  std::atomic<bool> owner_saved_{false};  // owner_state_file holds the owner's states
  bool owner_by_capture_ = false;   // ... written by the capture now running or pending restore
  std::string camera_model_;
  bool camera_connected_ = false;
  double mean_step_s_ = 0;
  PendingRestore pending_restore_;  // worker thread only

  std::atomic<bool> cancel_{false};
  std::atomic<bool> stopping_{false};
  std::mutex camera_mutex_;  // capture vs live view

  std::mutex jobs_mutex_;
  std::condition_variable jobs_cv_;
  std::deque<std::function<void()>> jobs_;
  std::thread worker_;

  std::mutex live_mutex_;
  std::condition_variable live_cv_;
  double live_fps_ = 0;
  uint64_t live_plan_ = 0;  // bumped by every set_live_fps: the live thread plans its next frame again
  uint64_t live_seq_ = 0;
  std::thread live_;
};

}  // namespace veneerd
