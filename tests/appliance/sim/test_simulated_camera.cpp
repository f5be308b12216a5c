// The simulated camera (lamps read back from the bridge emulator over HTTP),
// the simulated button and LED, and the one-call SimulatedRig.
#include <gtest/gtest.h>

#include <opencv2/imgcodecs.hpp>

#include "veneer/io/raw.hpp"
#include "veneer/sim/simulator.hpp"
#include "veneerd/sim/simulated_rig.hpp"

using veneerd::SimulatedRig;
using veneerd::SimulatedRigOptions;

namespace {

std::vector<bool> one_hot(int n, int i) {
  std::vector<bool> v(n, false);
  v[i] = true;
  return v;
}

SimulatedRigOptions small_rig() {
  SimulatedRigOptions o;
  o.scenes = {"sphere-gray", "two-spheres"};
  o.size = {256, 170};
  o.preview_size = {200, 132};
  o.noise_sigma = 0.0;
  o.apply_delay_ms = 30;
  o.settle_ms = 60;
  o.latency_ms = 0;
  return o;
}

double max_abs_diff(const cv::Mat& a, const cv::Mat& b) {
  cv::Mat d;
  cv::absdiff(a, b, d);
  double m = 0;
  cv::minMaxLoc(d.reshape(1), nullptr, &m);
  return m;
}

class Camera : public ::testing::Test {
 protected:
  void SetUp() override {
    auto r = SimulatedRig::start(small_rig());
    ASSERT_TRUE(r.ok()) << r.message();
    rig = std::move(*r);
    auto l = rig->make_lamps();
    ASSERT_TRUE(l.ok()) << l.message();
    lamps = std::move(*l);
    auto c = rig->make_camera();
    ASSERT_TRUE(c.ok()) << c.message();
    camera = std::move(*c);
    ASSERT_TRUE(camera->open().ok());
  }
  cv::Mat direct(const std::vector<int>& lit, const veneer::sim::RenderOptions& r, const std::string& scene) {
    auto s = veneer::sim::make_scene(scene, r);
    EXPECT_TRUE(s.ok());
    std::vector<veneer::sim::Lamp> lamps_on;
    auto ring = veneer::sim::thesis_rig();
    for (int i : lit) lamps_on.push_back(ring[i]);
    return veneer::sim::render(**s, lamps_on, r);
  }

  std::unique_ptr<SimulatedRig> rig;
  std::unique_ptr<veneerd::hw::HueLamps> lamps;
  std::unique_ptr<veneerd::SimulatedCamera> camera;
};

}  // namespace

TEST_F(Camera, RendersExactlyTheLitLamp) {
  ASSERT_TRUE(lamps->set(one_hot(7, 2)).ok());
  auto r = camera->still_options();
  auto still = camera->capture();
  ASSERT_TRUE(still.ok()) << still.message();
  ASSERT_EQ(still->linear.type(), CV_32FC3);
  ASSERT_EQ(still->linear.size(), cv::Size(256, 170));
  cv::Mat same = direct({2}, r, "sphere-gray");
  cv::Mat other = direct({5}, r, "sphere-gray");
  EXPECT_LT(max_abs_diff(still->linear, same), 1e-6);
  EXPECT_GT(max_abs_diff(still->linear, other), 0.05);  // the oracle tells lamps apart
  EXPECT_GT(cv::mean(still->linear)[1], 0.005);

  auto lit = camera->last_lamps();
  ASSERT_EQ(lit.size(), 7u);
  for (int i = 0; i < 7; ++i) EXPECT_EQ(lit[i].brightness > 0, i == 2) << i;
}

TEST_F(Camera, EachStillComesWithADngOfItsLinearRender) {
  ASSERT_TRUE(lamps->set(one_hot(7, 4)).ok());
  auto still = camera->capture();
  ASSERT_TRUE(still.ok()) << still.message();
  EXPECT_TRUE(veneer::io::is_raw_file_name(still->original_name)) << still->original_name;
  ASSERT_FALSE(still->original.empty());
  const std::string_view bytes(reinterpret_cast<const char*>(still->original.data()), still->original.size());
  auto decoded = veneer::io::decode_raw_linear(bytes, {}, still->original_name);
  ASSERT_TRUE(decoded.ok()) << decoded.message();
  ASSERT_EQ(decoded->size(), still->linear.size());
  // The RAW path gives the render back: each channel's mean within 1 %.
  const cv::Scalar a = cv::mean(*decoded), b = cv::mean(still->linear);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(a[c], b[c], 0.01 * b[c] + 1e-5) << "channel " << c;
  EXPECT_GT(b[1], 0.005);
}

TEST_F(Camera, AmbientFrameIsDarkAndNoiseFollowsTheShotCounter) {
  ASSERT_TRUE(lamps->all_off().ok());
  auto dark = camera->capture();
  ASSERT_TRUE(dark.ok()) << dark.message();
  EXPECT_LT(cv::mean(dark->linear)[0] + cv::mean(dark->linear)[1] + cv::mean(dark->linear)[2], 1e-4);

  // With noise: the same as the simulator with seed = shot number.
  auto o = small_rig();
  o.noise_sigma = 0.01;
  auto noisy_rig = SimulatedRig::start(o);
  ASSERT_TRUE(noisy_rig.ok());
  auto l = (*noisy_rig)->make_lamps();
  auto c = (*noisy_rig)->make_camera();
  ASSERT_TRUE(l.ok() && c.ok());
  ASSERT_TRUE((*l)->set(one_hot(7, 0)).ok());
  auto r1 = (*c)->still_options();
  auto s1 = (*c)->capture();
  auto r2 = (*c)->still_options();
  auto s2 = (*c)->capture();
  ASSERT_TRUE(s1.ok() && s2.ok());
  EXPECT_EQ(r1.seed, 1u);
  EXPECT_EQ(r2.seed, 2u);
  EXPECT_LT(max_abs_diff(s1->linear, direct({0}, r1, "sphere-gray")), 1e-6);
  EXPECT_LT(max_abs_diff(s2->linear, direct({0}, r2, "sphere-gray")), 1e-6);
  EXPECT_GT(max_abs_diff(s1->linear, s2->linear), 1e-3);  // different noise per shot
}

TEST_F(Camera, ExposureScalesTheImage) {
  ASSERT_TRUE(lamps->set(one_hot(7, 1)).ok());
  auto base = camera->capture();
  ASSERT_TRUE(base.ok());
  EXPECT_DOUBLE_EQ(camera->gain(), 1.0);
  ASSERT_TRUE(camera->set_exposure({1.0 / 60, 0, 0}).ok());
  EXPECT_NEAR(camera->gain(), 0.5, 1e-12);
  auto half = camera->capture();
  ASSERT_TRUE(half.ok());
  EXPECT_NEAR(cv::mean(half->linear)[1], 0.5 * cv::mean(base->linear)[1], 0.05 * cv::mean(base->linear)[1] + 1e-6);
  EXPECT_FALSE(camera->set_exposure({-1, 0, 0}).ok());
  EXPECT_FALSE(camera->set_exposure({0, 0.2, 0}).ok());
  auto d = camera->describe();
  ASSERT_TRUE(d.ok());
  EXPECT_FALSE(d->shutter_values.empty());
  EXPECT_FALSE(d->aperture_values.empty());
  EXPECT_FALSE(d->iso_values.empty());
  auto info = camera->camera_info();
  EXPECT_NEAR(info.exposure_s, 1.0 / 60, 1e-12);
}

TEST_F(Camera, SceneSwitchAndTruth) {
  ASSERT_TRUE(lamps->set(one_hot(7, 0)).ok());
  EXPECT_EQ(camera->scene(), "sphere-gray");
  ASSERT_TRUE(camera->set_scene(rig->scene_for(veneer::io::Role::source)).ok());
  EXPECT_EQ(camera->scene(), "two-spheres");
  auto r = camera->still_options();
  auto still = camera->capture();
  ASSERT_TRUE(still.ok());
  EXPECT_LT(max_abs_diff(still->linear, direct({0}, r, "two-spheres")), 1e-6);
  auto truth = camera->truth();
  ASSERT_TRUE(truth.ok()) << truth.message();
  EXPECT_EQ(truth->normals.size(), cv::Size(256, 170));
  EXPECT_GT(cv::countNonZero(truth->mask), 100);
  auto bad = camera->set_scene("unicorn");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.message().find("unicorn"), std::string::npos);
  EXPECT_NE(bad.message().find("bull"), std::string::npos);  // lists the known scenes
}

TEST_F(Camera, PreviewIsAJpegOfTheSourceUnderTheHandLamp) {
  auto a = camera->preview();
  ASSERT_TRUE(a.ok()) << a.message();
  cv::Mat img = cv::imdecode(*a, cv::IMREAD_COLOR);
  ASSERT_FALSE(img.empty());
  EXPECT_EQ(img.size(), cv::Size(200, 132));
  EXPECT_GT(cv::mean(img)[1], 1.0);
  camera->set_hand_lamp({-0.4, -0.2, 0.5});
  auto b = camera->preview();
  ASSERT_TRUE(b.ok());
  cv::Mat img2 = cv::imdecode(*b, cv::IMREAD_COLOR);
  cv::Mat diff;
  cv::absdiff(img, img2, diff);
  EXPECT_GT(cv::mean(diff)[0] + cv::mean(diff)[1] + cv::mean(diff)[2], 1.0);  // the light moved
}

TEST(SimulatedCameraPreview, FastLiveViewAgreesWithTheFullRender) {
  auto o = small_rig();
  o.scenes = {"sphere-gray"};
  auto rig = SimulatedRig::start(o);
  ASSERT_TRUE(rig.ok());
  auto fast_cfg = (*rig)->camera_config();
  auto full_cfg = fast_cfg;
  full_cfg["preview_render"] = "full";
  auto fast_o = veneerd::SimulatedCameraOptions::from_json(fast_cfg);
  auto full_o = veneerd::SimulatedCameraOptions::from_json(full_cfg);
  ASSERT_TRUE(fast_o.ok() && full_o.ok());
  EXPECT_FALSE(fast_o->preview_full_render);
  EXPECT_TRUE(full_o->preview_full_render);
  auto fast = veneerd::SimulatedCamera::create(*fast_o);
  auto full = veneerd::SimulatedCamera::create(*full_o);
  ASSERT_TRUE(fast.ok() && full.ok());
  veneer::sim::RenderOptions r;
  r.size = o.preview_size;
  r.focal_px = 2.0 * r.size.width;
  auto scene = veneer::sim::make_scene("sphere-gray", r);
  ASSERT_TRUE(scene.ok());
  cv::Mat object = veneer::sim::render_truth(**scene, r).mask;
  for (cv::Vec3d pos : {cv::Vec3d{0.3, 0.3, 0.7}, cv::Vec3d{-0.4, 0.0, 0.5}}) {
    (*fast)->set_hand_lamp(pos);
    (*full)->set_hand_lamp(pos);
    auto a = (*fast)->preview();
    auto b = (*full)->preview();
    ASSERT_TRUE(a.ok() && b.ok());
    cv::Mat ia = cv::imdecode(*a, cv::IMREAD_GRAYSCALE), ib = cv::imdecode(*b, cv::IMREAD_GRAYSCALE);
    ASSERT_EQ(ia.size(), ib.size());
    cv::Mat lit = (ib > 20) & object;  // the sphere where the full render sees it lit
    ASSERT_GT(cv::countNonZero(lit), 200);
    cv::Mat background;
    cv::bitwise_not(object, background);
    // The table: same light falloff, apart from the object's cast shadow.
    cv::Mat table_diff;
    cv::absdiff(ia, ib, table_diff);
    EXPECT_LT(cv::mean(table_diff, background)[0], 10.0) << "hand lamp at " << pos;
    EXPECT_GT(cv::mean(ia, background)[0], 5.0);
    cv::Mat diff;
    cv::absdiff(ia, ib, diff);
    EXPECT_LT(cv::mean(diff, lit)[0], 12.0) << "hand lamp at " << pos;
    EXPECT_GT(cv::mean(ia, lit)[0], 30.0);
  }
  auto bad = full_cfg;
  bad["preview_render"] = "raytraced";
  EXPECT_FALSE(veneerd::SimulatedCameraOptions::from_json(bad).ok());
}

TEST_F(Camera, FailsOnShotKAndSurvives) {
  ASSERT_TRUE(lamps->set(one_hot(7, 3)).ok());
  camera->fail_on_shot(2);
  EXPECT_TRUE(camera->capture().ok());
  auto failed = camera->capture();
  ASSERT_FALSE(failed.ok());
  EXPECT_NE(failed.message().find("shot 2"), std::string::npos) << failed.message();
  EXPECT_TRUE(camera->capture().ok());
}

TEST_F(Camera, DisconnectAndReconnect) {
  std::vector<bool> events;
  camera->on_connection_change = [&](bool c) { events.push_back(c); };
  camera->disconnect();
  EXPECT_FALSE(camera->connected());
  auto shot = camera->capture();
  ASSERT_FALSE(shot.ok());
  EXPECT_NE(shot.message().find("not connected"), std::string::npos);
  EXPECT_FALSE(camera->preview().ok());
  EXPECT_FALSE(camera->open().ok());
  camera->reconnect();
  EXPECT_TRUE(camera->connected());
  EXPECT_TRUE(camera->open().ok());
  EXPECT_EQ(events, (std::vector<bool>{false, true}));
}

TEST_F(Camera, BridgeDownIsAClearCaptureError) {
  rig->bridge().fail_next(1000, 500);
  auto shot = camera->capture();
  ASSERT_FALSE(shot.ok());
  EXPECT_NE(shot.message().find("cannot read the lamps"), std::string::npos) << shot.message();
}

TEST(SimulatedRig, DevicesThroughTheRegistry) {
  veneerd::register_simulated_devices();
  veneerd::register_hardware_devices();  // the lamps: the real "hue" back-end on the emulator
  auto r = SimulatedRig::start(small_rig());
  ASSERT_TRUE(r.ok()) << r.message();
  auto devices = (*r)->devices_config();
  auto& reg = veneerd::DeviceRegistry::instance();
  auto lamps = veneerd::DeviceRegistry::make(reg.lamps, "lamps", devices["lamps"]["backend"], devices["lamps"]);
  ASSERT_TRUE(lamps.ok()) << lamps.message();
  EXPECT_EQ((*lamps)->count(), 7);
  auto camera = veneerd::DeviceRegistry::make(reg.cameras, "camera", devices["camera"]["backend"], devices["camera"]);
  ASSERT_TRUE(camera.ok()) << camera.message();
  ASSERT_NE(veneerd::as_simulated(camera->get()), nullptr);
  auto trigger = veneerd::DeviceRegistry::make(reg.triggers, "trigger", devices["trigger"]["backend"], devices["trigger"]);
  ASSERT_TRUE(trigger.ok());
  std::vector<veneerd::Press> presses;
  (*trigger)->on_press = [&](veneerd::Press p) { presses.push_back(p); };
  (*trigger)->press(veneerd::Press::short_press);
  (*trigger)->press(veneerd::Press::long_press);
  EXPECT_EQ(presses, (std::vector<veneerd::Press>{veneerd::Press::short_press, veneerd::Press::long_press}));
  auto led = veneerd::DeviceRegistry::make(reg.leds, "led", devices["led"]["backend"], devices["led"]);
  ASSERT_TRUE(led.ok());
  (*led)->show(veneerd::LedState::capturing);
  (*led)->show(veneerd::LedState::done);
  auto* sim_led = dynamic_cast<veneerd::SimulatedLed*>(led->get());
  ASSERT_NE(sim_led, nullptr);
  EXPECT_EQ(sim_led->state(), veneerd::LedState::done);
  EXPECT_EQ(sim_led->history().size(), 2u);

  // A whole capture sequence over the real HTTP path: ambient + one shot per lamp, no refusals.
  ASSERT_TRUE((*lamps)->all_off().ok());
  auto* cam = veneerd::as_simulated(camera->get());
  for (int i = 0; i < 7; ++i) {
    ASSERT_TRUE((*lamps)->set(one_hot(7, i)).ok());
    auto still = cam->capture();
    ASSERT_TRUE(still.ok()) << still.message();
    auto lit = cam->last_lamps();
    for (int k = 0; k < 7; ++k) EXPECT_EQ(lit[k].brightness > 0, k == i) << "shot " << i << " lamp " << k;
  }
  ASSERT_TRUE((*lamps)->all_off().ok());
  EXPECT_EQ((*r)->bridge().counters().refused_rate, 0u);
  EXPECT_EQ((*r)->bridge().counters().refused_busy, 0u);
}

TEST(SimulatedRig, RejectsUnknownScenes) {
  SimulatedRigOptions o;
  o.scenes = {"bull", "dragon"};
  auto r = SimulatedRig::start(o);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.message().find("dragon"), std::string::npos);
}

// Issue 27: the simulated live view can play a motion (the SPEC of `veneer
// simulate --motion`), back and forth; a bad SPEC is refused naming it.
TEST(SimulatedCameraPreview, PlaysAMotionBackAndForth) {
  auto o = small_rig();
  o.scenes = {"sphere-gray"};
  o.preview_motion = "shift=12:0";
  o.preview_motion_frames = 3;
  auto rig = SimulatedRig::start(o);
  ASSERT_TRUE(rig.ok()) << rig.message();
  auto cam = (*rig)->make_camera();
  ASSERT_TRUE(cam.ok()) << cam.message();
  ASSERT_TRUE((*cam)->open().ok());
  std::vector<cv::Mat> frames;
  for (int i = 0; i < 5; ++i) {  // positions 0, 6, 12, 6, 0 px
    auto jpeg = (*cam)->preview();
    ASSERT_TRUE(jpeg.ok()) << jpeg.message();
    frames.push_back(cv::imdecode(*jpeg, cv::IMREAD_GRAYSCALE));
  }
  const cv::Rect inner(20, 10, 150, 110);
  auto mean_diff = [](const cv::Mat& a, const cv::Mat& b) {
    cv::Mat d;
    cv::absdiff(a, b, d);
    return cv::mean(d)[0];
  };
  // frame 2 is frame 0 moved 12 px to the right (JPEG's blocks apart); frame 4 is back
  const double moved = mean_diff(frames[2](inner + cv::Point(12, 0)), frames[0](inner));
  const double unmoved = mean_diff(frames[2](inner), frames[0](inner));
  EXPECT_LT(moved, 3.0);
  EXPECT_GT(unmoved, 3 * moved) << moved;
  EXPECT_LT(mean_diff(frames[4], frames[0]), 1.0);
  EXPECT_LT(mean_diff(frames[3], frames[1]), 1.0);

  auto cfg = (*rig)->camera_config();
  EXPECT_EQ(cfg["preview_motion"], "shift=12:0");
  cfg["preview_motion"] = "shift=1:1,wobble=2";
  auto bad = veneerd::SimulatedCameraOptions::from_json(cfg);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.message().find("wobble=2"), std::string::npos) << bad.message();
}
