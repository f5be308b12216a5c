#include <gtest/gtest.h>

#include "fakes.hpp"
#include "veneerd/config.hpp"
#include "veneerd/sequencer.hpp"

using rigtest::FakeCamera;
using rigtest::FakeLamps;
using veneerd::LampState;

namespace {
// Every lamp shows its owner's state again (on/off, and the colour of those on).
void expect_owner_states(const FakeLamps& lamps, const std::vector<LampState>& owner) {
  ASSERT_EQ(lamps.states_.size(), owner.size());
  for (size_t i = 0; i < owner.size(); ++i)
    EXPECT_TRUE(veneerd::same_light(lamps.states_[i], owner[i]))
        << "lamp " << i + 1 << ": " << veneerd::describe(lamps.states_[i]) << ", owner had "
        << veneerd::describe(owner[i]);
}

// Each frame shows exactly its lamp: FakeCamera's level is 0.1 * (i + 1) per lamp on.
void expect_one_lamp_per_frame(const veneer::io::ImageSet& set, int n) {
  EXPECT_NEAR(set.ambient.at<cv::Vec3f>(0, 0)[0], 0.0f, 1e-6) << "ambient frame with a lamp on";
  ASSERT_EQ(set.images.size(), static_cast<size_t>(n));
  for (int i = 0; i < n; ++i)
    EXPECT_NEAR(set.images[i].at<cv::Vec3f>(3, 3)[1], 0.1f * (i + 1), 1e-6) << "frame " << i + 1 << ": only lamp " << i + 1;
}

veneerd::CapturePlan plan(int n) {
  veneerd::CapturePlan p;
  p.set_id = "t1";
  p.role = veneer::io::Role::destination;
  p.object = "thing";
  auto ring = veneerd::thesis_ring_positions();
  p.lamp_positions.assign(ring.begin(), ring.begin() + n);
  for (int i = 0; i < n; ++i) p.lamp_ids.push_back(std::to_string(i + 10));
  return p;
}
}  // namespace

TEST(Sequencer, AmbientThenOneShotPerLampThenRestores) {
  FakeLamps lamps(4);
  lamps.states_[2].on = true;  // the owner left lamp 3 on at brightness 100
  lamps.states_[2].brightness = 100;
  auto owner = lamps.states_;
  FakeCamera camera(lamps, {16, 12});
  std::vector<int> ks;
  veneerd::CaptureHooks hooks;
  hooks.on_shot = [&](int k, int n, double eta) {
    ks.push_back(k);
    EXPECT_EQ(n, 5);
    EXPECT_GE(eta, 0);
  };
  auto r = veneerd::run_capture(lamps, camera, plan(4), hooks);
  ASSERT_TRUE(r) << r.message();
  EXPECT_EQ(ks, (std::vector<int>{1, 2, 3, 4, 5}));
  const auto& set = r->set;
  ASSERT_EQ(set.images.size(), 4u);
  EXPECT_NEAR(set.ambient.at<cv::Vec3f>(0, 0)[0], 0.0f, 1e-6);  // all off, not the owner's lamp
  for (int i = 0; i < 4; ++i) {
    EXPECT_NEAR(set.images[i].at<cv::Vec3f>(3, 3)[1], 0.1f * (i + 1), 1e-6) << "only lamp " << i << " on";
    EXPECT_EQ(set.lights[i].lamp_id, std::to_string(i + 10));
    EXPECT_NEAR(cv::norm(set.lights[i].direction), 1.0, 1e-9);
  }
  EXPECT_TRUE(set.warnings.empty());
  EXPECT_TRUE(r->restored);
  EXPECT_EQ(r->retakes, 0);
  expect_owner_states(lamps, owner);
  EXPECT_EQ(lamps.states_[2].brightness, 100);
}

TEST(Sequencer, LampFailureFailsTheWholeCaptureAndRestores) {
  FakeLamps lamps(5);
  FakeCamera camera(lamps, {8, 8});
  // All lamps are off already, so the ambient frame needs no command: the
  // second command is lamp 2's.
  lamps.fail_on_set = 2;
  auto owner = lamps.states_;
  auto r = veneerd::run_capture(lamps, camera, plan(5));
  ASSERT_FALSE(r);
  EXPECT_NE(r.message().find("shot 3 (lamp 2 alone)"), std::string::npos) << r.message();
  EXPECT_NE(r.message().find("bridge timeout"), std::string::npos) << r.message();
  expect_owner_states(lamps, owner);
}

TEST(Sequencer, UnreachableLampStopsBeforeAnyShot) {
  FakeLamps lamps(3);
  lamps.states_[1].reachable = false;
  FakeCamera camera(lamps, {8, 8});
  auto r = veneerd::run_capture(lamps, camera, plan(3));
  ASSERT_FALSE(r);
  EXPECT_NE(r.message().find("unreachable"), std::string::npos) << r.message();
  EXPECT_EQ(camera.shots, 0);
}

TEST(Sequencer, CameraFailureOnShotKNamesTheShot) {
  FakeLamps lamps(4);
  FakeCamera camera(lamps, {8, 8});
  camera.fail_on_shot = 3;
  auto r = veneerd::run_capture(lamps, camera, plan(4));
  ASSERT_FALSE(r);
  EXPECT_NE(r.message().find("shot 3 of 5"), std::string::npos) << r.message();
  for (const auto& s : lamps.states_) EXPECT_FALSE(s.on) << "lamp 2 left on after the failed shot";
}

TEST(Sequencer, CancelStopsAndRestores) {
  FakeLamps lamps(4);
  lamps.states_[3].on = true;
  auto owner = lamps.states_;
  FakeCamera camera(lamps, {8, 8});
  std::atomic<bool> cancel{false};
  veneerd::CaptureHooks hooks;
  hooks.cancel = &cancel;
  hooks.on_shot = [&](int k, int, double) {
    if (k == 2) cancel = true;
  };
  auto r = veneerd::run_capture(lamps, camera, plan(4), hooks);
  ASSERT_FALSE(r);
  EXPECT_EQ(r.message(), "cancelled");
  EXPECT_EQ(camera.shots, 2);
  expect_owner_states(lamps, owner);
}

TEST(Sequencer, BrightAmbientFrameWarnsInTheManifest) {
  FakeLamps lamps(3);
  FakeCamera camera(lamps, {8, 8});
  camera.ambient = 0.08f;
  auto r = veneerd::run_capture(lamps, camera, plan(3));
  ASSERT_TRUE(r) << r.message();
  ASSERT_EQ(r->set.warnings.size(), 1u);
  EXPECT_NE(r->set.warnings[0].find("ambient"), std::string::npos);
}

TEST(Sequencer, RestoreFailureIsReportedAndLeftPending) {
  FakeLamps lamps(3);
  FakeCamera camera(lamps, {8, 8});
  lamps.states_[0].on = true;
  camera.fail_on_shot = 2;
  veneerd::CaptureHooks hooks;
  hooks.on_shot = [&](int, int, double) { lamps.down = true; };  // the bridge dies after shot 1
  veneerd::PendingRestore pending;
  auto r = veneerd::run_capture(lamps, camera, plan(3), hooks, &pending);
  ASSERT_FALSE(r);
  ASSERT_TRUE(pending.needed);
  EXPECT_TRUE(pending.states[0].on);
}

TEST(Sequencer, LampsSwitchedByAnotherClientBeforeAndDuringTheSetAreCorrected) {
  FakeLamps lamps(5);
  // The owner left lamp 2 on in ct mode and lamp 4 on in hue/sat mode; lamp 5
  // is off but remembers a dim warm white.
  lamps.states_[1] = LampState{.on = true, .brightness = 120, .mode = veneerd::ColourMode::ct, .ct = 400};
  lamps.states_[3] = LampState{.on = true, .brightness = 60, .mode = veneerd::ColourMode::hs, .hue = 46000, .sat = 200};
  lamps.states_[4] = LampState{.on = false, .brightness = 30, .mode = veneerd::ColourMode::ct, .ct = 450};
  auto owner = lamps.states_;
  FakeCamera camera(lamps, {8, 8});
  // Mid-set, after the third command, another app switches lamps 1 and 3 on, red.
  lamps.after_command = [&](int n) {
    if (n != 3) return;
    for (int i : {0, 2}) lamps.states_[i] = LampState{.on = true, .brightness = 254, .x = 0.65, .y = 0.3};
  };
  auto r = veneerd::run_capture(lamps, camera, plan(5));
  ASSERT_TRUE(r) << r.message();
  expect_one_lamp_per_frame(r->set, 5);
  expect_owner_states(lamps, owner);
  EXPECT_EQ(lamps.states_[1].mode, veneerd::ColourMode::ct);
  EXPECT_EQ(lamps.states_[3].mode, veneerd::ColourMode::hs);
  // Off lamps keep their owner's look for the next time they are switched on.
  for (int i : {0, 2, 4}) {
    EXPECT_FALSE(lamps.states_[i].on);
    EXPECT_TRUE(veneerd::same_colour(lamps.states_[i], owner[i])) << "lamp " << i + 1 << " " << veneerd::describe(lamps.states_[i]);
  }
}

TEST(Sequencer, AFrameDuringWhichALampChangedIsTakenAgain) {
  FakeLamps lamps(4);
  auto owner = lamps.states_;
  FakeCamera camera(lamps, {8, 8});
  // While shot 3 (lamp 2 alone) is exposed, another app switches lamp 4 on.
  camera.during_exposure = [&](int shot) {
    if (shot == 3) lamps.states_[3] = LampState{.on = true, .brightness = 254};
  };
  auto r = veneerd::run_capture(lamps, camera, plan(4));
  ASSERT_TRUE(r) << r.message();
  EXPECT_EQ(r->retakes, 1);
  EXPECT_EQ(camera.shots, 6);
  expect_one_lamp_per_frame(r->set, 4);
  expect_owner_states(lamps, owner);
}

TEST(Sequencer, LampsThatWillNotHoldStillFailTheSetAndNothingIsReturned) {
  FakeLamps lamps(3);
  auto owner = lamps.states_;
  FakeCamera camera(lamps, {8, 8});
  // Another app switches lamp 3 on during every exposure.
  camera.during_exposure = [&](int) { lamps.states_[2] = LampState{.on = true, .brightness = 254}; };
  auto r = veneerd::run_capture(lamps, camera, plan(3));
  ASSERT_FALSE(r);
  EXPECT_NE(r.message().find("another client changed the lamps during the exposure"), std::string::npos) << r.message();
  EXPECT_NE(r.message().find("lamp 3"), std::string::npos) << r.message();
  expect_owner_states(lamps, owner);
}

TEST(Sequencer, OwnerStatesAreSavedBeforeAnyLampIsTouched) {
  FakeLamps lamps(3);
  lamps.states_[0].on = true;
  auto owner = lamps.states_;
  FakeCamera camera(lamps, {8, 8});
  veneerd::CaptureHooks hooks;
  std::vector<LampState> saved;
  int commands_before_save = -1;
  hooks.save_owner_state = [&](const std::vector<LampState>& s) {
    saved = s;
    commands_before_save = lamps.sets;
    return veneer::Status{};
  };
  auto r = veneerd::run_capture(lamps, camera, plan(3), hooks);
  ASSERT_TRUE(r) << r.message();
  EXPECT_EQ(commands_before_save, 0);
  ASSERT_EQ(saved.size(), 3u);
  EXPECT_TRUE(saved[0].on);

  // When they cannot be saved, nothing is touched.
  FakeLamps lamps2(3);
  lamps2.states_[0].on = true;
  FakeCamera camera2(lamps2, {8, 8});
  hooks.save_owner_state = [](const std::vector<LampState>&) { return veneer::Status(veneer::make_error("disk full")); };
  auto r2 = veneerd::run_capture(lamps2, camera2, plan(3), hooks);
  ASSERT_FALSE(r2);
  EXPECT_NE(r2.message().find("disk full"), std::string::npos);
  EXPECT_EQ(lamps2.sets, 0);
  EXPECT_EQ(camera2.shots, 0);
}

TEST(Sequencer, TheCamerasRawFilesGoWithTheSet) {
  FakeLamps lamps(3);
  FakeCamera camera(lamps, {16, 12});
  camera.raw = true;
  auto r = veneerd::run_capture(lamps, camera, plan(3), {});
  ASSERT_TRUE(r) << r.message();
  const auto& set = r->set;
  ASSERT_EQ(set.raw.size(), 3u);
  // Shot 1 is the ambient frame, shot k + 2 lamp k's photo.
  EXPECT_EQ(set.ambient_raw.extension, "cr2");
  EXPECT_EQ(set.ambient_raw.bytes, "raw of shot 1");
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(set.raw[i].extension, "cr2");
    EXPECT_EQ(set.raw[i].bytes, "raw of shot " + std::to_string(i + 2));
  }
  // A camera that gives no RAW file: none in the set.
  FakeCamera plain(lamps, {16, 12});
  auto p = veneerd::run_capture(lamps, plain, plan(3), {});
  ASSERT_TRUE(p) << p.message();
  for (const auto& f : p->set.raw) EXPECT_TRUE(f.bytes.empty());
  EXPECT_TRUE(p->set.ambient_raw.bytes.empty());
}
