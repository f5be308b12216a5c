// A live sequence under one moving lamp (sim/light_path.hpp, issue 40): the
// named paths' lamps lie between and beyond the rig's, the sidecar round-trips,
// the truth frames are a direct render of the destination in the source's
// material and the live frames the source's.
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>

#include <gtest/gtest.h>

#include "live_frame.hpp"
#include "veneer/sim/light_path.hpp"
#include "veneer/sim/simulator.hpp"

namespace veneer::sim {
namespace {
namespace fs = std::filesystem;

double degrees_between(const cv::Vec3d& a, const cv::Vec3d& b) {
  return std::acos(std::clamp(a.dot(b) / (cv::norm(a) * cv::norm(b)), -1.0, 1.0)) * 180 / CV_PI;
}
double off_axis_deg(const cv::Vec3d& d) { return degrees_between(d, {0, 0, 1}); }

TEST(LightPath, LampsLieBetweenAndBeyondTheRigsLamps) {
  std::vector<cv::Vec3d> rig;
  for (const Lamp& l : thesis_rig()) rig.push_back(l.position_m / cv::norm(l.position_m));
  const double ring = off_axis_deg(rig[0]);  // 25.2 degrees
  EXPECT_NEAR(ring, 25.18, 0.01);
  for (const std::string& name : light_path_names()) {
    SCOPED_TRACE(name);
    auto spec = parse_light_path(name);
    ASSERT_TRUE(spec) << spec.message();
    const auto lights = light_path_lights(*spec, 30);
    ASSERT_EQ(lights.size(), 30u);
    double nearest = 180, lo = 90, hi = 0;
    for (const PathLight& l : lights) {
      EXPECT_NEAR(cv::norm(l.direction), 1.0, 1e-12);
      double d = 180;
      for (const cv::Vec3d& r : rig) d = std::min(d, degrees_between(l.direction, r));
      nearest = std::min(nearest, d);
      lo = std::min(lo, off_axis_deg(l.direction));
      hi = std::max(hi, off_axis_deg(l.direction));
      // as bright at the object as a rig lamp
      EXPECT_NEAR(l.intensity[0], 1.0, 1e-6);
    }
    std::printf("%s: %.1f..%.1f degrees off the camera's axis (the rig: %.1f), nearest rig lamp %.1f degrees away\n",
                name.c_str(), lo, hi, ring, nearest);
    EXPECT_GT(nearest, 8.0);  // never on a captured lamp
    if (name == "spiral") {   // inside the ring, across it, beyond it
      EXPECT_LT(lo, ring - 10);
      EXPECT_GT(hi, ring + 10);
    } else if (name == "circle") {
      EXPECT_GT(lo, ring + 10);
    } else {
      EXPECT_LT(hi, ring - 5);
    }
  }
  // where the spiral crosses the ring it passes between two lamps: bottom-right (135) and bottom-left (225)
  const auto spiral = light_path_lights(*parse_light_path("spiral"), 101);
  for (size_t i = 1; i < spiral.size(); ++i) {
    const double a = off_axis_deg(spiral[i - 1].direction), b = off_axis_deg(spiral[i].direction);
    if ((a - ring) * (b - ring) > 0) continue;
    const cv::Vec3d& p = spiral[i].position_m;
    double azimuth = std::atan2(p[0], p[1]) * 180 / CV_PI;
    if (azimuth < 0) azimuth += 360;
    std::printf("spiral crosses the ring at azimuth %.1f degrees\n", azimuth);
    EXPECT_GT(azimuth, 135 + 10);
    EXPECT_LT(azimuth, 225 - 10);
  }
}

TEST(LightPath, ParsesOverridesAndRefusesBadSpecs) {
  auto c = parse_light_path("circle,radius=0.5,height=0.9,from=0,to=90,colour=1:0.9:0.8");
  ASSERT_TRUE(c) << c.message();
  EXPECT_EQ(c->radius_m, 0.5);
  EXPECT_EQ(c->inner_m, 0.5);
  EXPECT_EQ(c->height_m, 0.9);
  EXPECT_EQ(c->to_deg, 90);
  EXPECT_EQ(c->colour, cv::Vec3f(1, 0.9f, 0.8f));
  for (const char* bad : {"zigzag", "circle,radius", "circle,radius=x", "circle,height=0", "circle,speed=2",
                          "arc,colour=1:2"}) {
    auto r = parse_light_path(bad);
    EXPECT_FALSE(r) << bad;
    if (!r) {
      EXPECT_NE(r.message().find("light path"), std::string::npos) << r.message();
    }
  }
}

TEST(LightPath, SidecarRoundTrips) {
  LightPathFile c;
  c.spec = "spiral";
  c.source = "orange";
  c.destination = "bull";
  c.size = {64, 40};
  c.lights = light_path_lights(*parse_light_path("circle,colour=1:0.5:0.25"), 4, 2.0);
  c.truth_mask = "truth/mask.png";
  for (int i = 0; i < 4; ++i) {
    c.files.push_back("frame_000" + std::to_string(i) + ".png");
    c.truth_files.push_back("truth/frame_000" + std::to_string(i) + ".png");
  }
  const fs::path file = fs::temp_directory_path() / ("veneer-light-path-" + std::to_string(::getpid()) + ".json");
  ASSERT_TRUE(write_light_path_json(file, c));
  auto back = read_light_path_json(file);
  fs::remove(file);
  ASSERT_TRUE(back) << back.message();
  EXPECT_EQ(back->spec, c.spec);
  EXPECT_EQ(back->source, "orange");
  EXPECT_EQ(back->destination, "bull");
  EXPECT_EQ(back->size, c.size);
  EXPECT_EQ(back->files, c.files);
  EXPECT_EQ(back->truth_files, c.truth_files);
  EXPECT_EQ(back->truth_mask, c.truth_mask);
  ASSERT_EQ(back->lights.size(), 4u);
  for (size_t i = 0; i < 4; ++i) {
    EXPECT_LT(cv::norm(back->lights[i].position_m - c.lights[i].position_m), 1e-12);
    EXPECT_LT(cv::norm(back->lights[i].direction - c.lights[i].direction), 1e-12);
    EXPECT_EQ(back->lights[i].intensity, cv::Vec3f(2, 1, 0.5f));
    EXPECT_EQ(back->lights[i].colour, c.lights[i].colour);
    EXPECT_LT(cv::norm(back->lights[i].lamp.color - c.lights[i].lamp.color), 1e-6);
  }
  EXPECT_FALSE(read_light_path_json(fs::temp_directory_path() / "veneer-no-such-light-path.json"));
}

TEST(LightPath, FramesAndTruthEqualADirectRender) {
  RenderOptions o;
  o.size = {128, 85};
  o.noise_sigma = 0.005;
  auto spec = parse_light_path("spiral");
  ASSERT_TRUE(spec);
  auto seq = simulate_light_path("orange", "bull", o, *spec, 3);
  ASSERT_TRUE(seq) << seq.message();
  ASSERT_EQ(seq->frames.size(), 3u);
  ASSERT_EQ(seq->truth.size(), 3u);
  RenderOptions clean = o;
  clean.noise_sigma = 0;
  auto truth_scene = make_scene_with_material("bull", "orange", o);
  auto source = make_scene("orange", o);
  ASSERT_TRUE(truth_scene && source);
  EXPECT_EQ(cv::countNonZero(seq->truth_mask != render_truth(**truth_scene, clean).mask), 0);
  for (int i = 0; i < 3; ++i) {
    const cv::Mat truth = render(**truth_scene, {seq->lights[static_cast<size_t>(i)].lamp}, clean);
    EXPECT_EQ(cv::norm(seq->truth[static_cast<size_t>(i)], truth, cv::NORM_INF), 0.0) << "truth frame " << i;
    RenderOptions oi = o;
    oi.shot = static_cast<uint32_t>(i);
    const cv::Mat live = encode_live_frame(render(**source, {seq->lights[static_cast<size_t>(i)].lamp}, oi));
    EXPECT_EQ(cv::norm(seq->frames[static_cast<size_t>(i)], live, cv::NORM_INF), 0.0) << "frame " << i;
    EXPECT_EQ(seq->frames[static_cast<size_t>(i)].type(), CV_8UC3);
  }
  // the lamp moves: the frames differ
  EXPECT_GT(cv::norm(seq->truth[0], seq->truth[2], cv::NORM_L1), 0.0);
  // without a destination: no truth
  auto alone = simulate_light_path("orange", "", o, *spec, 1);
  ASSERT_TRUE(alone);
  EXPECT_TRUE(alone->truth.empty());
  EXPECT_TRUE(alone->truth_mask.empty());
  EXPECT_FALSE(simulate_light_path("orange", "no-such-scene", o, *spec, 1));
}

}  // namespace
}  // namespace veneer::sim
