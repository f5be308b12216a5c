#include <gtest/gtest.h>

#include "fakes.hpp"
#include "veneerd/config.hpp"
#include "veneerd/sequencer.hpp"

using rigtest::FakeCamera;
using rigtest::FakeLamps;

namespace {
veneerd::CapturePlan plan(int n) {
  veneerd::CapturePlan p;
  p.set_id = "t1";
  p.role = veneer::Role::destination;
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
  EXPECT_EQ(lamps.restores, 1);
  EXPECT_TRUE(lamps.states_[2].on);
  EXPECT_EQ(lamps.states_[2].brightness, 100);
}

TEST(Sequencer, LampFailureFailsTheWholeCaptureAndRestores) {
  FakeLamps lamps(5);
  FakeCamera camera(lamps, {8, 8});
  lamps.fail_on_set = 3;  // lamp 2 cannot be switched on
  auto r = veneerd::run_capture(lamps, camera, plan(5));
  ASSERT_FALSE(r);
  EXPECT_NE(r.message().find("lamp 2 (id 11)"), std::string::npos) << r.message();
  EXPECT_EQ(lamps.restores, 1);
  for (const auto& s : lamps.states_) EXPECT_FALSE(s.on);
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
  EXPECT_EQ(lamps.restores, 1);
}

TEST(Sequencer, CancelStopsAndRestores) {
  FakeLamps lamps(4);
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
  EXPECT_EQ(lamps.restores, 1);
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
