// Registration of live frames (match/track.hpp), the simulated motion with
// truth it is measured on (sim/motion.hpp), and `veneer simulate --motion` /
// `veneer repaint --video` end to end (issue 27).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <sys/wait.h>
#include <unistd.h>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "veneer/match/matcher.hpp"
#include "veneer/repaint/live.hpp"
#include "veneer/repaint/live_session.hpp"
#include "veneer/repaint/track.hpp"
#include "veneer/sim/light_path.hpp"
#include "veneer/sim/motion.hpp"
#include "veneer/sim/simulator.hpp"

namespace veneer {
namespace {

namespace fs = std::filesystem;

double percentile(std::vector<double> v, double p) {
  std::sort(v.begin(), v.end());
  return v[static_cast<size_t>(p * (v.size() - 1) + 0.5)];
}

TEST(Motion, ParsesTheSpecAndNamesTheBadPart) {
  auto m = sim::parse_motion("shift=30:-2,rotate=5,scale=1.05,turn=3,lamp=sweep");
  ASSERT_TRUE(m) << m.message();
  EXPECT_DOUBLE_EQ(m->shift_px[0], 30);
  EXPECT_DOUBLE_EQ(m->shift_px[1], -2);
  EXPECT_DOUBLE_EQ(m->rotate_deg, 5);
  EXPECT_DOUBLE_EQ(m->scale, 1.05);
  EXPECT_DOUBLE_EQ(m->turn_deg, 3);
  EXPECT_TRUE(m->lamp_sweep);
  EXPECT_TRUE(sim::parse_motion(""));
  for (const char* bad : {"shift=30", "rotate=five", "scale=0", "turn=45", "lamp=disco", "wobble=2", "rotate"}) {
    auto e = sim::parse_motion(std::string("shift=1:1,") + bad);
    ASSERT_FALSE(e) << bad;
    EXPECT_NE(e.message().find(bad), std::string::npos) << e.message();
  }
}

TEST(Motion, TruthMovesTheCentreAsSpecified) {
  sim::MotionSpec spec;
  spec.shift_px = {30, 0};
  spec.rotate_deg = 5;
  const cv::Point2d c(100, 50);
  const auto first = sim::motion_at(spec, 0, 11, c), last = sim::motion_at(spec, 10, 11, c);
  EXPECT_LT(cv::norm(cv::Mat(first.still_to_frame), cv::Mat(cv::Matx23d(1, 0, 0, 0, 1, 0))), 1e-12);
  const cv::Vec3d centre(c.x, c.y, 1);
  const cv::Vec2d moved = last.still_to_frame * centre;
  EXPECT_NEAR(moved[0], 130, 1e-9);
  EXPECT_NEAR(moved[1], 50, 1e-9);
  EXPECT_NEAR(std::atan2(-last.still_to_frame(1, 0), last.still_to_frame(0, 0)) * 180 / CV_PI, 5, 1e-9);
}

// The source set's photos and a moving sequence of the same scene.
struct Sequence {
  io::ImageSet source;
  sim::MotionSequence seq;
};

Sequence make_sequence(const std::string& spec_text, int frames) {
  sim::RenderOptions o;
  o.size = {256, 170};
  o.scale = 2.5;
  o.ambient = 0.05;
  o.noise_sigma = 0.005;
  o.seed = 7;
  auto source = sim::simulate_set("orange", o, io::Role::source);
  EXPECT_TRUE(source) << source.message();
  auto spec = sim::parse_motion(spec_text);
  EXPECT_TRUE(spec) << spec.message();
  auto seq = sim::simulate_motion("orange", o, *spec, frames);
  EXPECT_TRUE(seq) << seq.message();
  return {std::move(*source), std::move(*seq)};
}

TEST(Track, FollowsShiftRotateScaleTurnUnderASweepingLamp) {
  Sequence s = make_sequence("shift=30:0,rotate=5,scale=1.05,turn=3,lamp=sweep", 12);
  repaint::Tracker tracker(s.source.images, s.source.truth.mask);
  ASSERT_TRUE(tracker.ready());
  std::vector<double> errors, untracked;
  for (size_t i = 0; i < s.seq.frames.size(); ++i) {
    const auto r = tracker.track(s.seq.frames[i]);
    EXPECT_FALSE(r.lost) << "frame " << i << " correlation " << r.correlation;
    errors.push_back(repaint::motion_error_px(r.still_to_frame, s.seq.truth[i].still_to_frame, s.source.truth.mask));
    untracked.push_back(
        repaint::motion_error_px(cv::Matx23d(1, 0, 0, 0, 1, 0), s.seq.truth[i].still_to_frame, s.source.truth.mask));
  }
  EXPECT_LT(percentile(errors, 0.5), 1.0);
  EXPECT_LT(percentile(errors, 0.95), 2.0);
  EXPECT_GT(percentile(untracked, 0.95), 10.0);  // the motion matters
}

// Issue 47: only the lamp moves, far to the side of the camera's axis (72-75
// degrees, beyond the stills' ring at 25), and the object stays registered.
// The frames: the source still under one lamp on a light path (simulated;
// the truth is the identity), or the same frames moved by a known affine.
struct SideLamp {
  io::ImageSet source;
  sim::LightSequence seq;
};

SideLamp side_lamp(const std::string& scene, const std::string& path, int frames) {
  sim::RenderOptions o;
  o.size = {384, 256};
  o.scale = 2.5;
  o.noise_sigma = 0.005;
  o.seed = 11;
  auto source = sim::simulate_set(scene, o, io::Role::source);
  EXPECT_TRUE(source) << source.message();
  auto spec = sim::parse_light_path(path);
  EXPECT_TRUE(spec) << spec.message();
  auto seq = sim::simulate_light_path(scene, "", o, *spec, frames);
  EXPECT_TRUE(seq) << seq.message();
  return {std::move(*source), std::move(*seq)};
}

double off_axis_deg(const sim::PathLight& l) { return std::acos(std::clamp(l.direction[2], -1.0, 1.0)) * 180 / CV_PI; }

struct PathRun {
  int lost = 0;
  std::vector<double> errors, correlations;
};

PathRun track_path(const SideLamp& s, const repaint::TrackOptions& options, const std::vector<cv::Matx23d>& truth = {}) {
  repaint::Tracker tracker(s.source.images, s.source.truth.mask, options);
  EXPECT_TRUE(tracker.ready());
  PathRun run;
  for (size_t i = 0; i < s.seq.frames.size(); ++i) {
    cv::Mat frame = s.seq.frames[i];
    cv::Matx23d t(1, 0, 0, 0, 1, 0);
    if (!truth.empty()) {
      t = truth[i];
      cv::warpAffine(s.seq.frames[i], frame, cv::Mat(t), frame.size(), cv::INTER_LINEAR, cv::BORDER_REPLICATE);
    }
    const auto r = tracker.track(frame);
    run.lost += r.lost;
    run.correlations.push_back(r.correlation);
    run.errors.push_back(repaint::motion_error_px(r.still_to_frame, t, s.source.truth.mask));
    std::printf("frame %zu: %.1f deg off the axis, correlation %.3f, lit %.2f, %s, %.3f px\n", i, off_axis_deg(s.seq.lights[i]),
                r.correlation, r.lit, r.lost ? "lost" : "tracked", run.errors.back());
  }
  return run;
}

// Counting only what the frame lights (TrackOptions::lit_fraction) is off by default: on the viewer's
// simulated live view (no backdrop lit, half the orange clipped) it weighed the outline out and the copy look's
// registration went 3 px off (app/Viewer.CaptureByButtonAndUiPullTransferAndLive); on here, at 0.03.
repaint::TrackOptions side_lamp_options() {
  repaint::TrackOptions o;
  o.lit_fraction = 0.03;
  return o;
}

TEST(Track, ALampFarToTheSideKeepsTheObjectRegistered) {
  for (const char* path : {"arc,radius=0.9,height=0.3", "circle,radius=0.97,height=0.26"}) {
    SideLamp s = side_lamp("stone", path, 8);
    for (const auto& l : s.seq.lights) EXPECT_GT(off_axis_deg(l), 70) << path;
    const PathRun now = track_path(s, side_lamp_options());
    EXPECT_EQ(now.lost, 0) << path;
    EXPECT_LT(percentile(now.errors, 0.5), 0.3) << path;
    EXPECT_LT(percentile(now.errors, 1.0), 0.6) << path;
    repaint::TrackOptions every_pixel;  // the tracker before issue 47: shadows counted
    every_pixel.lit_fraction = 0;
    EXPECT_GE(track_path(s, every_pixel).lost, 4) << path;
  }
}

TEST(Track, AMovingObjectUnderASideLampIsFollowed) {
  SideLamp s = side_lamp("stone", "arc,radius=0.9,height=0.3", 10);
  std::vector<cv::Matx23d> truth;
  const cv::Point2f centre(191.5f, 127.5f);
  for (int i = 0; i < 10; ++i) {
    cv::Mat r = cv::getRotationMatrix2D(centre, 0.5 * i, 1.0 + 0.004 * i);
    r.at<double>(0, 2) += 3.0 * i;
    r.at<double>(1, 2) -= 1.0 * i;
    truth.push_back(cv::Matx23d(r));
  }
  const PathRun run = track_path(s, side_lamp_options(), truth);
  EXPECT_EQ(run.lost, 0);
  EXPECT_LT(percentile(run.errors, 0.5), 0.3);
  EXPECT_LT(percentile(run.errors, 1.0), 0.6);
}

// Issue 47, item 6: a lamp 72 deg off the axis on every frame, the
// light-robust options (repaint::light_robust_track_options), the glossy
// sources the lit pixels alone lost (every frame of the orange and the apple
// at 1024x680) tracked on every frame near the truth (the identity).
// Measured at 384x256: orange 0.21-0.35 px, apple 0.30-1.17 px (median 0.58).
TEST(Track, ALampAt72DegreesIsTrackedWithTheLightRobustOptions) {
  struct Case {
    const char* scene;
    double median_px, max_px;
  };
  for (const Case& c : {Case{"orange", 0.5, 0.6}, Case{"apple", 0.8, 1.5}}) {
    SideLamp s = side_lamp(c.scene, "arc,radius=0.9,height=0.3", 8);
    for (const auto& l : s.seq.lights) {
      EXPECT_GT(off_axis_deg(l), 70) << c.scene;
      EXPECT_LT(off_axis_deg(l), 76) << c.scene;
    }
    const PathRun run = track_path(s, repaint::light_robust_track_options());
    EXPECT_EQ(run.lost, 0) << c.scene;
    EXPECT_LT(percentile(run.errors, 0.5), c.median_px) << c.scene;
    EXPECT_LT(percentile(run.errors, 1.0), c.max_px) << c.scene;
  }
}

// ... and the rule for lost that the lamp cannot trip still sees a cover:
// the object under the side lamp covered by a hand (a bright, smooth patch
// over most of it) is lost, and found again when uncovered;
// the object moved out of the search's reach is lost, not followed wrongly.
TEST(Track, ACoveredObjectUnderASideLampIsLostAndFoundAgain) {
  SideLamp s = side_lamp("orange", "arc,radius=0.9,height=0.3", 6);
  repaint::Tracker tracker(s.source.images, s.source.truth.mask, repaint::light_robust_track_options());
  ASSERT_TRUE(tracker.ready());
  const cv::Rect box = cv::boundingRect(s.source.truth.mask);
  cv::Mat hand(s.seq.frames[0].size(), CV_32FC3);
  cv::randu(hand, cv::Scalar::all(0), cv::Scalar::all(1));
  cv::GaussianBlur(hand, hand, cv::Size(), 6);
  cv::Mat hand8;
  hand.convertTo(hand8, CV_8UC3, 4 * 180, -2 * 180 + 150);  // skin-bright, smooth, uneven
  for (size_t i = 0; i < s.seq.frames.size(); ++i) {
    cv::Mat frame = s.seq.frames[i].clone();
    const bool covered = i == 2 || i == 3;
    if (covered) {  // 80 % of the object's box, from the left
      const cv::Rect cover(box.x - 4, box.y - 4, box.width * 8 / 10 + 4, box.height + 8);
      hand8(cover).copyTo(frame(cover));
    }
    const auto r = tracker.track(frame);
    std::printf("frame %zu%s: correlation %.3f lit %.2f %s\n", i, covered ? " (covered)" : "", r.correlation, r.lit,
                r.lost ? "lost" : "tracked");
    EXPECT_EQ(r.lost, covered) << "frame " << i << " correlation " << r.correlation << " lit " << r.lit;
    if (!r.lost) {
      EXPECT_LT(repaint::motion_error_px(r.still_to_frame, cv::Matx23d(1, 0, 0, 0, 1, 0), s.source.truth.mask), 1.0)
          << "frame " << i;
    }
  }
  // moved 60 px at once (beyond search_px): lost, and the estimate not moved along a wrong way
  cv::Mat moved;
  cv::warpAffine(s.seq.frames[5], moved, cv::Mat(cv::Matx23d(1, 0, 60, 0, 1, 0)), s.seq.frames[5].size(),
                 cv::INTER_LINEAR, cv::BORDER_REPLICATE);
  const auto r = tracker.track(moved);
  EXPECT_TRUE(r.lost) << "correlation " << r.correlation << " lit " << r.lit;
}

TEST(Track, AFrameWithoutTheObjectIsLost) {
  Sequence s = make_sequence("shift=4:0", 2);
  repaint::Tracker tracker(s.source.images, s.source.truth.mask);
  cv::Mat noise(s.seq.frames[0].size(), CV_8UC3);
  cv::randu(noise, cv::Scalar::all(0), cv::Scalar::all(255));
  EXPECT_TRUE(tracker.track(noise).lost);
  EXPECT_FALSE(tracker.track(s.seq.frames[1]).lost);  // and found again from the last good estimate
}

TEST(LiveRepainter, AMovedFrameIsReadWhereTheObjectWent) {
  // map: every destination pixel reads source pixel (x, y); frame: the source moved by (5, 3)
  const cv::Size size(40, 30);
  match::Map map;
  map.xy.create(size, CV_32FC2);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) map.xy.at<cv::Vec2f>(y, x) = {float(x), float(y)};
  map.distance = cv::Mat::zeros(size, CV_32F);
  cv::Mat still(size, CV_8UC3), frame(size, CV_8UC3, cv::Scalar::all(0));
  cv::randu(still, cv::Scalar::all(0), cv::Scalar::all(255));
  still(cv::Rect(0, 0, 35, 27)).copyTo(frame(cv::Rect(5, 3, 35, 27)));
  repaint::LiveRepainter repainter(map, size);
  const cv::Mat out = repainter.apply(frame, cv::Matx23d(1, 0, 5, 0, 1, 3));
  // (the last column and row read past the frame's edge bilinearly and keep the backdrop)
  EXPECT_EQ(cv::norm(out(cv::Rect(0, 0, 34, 26)), still(cv::Rect(0, 0, 34, 26)), cv::NORM_INF), 0);
  // the same at the nearest pixel
  repaint::LiveRepainter nearest(map, size);
  nearest.set_bilinear(false);
  const cv::Mat near = nearest.apply(frame, cv::Matx23d(1, 0, 5.2, 0, 1, 2.9));
  EXPECT_EQ(cv::norm(near(cv::Rect(0, 0, 34, 26)), still(cv::Rect(0, 0, 34, 26)), cv::NORM_INF), 0);
  // a map covering only part of the destination: the rest keeps the backdrop
  match::Map part = map;
  part.xy(cv::Rect(0, 0, size.width, 10)).setTo(cv::Scalar(-1, -1));
  part.xy(cv::Rect(30, 0, 10, size.height)).setTo(cv::Scalar(-1, -1));
  const cv::Mat backdrop(size, CV_8UC3, cv::Scalar(1, 2, 3));
  repaint::LiveRepainter partial(part, size, backdrop);
  const cv::Mat out2 = partial.apply(frame, cv::Matx23d(1, 0, 5, 0, 1, 3));
  EXPECT_EQ(cv::norm(out2(cv::Rect(0, 10, 30, 16)), still(cv::Rect(0, 10, 30, 16)), cv::NORM_INF), 0);
  EXPECT_EQ(cv::norm(out2(cv::Rect(0, 0, size.width, 10)), backdrop(cv::Rect(0, 0, size.width, 10)), cv::NORM_INF), 0);
  EXPECT_EQ(cv::norm(out2(cv::Rect(30, 0, 10, size.height)), backdrop(cv::Rect(30, 0, 10, size.height)), cv::NORM_INF), 0);
}

match::Map identity_map(cv::Size size) {
  match::Map map;
  map.xy.create(size, CV_32FC2);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) map.xy.at<cv::Vec2f>(y, x) = {float(x), float(y)};
  map.distance = cv::Mat::zeros(size, CV_32F);
  return map;
}

TEST(Motion, ViewIsACentredCropAtOneScale) {
  // 16:9 from 3:2: the full width, top and bottom cropped
  const cv::Matx23d v = sim::view_transform({300, 200}, {480, 270});
  EXPECT_DOUBLE_EQ(v(0, 0), 1.6);
  EXPECT_DOUBLE_EQ(v(1, 1), 1.6);
  const cv::Vec2d centre = v * cv::Vec3d(149.5, 99.5, 1);
  EXPECT_NEAR(centre[0], 239.5, 1e-9);
  EXPECT_NEAR(centre[1], 134.5, 1e-9);
  // 4:3 from 3:2: the full height
  EXPECT_DOUBLE_EQ(sim::view_transform({300, 200}, {200, 150})(1, 1), 0.75);
  EXPECT_FALSE(sim::parse_motion("view=320"));
  EXPECT_FALSE(sim::parse_motion("view=320x9"));
  EXPECT_EQ(sim::parse_motion("view=320x180")->view, cv::Size(320, 180));
}

// Issue 27's live-to-still geometry: a 16:9 live view (another size, its
// top and bottom cropped) of the 3:2 stills, the object moving under a
// sweeping lamp, is related once and followed within 1 px.
TEST(LiveSession, ALiveViewOfAnotherAspectAndSizeIsFollowedWithin1px) {
  for (const char* view : {"320x180", "192x108"}) {
    Sequence s = make_sequence(std::string("shift=30:0,rotate=5,lamp=sweep,view=") + view, 12);
    ASSERT_NE(s.seq.frames[0].size(), s.source.size) << view;
    repaint::LiveSession session(s.source.images, s.source.truth.mask, identity_map(s.source.size), s.source.size);
    ASSERT_TRUE(session.ready());
    std::vector<double> errors;
    for (size_t i = 0; i < s.seq.frames.size(); ++i) {
      auto f = session.process(s.seq.frames[i]);
      ASSERT_TRUE(f) << view << ": " << f.message();
      EXPECT_FALSE(f->lost) << view << " frame " << i << " quality " << f->quality;
      EXPECT_EQ(f->repainted.size(), s.source.size);
      EXPECT_FALSE(f->outline.empty());
      errors.push_back(repaint::motion_error_px(f->still_to_frame, s.seq.truth[i].still_to_frame, s.source.truth.mask));
    }
    const auto& g = *session.geometry();
    EXPECT_FALSE(g.same);
    const double truth_scale = s.seq.truth[0].still_to_frame(0, 0);
    EXPECT_NEAR(g.scale, truth_scale, 0.01 * truth_scale) << g.describe();
    EXPECT_NE(g.describe().find("16:9"), std::string::npos) << g.describe();
    EXPECT_LT(percentile(errors, 0.5), 1.0) << view;
    EXPECT_LT(percentile(errors, 0.95), 2.0) << view;
  }
}

// The old bug: a live view stretched to another aspect (x and y scaled
// separately) is refused, naming both geometries, not followed wrongly.
TEST(LiveSession, AStretchedLiveViewIsRefusedNamingBothGeometries) {
  Sequence s = make_sequence("shift=2:0", 2);
  cv::Mat stretched;
  cv::resize(s.seq.frames[0], stretched, cv::Size(320, 180), 0, 0, cv::INTER_AREA);  // 256x170 -> 16:9 anyhow
  repaint::LiveSession session(s.source.images, s.source.truth.mask, identity_map(s.source.size), s.source.size);
  auto f = session.process(stretched);
  ASSERT_FALSE(f);
  EXPECT_NE(f.message().find("320x180 (16:9)"), std::string::npos) << f.message();
  EXPECT_NE(f.message().find("256x170 (3:2)"), std::string::npos) << f.message();
  EXPECT_FALSE(session.geometry());
  // the stills' own framing is taken as it is, and a later frame of another size is refused
  auto same = session.process(s.seq.frames[0]);
  ASSERT_TRUE(same) << same.message();
  EXPECT_TRUE(session.geometry()->same);
  EXPECT_FALSE(session.process(stretched));
}

// `veneer` end to end (skipped when it is not built).
struct Scratch {
  fs::path path;
  Scratch() {
    path = fs::temp_directory_path() / ("veneer-track-" + std::to_string(::getpid()));
    fs::remove_all(path);
    fs::create_directories(path);
  }
  ~Scratch() { fs::remove_all(path); }
};

std::pair<std::string, int> run_veneer(const std::string& args) {
  const std::string cmd = std::string(VENEER_BIN_DIR) + "/veneer " + args + " 2>&1";
  std::string out;
  FILE* pipe = ::popen(cmd.c_str(), "r");
  if (!pipe) return {"", -1};
  char buf[4096];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, pipe)) > 0) out.append(buf, n);
  const int status = ::pclose(pipe);
  return {out, WIFEXITED(status) ? WEXITSTATUS(status) : -1};
}

TEST(RepaintCommand, SimulatedMotionRepaintedWithReport) {
  if (!fs::exists(fs::path(VENEER_BIN_DIR) / "veneer")) GTEST_SKIP() << "veneer is not built in " << VENEER_BIN_DIR;
  Scratch dir;
  const std::string d = dir.path.string();
  const std::string common = " --size 256x170 --ambient 0.05";
  for (const std::string& args :
       {"simulate --scene orange --scale 2.5 --role source --out " + d + "/src" + common,
        "simulate --scene bull --role destination --out " + d + "/dst" + common,
        "transfer --dst " + d + "/dst --src " + d + "/src --out " + d + "/map",
        "simulate --scene orange --scale 2.5 --motion shift=30:0,rotate=5,scale=1.05,lamp=sweep --frames 12 --out " + d +
            "/video" + common}) {
    auto [out, rc] = run_veneer(args);
    ASSERT_EQ(rc, 0) << args << "\n" << out;
  }
  EXPECT_TRUE(fs::exists(dir.path / "video/frame_0011.png"));
  EXPECT_TRUE(fs::exists(dir.path / "video/motion.json"));
  auto [out, rc] = run_veneer("repaint --src " + d + "/src --dst " + d + "/dst --map " + d + "/map --video " + d +
                              "/video --out " + d + "/out --overlay");
  ASSERT_EQ(rc, 0) << out;
  for (int i : {0, 11}) {
    char name[32];
    std::snprintf(name, sizeof name, "out/frame_%04d.png", i);
    EXPECT_TRUE(fs::exists(dir.path / name)) << name;
    std::snprintf(name, sizeof name, "out/align_%04d.png", i);
    EXPECT_TRUE(fs::exists(dir.path / name)) << name;
  }
  std::ifstream in(dir.path / "out/report.json");
  const auto report = nlohmann::json::parse(in);
  EXPECT_EQ(report.at("frames"), 12);
  EXPECT_EQ(report.at("lost"), 0);
  EXPECT_GT(report.at("ms_per_frame").at("median").get<double>(), 0);
  EXPECT_LT(report.at("align_error_px").at("median").get<double>(), 1.0);
  EXPECT_LT(report.at("align_error_px").at("p95").get<double>(), 2.0);
  EXPECT_EQ(report.at("per_frame").size(), 12u);
  EXPECT_EQ(report.at("blend_px"), 2);  // as the transfer blended (its metrics.json)
  // the shaded look by default (issue 40): each frame's light, found near the hand lamp's direction
  EXPECT_EQ(report.at("look"), "shaded");
  {
    std::ifstream motion_in(dir.path / "video/motion.json");
    const auto motion = nlohmann::json::parse(motion_in);
    for (size_t i = 0; i < 12; ++i) {
      const auto& f = report.at("per_frame").at(i);
      EXPECT_EQ(f.at("look"), "shaded") << "frame " << i;
      ASSERT_TRUE(f.contains("light")) << "frame " << i;
      EXPECT_TRUE(f.at("light").at("explained").get<bool>()) << "frame " << i;
      const auto& lamp = motion.at("frames").at(i).at("lamp_m");
      cv::Vec3d truth(lamp[0].get<double>(), lamp[1].get<double>(), lamp[2].get<double>());
      const auto& dir = f.at("light").at("direction");
      const cv::Vec3d found(dir[0].get<double>(), dir[1].get<double>(), dir[2].get<double>());
      const double deg = std::acos(std::clamp(found.dot(truth / cv::norm(truth)), -1.0, 1.0)) * 180 / CV_PI;
      EXPECT_LT(deg, 2.0) << "frame " << i;  // measured 0.1-1.0 deg (256x170, moving)
    }
  }
  {  // --look copy: the pixel copy, no light
    auto [c_out, c_rc] = run_veneer("repaint --src " + d + "/src --dst " + d + "/dst --map " + d + "/map --video " +
                                    d + "/video --out " + d + "/copy --look copy");
    ASSERT_EQ(c_rc, 0) << c_out;
    std::ifstream c_in(dir.path / "copy/report.json");
    const auto copy = nlohmann::json::parse(c_in);
    EXPECT_EQ(copy.at("look"), "copy");
    EXPECT_EQ(copy.at("per_frame").at(0).at("look"), "copy");
    EXPECT_FALSE(copy.at("per_frame").at(0).contains("light"));
    auto [bad_out, bad_rc] = run_veneer("repaint --src " + d + "/src --dst " + d + "/dst --map " + d + "/map --video " +
                                        d + "/video --out " + d + "/bad --look glossy");
    EXPECT_NE(bad_rc, 0);
    EXPECT_NE(bad_out.find("glossy"), std::string::npos) << bad_out;
  }

  // issue 27's own check: 30 px and 5 deg over 60 frames under a sweeping lamp,
  // with and without tracking
  {
    auto [sim_out, sim_rc] = run_veneer(
        "simulate --scene orange --scale 2.5 --motion shift=30:0,rotate=5,lamp=sweep --frames 60 --out " + d + "/v60" +
        common);
    ASSERT_EQ(sim_rc, 0) << sim_out;
    nlohmann::json reports[2];
    for (int track = 0; track < 2; ++track) {
      const std::string o = d + (track ? "/r60" : "/r60-untracked");
      auto [r_out, r_rc] = run_veneer("repaint --src " + d + "/src --dst " + d + "/dst --map " + d + "/map --video " +
                                      d + "/v60 --out " + o + (track ? "" : " --no-track"));
      ASSERT_EQ(r_rc, 0) << r_out;
      std::ifstream r_in(o + "/report.json");
      reports[track] = nlohmann::json::parse(r_in);
    }
    EXPECT_LE(reports[1].at("align_error_px").at("median").get<double>(), 1.0);
    EXPECT_LE(reports[1].at("align_error_px").at("p95").get<double>(), 2.0);
    EXPECT_EQ(reports[1].at("lost"), 0);
    EXPECT_GT(reports[0].at("align_error_px").at("median").get<double>(), 10.0);  // the motion matters
  }

  // a live view framed otherwise than the stills: refused, both geometries named
  fs::create_directories(dir.path / "wide");
  ASSERT_TRUE(cv::imwrite((dir.path / "wide/frame_0000.png").string(), cv::Mat(180, 320, CV_8UC3, cv::Scalar::all(60))));
  auto [wide, wide_rc] = run_veneer("repaint --src " + d + "/src --dst " + d + "/dst --map " + d + "/map --video " + d +
                                    "/wide --out " + d + "/out3");
  EXPECT_EQ(wide_rc, 1);
  EXPECT_NE(wide.find("320x180"), std::string::npos) << wide;
  EXPECT_NE(wide.find("256x170"), std::string::npos) << wide;
  EXPECT_FALSE(fs::exists(dir.path / "out3"));  // nothing half-written
  // ... and a 16:9 live view of the object at another size: related once, then followed
  {
    auto [sim_out, sim_rc] = run_veneer(
        "simulate --scene orange --scale 2.5 --motion shift=20:0,rotate=3,lamp=sweep,view=320x180 --frames 8 --out " +
        d + "/v169" + common);
    ASSERT_EQ(sim_rc, 0) << sim_out;
    auto [r_out, r_rc] = run_veneer("repaint --src " + d + "/src --dst " + d + "/dst --map " + d + "/map --video " + d +
                                    "/v169 --out " + d + "/r169");
    ASSERT_EQ(r_rc, 0) << r_out;
    EXPECT_NE(r_out.find("320x180 (16:9) shows the stills' 256x170 (3:2) at x1.2"), std::string::npos) << r_out;
    std::ifstream r_in(d + "/r169/report.json");
    const auto r = nlohmann::json::parse(r_in);
    EXPECT_EQ(r.at("lost"), 0);
    EXPECT_LE(r.at("align_error_px").at("median").get<double>(), 1.0);
    EXPECT_NEAR(r.at("live_view").at("scale").get<double>(), 1.25, 0.0125);
  }

  auto [bad, bad_rc] = run_veneer("simulate --scene orange --motion shift=30:0,rotate=lots --frames 3 --out " + d + "/x");
  EXPECT_EQ(bad_rc, 2);
  EXPECT_NE(bad.find("'rotate=lots'"), std::string::npos) << bad;
  auto [missing, missing_rc] = run_veneer("repaint --src " + d + "/src --dst " + d + "/dst --map " + d + "/map --video " +
                                          d + "/no-such-video.mp4 --out " + d + "/out2");
  EXPECT_EQ(missing_rc, 2);
  EXPECT_NE(missing.find("no-such-video.mp4: no such file or folder"), std::string::npos) << missing;
}

}  // namespace
}  // namespace veneer
