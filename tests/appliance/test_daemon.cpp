// The real veneerd binary on loopback with the simulated rig (Hue bridge
// emulator + libcurl lamps + ray-cast camera), driven by the real `veneer`
// CLI and the rig client library.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <functional>
#include <fstream>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <mutex>
#include <sstream>

#include "rig_test_util.hpp"
#include "veneer/io/image_io.hpp"
#include "veneer/io/imageset.hpp"
#include "veneer/pipeline/transfer.hpp"
#include "veneer/ps/photometric_stereo.hpp"
#include "veneer/ps/segmentation.hpp"
#include "veneer/repaint/live.hpp"
#include "veneer/rig/client.hpp"
#include "veneer/sim/simulator.hpp"

namespace fs = std::filesystem;
using rigtest::DaemonProcess;
using rigtest::run;
namespace pb = veneer::v1;

namespace {

const std::vector<std::string> kSmall = {"--size", "256x170", "--noise", "0"};

std::string rig_args(const DaemonProcess& d, const fs::path& store) {
  return rigtest::cli_rig_args(d.address(), store);
}

std::unique_ptr<veneer::rig::Client> connect(const DaemonProcess& d, const fs::path& store) {
  auto token = veneer::rig::read_token_file(store / "token");
  if (!token) return nullptr;
  auto c = veneer::rig::Client::connect({"127.0.0.1", d.port()}, *token);
  return c ? std::move(*c) : nullptr;
}

// Angle in degrees between two unit normals.
double angle_deg(const cv::Vec3f& a, const cv::Vec3f& b) {
  double c = std::clamp(static_cast<double>(a.dot(b)) / (cv::norm(a) * cv::norm(b) + 1e-12), -1.0, 1.0);
  return std::acos(c) * 180.0 / CV_PI;
}

}  // namespace

TEST(Daemon, TwoPressesStoreTwoSetsThatPullWithTheRenderedPixelsAndTrueNormals) {
  fs::path dir = rigtest::temp_dir("flow");
  fs::path store = dir / "store";
  auto d = DaemonProcess::start(store, kSmall);
  ASSERT_TRUE(d && d->port() != 0) << (d ? d->log() : "no process");
  EXPECT_EQ(fs::status(store / "token").permissions() & (fs::perms::group_all | fs::perms::others_all), fs::perms::none);

  // A watcher records every event.
  auto watcher = connect(*d, store);
  ASSERT_TRUE(watcher);
  std::mutex m;
  std::vector<veneer::rig::Event> events;
  watcher->on_event = [&](const veneer::rig::Event& e) {
    std::lock_guard lock(m);
    events.push_back(e);
  };

  std::string rig = rigtest::veneer_cli() + rig_args(*d, store);
  auto first = run(rig + " press --wait");
  ASSERT_EQ(first.code, 0) << first.out << d->log();
  auto second = run(rig + " press --wait");
  ASSERT_EQ(second.code, 0) << second.out << d->log();

  auto list = run(rig + " list");
  ASSERT_EQ(list.code, 0) << list.out;
  std::vector<std::string> ids;
  std::istringstream lines(list.out);
  for (std::string line; std::getline(lines, line);) {
    if (!line.empty()) ids.push_back(line.substr(0, line.find(' ')));
  }
  ASSERT_EQ(ids.size(), 2u) << list.out;
  EXPECT_NE(ids[0].find("destination-bull"), std::string::npos);
  EXPECT_NE(ids[1].find("source-stone"), std::string::npos);

  // Events, in order, for each set: press, started, 8 shots, stored.
  {
    std::lock_guard lock(m);
    using K = veneer::rig::Event::Kind;
    std::vector<std::string> seen;
    for (const auto& e : events) {
      if (e.kind == K::lamp_state) continue;
      seen.push_back(std::string(veneer::rig::event_name(e.kind)) + (e.kind == K::shot_taken ? std::to_string(e.k) : ""));
    }
    std::vector<std::string> want;
    for (int set = 0; set < 2; ++set) {
      want.push_back("button_pressed");
      want.push_back("capture_started");
      for (int k = 1; k <= 8; ++k) want.push_back("shot_taken" + std::to_string(k));
      want.push_back("set_stored");
    }
    EXPECT_EQ(seen, want);
    for (size_t i = 1; i < events.size(); ++i) EXPECT_EQ(events[i].seq, events[i - 1].seq + 1);
  }

  // Pull both with the CLI and compare with an independent render.
  const std::vector<std::string> scenes = {"bull", "stone"};
  for (int s = 0; s < 2; ++s) {
    fs::path out = dir / ("pulled-" + std::to_string(s));
    auto pull = run(rig + " pull " + ids[s] + " --truth --out " + out.string());
    ASSERT_EQ(pull.code, 0) << pull.out;
    // The camera's RAW files came with the photos; the photos are compared here.
    EXPECT_TRUE(fs::exists(out / "light_06.dng")) << "no RAW file pulled";
    EXPECT_TRUE(fs::exists(out / "ambient.dng")) << "no RAW file of the ambient frame pulled";
    veneer::io::ReadOptions developed;
    developed.photos = veneer::io::PhotoSource::developed;
    auto set = veneer::io::read_set(out, developed);
    ASSERT_TRUE(set) << set.message();
    EXPECT_EQ(set->role, s == 0 ? veneer::io::Role::destination : veneer::io::Role::source);
    ASSERT_EQ(set->images.size(), 7u);
    ASSERT_TRUE(set->truth.present());
    ASSERT_FALSE(set->ambient.empty());
    // Without --truth (a user's pull) the simulator's truth/ stays on the rig.
    const fs::path users = dir / ("users-" + std::to_string(s));
    auto plain = run(rig + " pull " + ids[s] + " --out " + users.string());
    ASSERT_EQ(plain.code, 0) << plain.out;
    EXPECT_TRUE(fs::exists(users / "set.json"));
    EXPECT_FALSE(fs::exists(users / "truth")) << "truth/ is pulled only with --truth";

    veneer::sim::RenderOptions o;
    o.size = {256, 170};
    o.noise_sigma = 0;
    o.camera_optics();  // as the camera twin renders its stills
    auto scene = veneer::sim::make_scene(scenes[s], o);
    ASSERT_TRUE(scene) << scene.message();
    auto ring = veneer::sim::thesis_rig();
    for (int i = 0; i < 7; ++i) {
      cv::Mat expect = veneer::sim::render(**scene, {ring[i]}, o);
      // The photos are the camera's developed JPEGs (8-bit sRGB, quality 95),
      // read back linear: the render within JPEG's loss; the exact pixels
      // are in the RAW files (below, and CameraFiles tests).
      const double rel = cv::norm(set->images[i], expect, cv::NORM_L1) / cv::norm(expect, cv::NORM_L1);
      EXPECT_LT(rel, 0.03) << scenes[s] << " lamp " << i << ": the photo differs from the render by " << rel;
    }
  }

  // Photometric stereo (the ps module behind `veneer normals`) on the pulled
  // destination, from its photos and read as the viewer reads it by default,
  // from the camera's RAW files, each within 6 degrees: the 256x170 mosaic's
  // demosaicing blurs the small bull's edges (median 4.0 degrees over the
  // bull alone), and so do the camera's JPEGs (8-bit, chroma at half
  // resolution: median 4.8; the 16-bit PNGs the rig stored before gave 0.4).
  for (bool raw : {false, true}) {
    veneer::io::ReadOptions read;
    read.photos = raw ? veneer::io::PhotoSource::automatic : veneer::io::PhotoSource::developed;
    auto pulled = veneer::io::read_set(dir / "pulled-0", read);
    ASSERT_TRUE(pulled) << pulled.message();
    EXPECT_EQ(pulled->photos_from, raw ? "raw" : "jpeg");
    auto ps = veneer::ps::photometric_stereo(*pulled, pulled->truth.mask);
    ASSERT_TRUE(ps) << ps.message();
    const cv::Mat* n = &ps->normals;
    const cv::Mat* t = &pulled->truth.normals;
    std::vector<double> err;
    for (int y = 0; y < n->rows; ++y) {
      for (int x = 0; x < n->cols; ++x) {
        cv::Vec3f a = n->at<cv::Vec3f>(y, x), b = t->at<cv::Vec3f>(y, x);
        if (cv::norm(a) > 0.5 && cv::norm(b) > 0.5) err.push_back(angle_deg(a, b));
      }
    }
    ASSERT_GT(err.size(), 500u);
    std::nth_element(err.begin(), err.begin() + err.size() / 2, err.end());
    EXPECT_LT(err[err.size() / 2], raw ? 5.0 : 6.0) << "median angular error of the recovered normals, "
                                                    << (raw ? "RAW" : "photos");
  }
  fs::remove_all(dir);
}

// `veneer rig live --map`: the frames repainted as the transfer's stills were
// (its metrics.json's options; blended, guided by the sets' normals), or
// unblended when asked; a guide without the destination is refused.
// Issue 40: the rig's bull (256x170, the camera twin's optics, DNG + JPEG)
// as `veneer normals` and `veneer transfer` read it. The optics blur the
// edges of the legs' cast shadows: samples in a partial shadow are neither
// dropped as shadowed nor lit, and turned the fit (8.33 deg mean, 43.7 at
// the 95th percentile; 6.98 / 35.0 with ps::PsOptions::penumbra_fraction);
// the plinth's top was then too broken up for the base removal, which kept
// it (2772 pixels mapped, the plinth orange). Now the plinth is left out.
// Two presses of the rig's button (destination, then source), both sets
// pulled through the CLI into `dst` and `src`.
void press_twice_and_pull(const DaemonProcess& d, const fs::path& store, const fs::path& dst, const fs::path& src) {
  const std::string rig = rigtest::veneer_cli() + rig_args(d, store);
  for (int i = 0; i < 2; ++i) ASSERT_EQ(run(rig + " press --wait").code, 0) << d.log();
  auto list = run(rig + " list");
  std::vector<std::string> ids;
  std::istringstream lines(list.out);
  for (std::string line; std::getline(lines, line);)
    if (!line.empty()) ids.push_back(line.substr(0, line.find(' ')));
  ASSERT_EQ(ids.size(), 2u) << list.out;
  ASSERT_EQ(run(rig + " pull " + ids[0] + " --truth --out " + dst.string()).code, 0);
  ASSERT_EQ(run(rig + " pull " + ids[1] + " --truth --out " + src.string()).code, 0);
}

TEST(Daemon, TheRigsBullHasItsNormalsAndItsPlinthIsLeftOut) {
  fs::path dir = rigtest::temp_dir("plinth");
  fs::path store = dir / "store";
  auto d = DaemonProcess::start(store, {"--scenes", "bull,orange", "--size", "256x170"});
  ASSERT_TRUE(d && d->port() != 0) << (d ? d->log() : "no process");
  const fs::path dst = dir / "dst", src = dir / "src", tr = dir / "transfer";
  ASSERT_NO_FATAL_FAILURE(press_twice_and_pull(*d, store, dst, src));

  // Photometric stereo as `veneer normals` runs it (RAW, segmented, robust, near lamps).
  auto set = veneer::io::read_set(dst);
  ASSERT_TRUE(set) << set.message();
  ASSERT_EQ(set->photos_from, "raw");
  ASSERT_TRUE(set->truth.present());
  auto seg = veneer::ps::segment(*set);
  ASSERT_TRUE(seg) << seg.message();
  auto ps = veneer::ps::photometric_stereo(*set, seg->mask);
  ASSERT_TRUE(ps) << ps.message();
  const cv::Mat bull = set->truth.mask;
  auto err = veneer::ps::angular_error(ps->normals, set->truth.normals, bull & ps->mask);
  std::printf("rig's bull: normals %.2f deg mean, %.2f p95 off the truth (%d pixels)\n", err.mean_deg, err.p95_deg,
              err.pixels);
  EXPECT_GT(err.pixels, 1800);
  // measured 7.83 with our MHC, io::RawOptions' one default since issue 42 (6.98 with LibRaw's DCB, the io
  // default before; 8.33 before the penumbra fix): at 256x170 MHC's 5x5 filters cost the small bull 0.85 deg
  EXPECT_LT(err.mean_deg, 8.2);
  EXPECT_LT(err.p95_deg, 38.0);  // measured 34.95 (43.68 before)

  // The transfer leaves the plinth out: what the segmentation sees beyond the
  // bull (2 px around it: the lens mixes its outline) is not mapped.
  auto t = run(rigtest::veneer_cli() + " transfer --dst " + dst.string() + " --src " + src.string() + " --out " +
               tr.string());
  ASSERT_EQ(t.code, 0) << t.out;
  auto map = veneer::io::read_pfm(tr / "map.pfm", true);
  ASSERT_TRUE(map) << map.message();
  ASSERT_EQ(map->size(), bull.size());
  cv::Mat near_bull;
  cv::dilate(bull, near_bull, cv::Mat::ones(5, 5, CV_8U));
  const cv::Mat plinth = seg->mask & ~near_bull;
  std::vector<cv::Mat> xyd;
  cv::split(*map, xyd);
  const cv::Mat mapped = xyd[0] >= 0;
  const int plinth_px = cv::countNonZero(plinth), plinth_mapped = cv::countNonZero(mapped & plinth);
  const int mapped_px = cv::countNonZero(mapped), bull_px = cv::countNonZero(bull);
  std::printf("rig's bull: %d pixels mapped (the bull %d); the plinth %d pixels, %d of them mapped\n", mapped_px,
              bull_px, plinth_px, plinth_mapped);
  EXPECT_GT(plinth_px, 500) << "the bull stands on a plinth the segmentation sees";
  EXPECT_LT(plinth_mapped, plinth_px / 10);  // measured 39 of 629 (all of it before)
  EXPECT_LT(mapped_px, bull_px * 6 / 5);     // measured 2069 of 1853 (2772 before)
  EXPECT_GT(mapped_px, bull_px * 9 / 10);
}

TEST(Daemon, LiveFramesThroughAMapAreBlendedAsTheStills) {
  fs::path dir = rigtest::temp_dir("live-map");
  fs::path store = dir / "store";
  auto d = DaemonProcess::start(store, kSmall);
  ASSERT_TRUE(d && d->port() != 0) << (d ? d->log() : "no process");
  const fs::path dst = dir / "dst", src = dir / "src", tr = dir / "transfer";
  ASSERT_NO_FATAL_FAILURE(press_twice_and_pull(*d, store, dst, src));
  const std::string rig = rigtest::veneer_cli() + rig_args(*d, store);
  auto t = run(rigtest::veneer_cli() + " transfer --dst " + dst.string() + " --src " + src.string() +
               " --method coherent --blend 3 --out " + tr.string());
  ASSERT_EQ(t.code, 0) << t.out;

  // tracked (the default): each frame registered to the source's stills, its state printed, the outline drawn
  auto tracked = run(rig + " live --frames 2 --fps 5 --map " + tr.string() + " --src " + src.string() + " --dst " +
                     dst.string() + " --out " + (dir / "tracked").string());
  ASSERT_EQ(tracked.code, 0) << tracked.out;
  EXPECT_NE(tracked.out.find("frame 1: tracked, ECC 0.9"), std::string::npos) << tracked.out;
  EXPECT_NE(tracked.out.find("(2 tracked, 0 lost;"), std::string::npos) << tracked.out;
  EXPECT_TRUE(fs::exists(dir / "tracked" / "align_0001.png"));
  EXPECT_TRUE(fs::exists(dir / "tracked" / "repainted_0001.png"));

  // untracked: the fixed lookup, compared pixel for pixel below
  const std::string live =
      rig + " live --no-track --frames 2 --fps 5 --map " + tr.string() + " --src " + src.string();
  auto blended = run(live + " --dst " + dst.string() + " --out " + (dir / "blended").string());
  ASSERT_EQ(blended.code, 0) << blended.out;
  EXPECT_NE(blended.out.find("3 px, guided"), std::string::npos) << blended.out;
  auto plain = run(live + " --dst " + dst.string() + " --blend 0 --out " + (dir / "plain").string());
  ASSERT_EQ(plain.code, 0) << plain.out;
  auto refused = run(live + " --blend-guide 0.1 --out " + (dir / "refused").string());
  EXPECT_EQ(refused.code, 2) << refused.out;
  EXPECT_NE(refused.out.find("--blend-guide needs --dst"), std::string::npos) << refused.out;

  // the same frame repainted here through the core: with the stills' plan, and without
  auto dset = veneer::io::read_set(dst), sset = veneer::io::read_set(src);
  ASSERT_TRUE(dset && sset);
  auto options = veneer::pipeline::read_transfer_options(tr / "metrics.json");
  ASSERT_TRUE(options) << options.message();
  EXPECT_EQ(options->blend, 3);
  auto pair = veneer::pipeline::prepare_pair(*dset, *sset, *options);
  ASSERT_TRUE(pair) << pair.message();
  auto map = veneer::match::read_map(tr / "map.pfm");
  ASSERT_TRUE(map) << map.message();
  auto plan = veneer::pipeline::blend_plan_for(*pair, *options, *map);
  ASSERT_TRUE(plan && *plan) << (plan ? "no plan" : plan.message());
  // the live view's backdrop: the destination lit by the lamp that lights each pixel second most (issue 47)
  const cv::Mat backdrop = veneer::io::tonemap_picture(veneer::repaint::lit_photo(dset->images));
  for (const char* which : {"blended", "plain"}) {
    const cv::Mat frame = cv::imread((dir / which / "frame_0000.jpg").string(), cv::IMREAD_COLOR);
    const cv::Mat got = cv::imread((dir / which / "repainted_0000.png").string(), cv::IMREAD_COLOR);
    ASSERT_FALSE(frame.empty() || got.empty()) << which;
    veneer::repaint::LiveRepainter with(*map, pair->source.size, backdrop, *plan), without(*map, pair->source.size, backdrop);
    const cv::Mat want_blended = with.apply(frame), want_plain = without.apply(frame);
    const bool is_blended = std::string(which) == "blended";
    EXPECT_EQ(cv::norm(got, is_blended ? want_blended : want_plain, cv::NORM_INF), 0.0) << which;
    EXPECT_GT(cv::norm(got, is_blended ? want_plain : want_blended, cv::NORM_INF), 0.0) << which;
  }

  // Without --dst: no normals to guide, so the plain blend over the source's
  // mask, on black
  auto no_dst = run(live + " --out " + (dir / "no-dst").string());
  ASSERT_EQ(no_dst.code, 0) << no_dst.out;
  EXPECT_NE(no_dst.out.find("3 px, plain"), std::string::npos) << no_dst.out;
  {
    auto plain_plan = veneer::match::fast::blend_plan(*map, {}, pair->src.view.mask, 3);
    ASSERT_TRUE(plain_plan) << plain_plan.message();
    const cv::Mat frame = cv::imread((dir / "no-dst" / "frame_0000.jpg").string(), cv::IMREAD_COLOR);
    const cv::Mat got = cv::imread((dir / "no-dst" / "repainted_0000.png").string(), cv::IMREAD_COLOR);
    ASSERT_FALSE(frame.empty() || got.empty());
    veneer::repaint::LiveRepainter on_black(*map, pair->source.size, {},
                                          std::make_shared<const veneer::match::fast::BlendPlan>(*plain_plan));
    EXPECT_EQ(cv::norm(got, on_black.apply(frame), cv::NORM_INF), 0.0);
  }

  // A bare map.pfm of a half-scale transfer (no metrics.json beside it): its
  // scale comes from its width against the destination's, its blend is the default.
  const fs::path half = dir / "half", bare = dir / "bare";
  auto th = run(rigtest::veneer_cli() + " transfer --dst " + dst.string() + " --src " + src.string() +
                " --method coherent --scale 0.5 --out " + half.string());
  ASSERT_EQ(th.code, 0) << th.out;
  fs::create_directories(bare);
  fs::copy_file(half / "map.pfm", bare / "map.pfm");
  auto scaled = run(rig + " live --no-track --frames 1 --fps 5 --map " + (bare / "map.pfm").string() + " --src " + src.string() +
                    " --dst " + dst.string() + " --out " + (dir / "scaled").string());
  ASSERT_EQ(scaled.code, 0) << scaled.out;
  veneer::pipeline::TransferOptions defaults;
  defaults.scale = 0.5;
  auto half_pair = veneer::pipeline::prepare_pair(*dset, *sset, defaults);
  auto half_map = veneer::match::read_map(bare / "map.pfm");
  ASSERT_TRUE(half_pair && half_map);
  auto half_plan = veneer::pipeline::blend_plan_for(*half_pair, defaults, *half_map);
  ASSERT_TRUE(half_plan && *half_plan) << (half_plan ? "no plan" : half_plan.message());
  const cv::Mat frame = cv::imread((dir / "scaled" / "frame_0000.jpg").string(), cv::IMREAD_COLOR);
  const cv::Mat got = cv::imread((dir / "scaled" / "repainted_0000.png").string(), cv::IMREAD_COLOR);
  ASSERT_FALSE(frame.empty() || got.empty());
  EXPECT_EQ(got.size(), half_map->xy.size());
  veneer::repaint::LiveRepainter at_half(*half_map, half_pair->source.size, backdrop, *half_plan);
  EXPECT_EQ(cv::norm(got, at_half.apply(frame), cv::NORM_INF), 0.0);
  fs::remove_all(dir);
}

TEST(Daemon, BadInputGetsAnErrorOrAClosedConnectionAndTheDaemonServesOthers) {
  fs::path dir = rigtest::temp_dir("bad");
  fs::path store = dir / "store";
  auto d = DaemonProcess::start(store, kSmall);
  ASSERT_TRUE(d && d->port() != 0) << (d ? d->log() : "");
  auto token = veneer::rig::read_token_file(store / "token");
  ASSERT_TRUE(token);
  // A well-behaved client stays connected through all of it.
  auto good = connect(*d, store);
  ASSERT_TRUE(good);

  {  // garbage bytes
    rigtest::RawConnection c(d->port());
    ASSERT_TRUE(c.ok());
    c.send_bytes(std::string("\x05\x00\xff\xff\xff\xffGET / HTTP/1.1\r\n\r\n", 23));
    EXPECT_TRUE(c.closed_by_peer());
  }
  {  // a 4 GiB length prefix: refused without reading (or allocating) it
    rigtest::RawConnection c(d->port());
    c.send_bytes(std::string("\x80\x80\x80\x80\x10", 5));
    auto r = c.next_response(0);
    ASSERT_TRUE(r);
    EXPECT_NE(r->error().find("exceeds the limit"), std::string::npos) << r->error();
    EXPECT_TRUE(c.closed_by_peer());
  }
  for (std::string bad_token : {std::string("not-the-token"), std::string()}) {  // wrong or missing token
    rigtest::RawConnection c(d->port());
    pb::ClientMessage m;
    m.set_id(1);
    m.mutable_hello()->set_protocol_version(veneer::wire::kProtocolVersion);
    m.mutable_hello()->set_token(bad_token);
    c.send(m);
    auto r = c.next_response(1);
    ASSERT_TRUE(r);
    EXPECT_FALSE(r->ok());
    EXPECT_NE(r->error().find(bad_token.empty() ? "no access token" : "wrong access token"), std::string::npos);
    EXPECT_TRUE(c.closed_by_peer());
  }
  {  // a request before hello
    rigtest::RawConnection c(d->port());
    pb::ClientMessage m;
    m.set_id(4);
    m.mutable_list_sets();
    c.send(m);
    auto r = c.next_response(4);
    ASSERT_TRUE(r);
    EXPECT_FALSE(r->ok());
    EXPECT_NE(r->error().find("first request must be a hello"), std::string::npos);
    EXPECT_TRUE(c.closed_by_peer());
  }
  {  // an unknown message after hello: an error, the connection stays usable
    rigtest::RawConnection c(d->port());
    ASSERT_TRUE(c.hello(*token));
    c.send_bytes(std::string("\x07\x08\x09\x9a\x06\x02hi", 8));
    auto r = c.next_response(9);
    ASSERT_TRUE(r);
    EXPECT_FALSE(r->ok());
    EXPECT_NE(r->error().find("unknown"), std::string::npos);
    pb::ClientMessage m;
    m.set_id(10);
    m.mutable_status();
    c.send(m);
    auto s = c.next_response(10);
    ASSERT_TRUE(s);
    EXPECT_TRUE(s->ok());
  }
  {  // a second controller is refused; when the first leaves, it may control
    auto first = connect(*d, store);
    auto second = connect(*d, store);
    ASSERT_TRUE(first && second);
    ASSERT_TRUE(first->set_lamps({true, false, true}));
    auto refused = second->set_lamps({false, true});
    ASSERT_FALSE(refused);
    EXPECT_NE(refused.message().find("controls the rig"), std::string::npos) << refused.message();
    EXPECT_TRUE(second->status());  // watching is fine
    first->close();
    veneer::Status later = veneer::make_error("never tried");
    for (int i = 0; i < 50 && !later; ++i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
      later = second->set_lamps({false, false});
    }
    EXPECT_TRUE(later) << later.message();
  }
  EXPECT_TRUE(d->alive());
  auto status = good->status();
  ASSERT_TRUE(status) << status.message();
  EXPECT_EQ(status->lamp_count, 7);
  fs::remove_all(dir);
}

TEST(Daemon, KillDuringACaptureLeavesNoPartialSetAndEarlierSetsIntact) {
  fs::path dir = rigtest::temp_dir("kill");
  fs::path store = dir / "store";
  std::string first_id;
  {
    auto d = DaemonProcess::start(store, kSmall);
    ASSERT_TRUE(d && d->port() != 0);
    auto first = run(rigtest::veneer_cli() + rig_args(*d, store) + " press --wait");
    ASSERT_EQ(first.code, 0) << first.out;
    first_id = first.out.substr(first.out.rfind('\n', first.out.size() - 2) + 1);
    first_id.erase(first_id.find_last_not_of("\n") + 1);
    auto c = connect(*d, store);
    ASSERT_TRUE(c);
    ASSERT_TRUE(c->press_button());
    auto shot = c->wait_event([](const veneer::rig::Event& e) { return e.kind == veneer::rig::Event::Kind::shot_taken && e.k == 4; }, 30);
    ASSERT_TRUE(shot) << shot.message();
    d->stop(SIGKILL);
  }
  // What a crash while writing leaves: a temporary folder beside the sets.
  fs::create_directories(store / ".20261122-000000-source-stone.tmp-999999-0" / "truth");
  auto d = DaemonProcess::start(store, kSmall);
  ASSERT_TRUE(d && d->port() != 0) << (d ? d->log() : "");
  auto list = run(rigtest::veneer_cli() + rig_args(*d, store) + " list");
  ASSERT_EQ(list.code, 0) << list.out;
  EXPECT_EQ(std::count(list.out.begin(), list.out.end(), '\n'), 1) << list.out;
  EXPECT_EQ(list.out.substr(0, list.out.find(' ')), first_id);
  for (const auto& entry : fs::directory_iterator(store)) {
    std::string name = entry.path().filename().string();
    EXPECT_TRUE(name == "token" || name == ".lock" || name == first_id) << "left behind: " << name;
  }
  auto set = veneer::io::read_set(store / first_id);
  EXPECT_TRUE(set) << set.message();
  fs::remove_all(dir);
}

TEST(Daemon, DiskFullFailsTheCaptureClearlyAndStoresNothing) {
  fs::path dir = rigtest::temp_dir("full");
  fs::path store = dir / "store";
  fs::create_directories(store);
  { std::ofstream(store / "token") << "t0ken\n"; }
  fs::permissions(store / "token", fs::perms::owner_read | fs::perms::owner_write);
  // Files beyond 64 KiB fail with EFBIG, as on a full disk.
  auto extra = kSmall;
  extra.insert(extra.end(), {"--max-file-bytes", "65536"});
  auto d = DaemonProcess::start(store, extra);
  ASSERT_TRUE(d && d->port() != 0) << (d ? d->log() : "");
  auto press = run(rigtest::veneer_cli() + rig_args(*d, store) + " press --wait");
  EXPECT_EQ(press.code, 1) << press.out;
  EXPECT_NE(press.out.find("no set stored"), std::string::npos) << press.out;
  EXPECT_NE(press.out.find("File too large"), std::string::npos) << press.out;
  auto list = run(rigtest::veneer_cli() + rig_args(*d, store) + " list");
  EXPECT_EQ(list.code, 0);
  EXPECT_EQ(list.out, "");
  for (const auto& entry : fs::directory_iterator(store)) {
    std::string name = entry.path().filename().string();
    EXPECT_TRUE(name == "token" || name == ".lock") << "left behind: " << name;
  }
  EXPECT_TRUE(d->alive());
  fs::remove_all(dir);
}

namespace {
std::string file_bytes(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

pb::ClientMessage hello_message(const std::string& token, const std::string& name = "test", uint64_t id = 1) {
  pb::ClientMessage m;
  m.set_id(id);
  m.mutable_hello()->set_protocol_version(veneer::wire::kProtocolVersion);
  m.mutable_hello()->set_token(token);
  m.mutable_hello()->set_client_name(name);
  return m;
}

size_t count_lines(const std::string& s) { return static_cast<size_t>(std::count(s.begin(), s.end(), '\n')); }
}  // namespace

// proto/README.md: the token is the token file's content without surrounding
// whitespace; a client may send the file's bytes as they are.
TEST(Daemon, TheTokenFileSentWithItsTrailingNewlineIsAccepted) {
  fs::path dir = rigtest::temp_dir("token");
  fs::path store = dir / "store";
  auto d = DaemonProcess::start(store, kSmall);
  ASSERT_TRUE(d && d->port() != 0) << (d ? d->log() : "");
  const std::string bytes = file_bytes(store / "token");
  ASSERT_FALSE(bytes.empty());
  ASSERT_EQ(bytes.back(), '\n');
  std::string spaced("  "), tabbed("\t");
  spaced.append(bytes);
  tabbed.append(bytes).append("\r\n");
  for (const std::string& sent : {bytes, spaced, tabbed}) {
    rigtest::RawConnection c(d->port());
    c.send(hello_message(sent));
    auto r = c.next_response(1);
    ASSERT_TRUE(r);
    EXPECT_TRUE(r->ok()) << r->error();
    EXPECT_TRUE(r->has_status());
  }
  {  // whitespace inside the token still makes it wrong
    rigtest::RawConnection c(d->port());
    std::string inside = bytes;
    inside.insert(10, " ");
    c.send(hello_message(inside));
    auto r = c.next_response(1);
    ASSERT_TRUE(r);
    EXPECT_FALSE(r->ok());
    EXPECT_NE(r->error().find("wrong access token"), std::string::npos) << r->error();
  }
  fs::remove_all(dir);
}

TEST(Daemon, ATooLongClientNameIsRefusedSayingSoWithTheLimit) {
  fs::path dir = rigtest::temp_dir("name");
  fs::path store = dir / "store";
  auto d = DaemonProcess::start(store, kSmall);
  ASSERT_TRUE(d && d->port() != 0) << (d ? d->log() : "");
  auto token = veneer::rig::read_token_file(store / "token");
  ASSERT_TRUE(token);
  rigtest::RawConnection c(d->port());
  c.send(hello_message(*token, std::string(129, 'n')));
  auto r = c.next_response(1);
  ASSERT_TRUE(r);
  EXPECT_FALSE(r->ok());
  EXPECT_NE(r->error().find("hello.client_name: 129 characters is longer than the limit of 128"), std::string::npos)
      << r->error();
  EXPECT_TRUE(c.closed_by_peer());
  rigtest::RawConnection ok(d->port());
  ok.send(hello_message(*token, std::string(128, 'n')));
  auto r2 = ok.next_response(1);
  ASSERT_TRUE(r2);
  EXPECT_TRUE(r2->ok()) << r2->error();
  fs::remove_all(dir);
}

// 1,000 wrong tokens from 100 addresses (127.0.0.2..101, ten each, all at
// once): the daemon spends on them about what it spends on as many hellos
// with the right token (measured first, the same way, from 127.0.0.102..201:
// a CPU time asserted alone breaks under a sanitizer or on a loaded machine)
// and logs a handful of lines; each address is slowed (its last tries wait
// their turn, up to 1 s apart), and a client with the right token is served
// meanwhile.
TEST(Daemon, AThousandWrongTokensCostWhatAsManyRightOnesDoAndAFewLogLines) {
  fs::path dir = rigtest::temp_dir("wrong");
  fs::path store = dir / "store";
  auto d = DaemonProcess::start(store, kSmall);
  ASSERT_TRUE(d && d->port() != 0) << (d ? d->log() : "");
  auto token = veneer::rig::read_token_file(store / "token");
  ASSERT_TRUE(token);
  {  // 127.0.0.2 must be usable as a source address here
    rigtest::RawConnection probe(d->port(), 2);
    if (!probe.ok()) GTEST_SKIP() << "cannot connect from 127.0.0.2";
  }
  std::this_thread::sleep_for(std::chrono::seconds(1));  // the daemon's start is done
  constexpr int kAddresses = 100, kEach = 10;
  // kAddresses x kEach hellos, all at once from 127.0.0.<first>.., the i-th of
  // an address with token_of(i): how many were answered as `expected`, and
  // the seconds each address took.
  auto burst = [&](int first, const std::function<std::string(int)>& token_of, const std::string& expected,
                   std::vector<double>& per_address_s) {
    std::atomic<int> answered{0};
    per_address_s.assign(kAddresses, 0.0);
    std::vector<std::thread> peers;
    for (int a = 0; a < kAddresses; ++a) {
      peers.emplace_back([&, a] {
        auto start = std::chrono::steady_clock::now();
        for (int i = 0; i < kEach; ++i) {
          rigtest::RawConnection c(d->port(), first + a);
          c.send(hello_message(token_of(i), "guess"));
          auto r = c.next_response(1, 20);
          if (r && (expected.empty() ? r->ok() : !r->ok() && r->error().find(expected) != std::string::npos))
            ++answered;
        }
        per_address_s[static_cast<size_t>(a)] =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      });
    }
    for (auto& t : peers) t.join();
    return answered.load();
  };
  std::vector<double> per_address_s;
  double cpu_before = d->cpu_seconds();
  const int welcomed = burst(2 + kAddresses, [&](int) { return *token; }, "", per_address_s);
  const double cpu_right = d->cpu_seconds() - cpu_before;
  EXPECT_EQ(welcomed, kAddresses * kEach);

  const size_t log_before = count_lines(d->full_log());
  cpu_before = d->cpu_seconds();
  auto t0 = std::chrono::steady_clock::now();
  std::thread attack([&] {
    const int refused = burst(2, [](int i) { return "not-the-token-" + std::to_string(i); }, "wrong access token",
                              per_address_s);
    EXPECT_EQ(refused, kAddresses * kEach);
  });
  // Meanwhile the right token from another address is answered at once.
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  auto good_start = std::chrono::steady_clock::now();
  auto good = connect(*d, store);
  const double good_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - good_start).count();
  attack.join();
  const double attack_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const double cpu = d->cpu_seconds() - cpu_before;
  ASSERT_TRUE(good);
  EXPECT_LT(good_s, 1.0);
  // 3 answers at once, then turns 0.1, 0.2, 0.4, 0.8, 1, 1, 1 s apart (4.5 s).
  EXPECT_GE(*std::min_element(per_address_s.begin(), per_address_s.end()), 4.4);
  EXPECT_LT(attack_s, 30.0);
  // Measured (Release, load 3.3-4.3): the wrong ones cost 1.07-1.11 times the right ones' CPU (0.41-0.52 s).
  EXPECT_LT(cpu, 1.5 * cpu_right) << "daemon CPU for 1000 wrong tokens " << cpu << " s, for 1000 right ones "
                                  << cpu_right << " s";
  // The burst's summary comes once it has been quiet for 5 s.
  std::this_thread::sleep_for(std::chrono::seconds(6));
  std::string log = d->full_log();
  size_t pos = 0;
  for (size_t n = 0; n < log_before; ++n) pos = log.find('\n', pos) + 1;
  std::string added = log.substr(pos);
  EXPECT_LE(count_lines(added), 5u) << added;
  EXPECT_NE(added.find("1000 attempts"), std::string::npos) << added;
  std::printf("1000 wrong tokens: %.2f s of daemon CPU (1000 right ones: %.2f s, ratio %.2f), %zu log lines, %.1f s "
              "for the attack; right token answered in %.3f s meanwhile\n%s",
              cpu, cpu_right, cpu / cpu_right, count_lines(added), attack_s, good_s, added.c_str());
  EXPECT_TRUE(d->alive());
  fs::remove_all(dir);
}

// Control is taken by the first control request; one that is refused (here:
// delete of a set that is not there) leaves control free for others.
TEST(Daemon, ARefusedControlRequestDoesNotKeepControl) {
  fs::path dir = rigtest::temp_dir("control");
  fs::path store = dir / "store";
  auto d = DaemonProcess::start(store, kSmall);
  ASSERT_TRUE(d && d->port() != 0) << (d ? d->log() : "");
  auto first = connect(*d, store);
  auto second = connect(*d, store);
  ASSERT_TRUE(first && second);
  auto refused = first->delete_set("no-such-set");
  ASSERT_FALSE(refused);
  auto s = first->status();
  ASSERT_TRUE(s);
  EXPECT_FALSE(s->you_control);
  EXPECT_FALSE(s->controller_taken);
  ASSERT_TRUE(second->set_lamps({true}));  // free: the second takes it
  auto s2 = second->status();
  ASSERT_TRUE(s2);
  EXPECT_TRUE(s2->you_control);
  auto other = first->set_lamps({false});
  ASSERT_FALSE(other);
  EXPECT_NE(other.message().find("controls the rig"), std::string::npos) << other.message();
  // A controller's own refused request does not cost it control.
  EXPECT_FALSE(second->delete_set("no-such-set"));
  s2 = second->status();
  ASSERT_TRUE(s2);
  EXPECT_TRUE(s2->you_control);
  fs::remove_all(dir);
}

// A set restored from the trash is announced to every client, as its delete
// was: another viewer sees it come back without listing again.
TEST(Daemon, RestoringASetFromTheTrashIsAnnouncedToOtherClients) {
  fs::path dir = rigtest::temp_dir("restore");
  fs::path store = dir / "store";
  auto d = DaemonProcess::start(store, kSmall);
  ASSERT_TRUE(d && d->port() != 0) << (d ? d->log() : "");
  auto actor = connect(*d, store);
  auto watcher = connect(*d, store);
  ASSERT_TRUE(actor && watcher);
  using K = veneer::rig::Event::Kind;
  ASSERT_TRUE(actor->press_button());
  auto stored = actor->wait_event([](const veneer::rig::Event& e) { return e.kind == K::set_stored; }, 60);
  ASSERT_TRUE(stored) << stored.message() << d->log();
  const std::string id = stored->set_id;

  ASSERT_TRUE(actor->delete_set(id));
  auto deleted = watcher->wait_event([](const veneer::rig::Event& e) { return e.kind == K::set_deleted; }, 10);
  ASSERT_TRUE(deleted) << deleted.message();
  EXPECT_EQ(deleted->set_id, id);

  ASSERT_TRUE(actor->restore_set(id));
  auto restored = watcher->wait_event([](const veneer::rig::Event& e) { return e.kind == K::set_restored; }, 10);
  ASSERT_TRUE(restored) << restored.message();
  EXPECT_EQ(restored->set_id, id);
  EXPECT_EQ(restored->seq, deleted->seq + 1) << "one event per change, in order";
  EXPECT_EQ(veneer::rig::describe(*restored), "set_restored " + id);
  // the actor hears it too, and the set is listed again
  EXPECT_TRUE(actor->wait_event([](const veneer::rig::Event& e) { return e.kind == K::set_restored; }, 10));
  auto sets = watcher->list_sets();
  ASSERT_TRUE(sets);
  ASSERT_EQ(sets->size(), 1u);
  EXPECT_EQ(sets->front().id, id);

  // a refused restore (nothing of that id in the trash) announces nothing
  EXPECT_FALSE(actor->restore_set(id));
  EXPECT_FALSE(watcher->wait_event([](const veneer::rig::Event& e) { return e.kind == K::set_restored; }, 0.5));
  fs::remove_all(dir);
}

// Issue 29: the rig side holds one frame at a time, not the set, and one
// scene's G-buffer, not the pair's. Capturing a pair at 1600x1064 (the
// destination, then the source: another scene) may grow the daemon's peak
// resident memory (VmHWM) by at most 16 frames' worth of float pixels: the
// scene's G-buffer (~5 of them), the frame being shaded, encoded and its RAW
// file (~4), the truth (~2, after the shots). Holding a set's 8 frames as
// float until the end, as before, adds 7 more and fails; so does keeping the
// first scene's G-buffer while the second is made, or a truth twice its size.
TEST(Daemon, ACapturesPeakMemoryIsAFewFramesNotTheWholeSetAsFloat) {
#if defined(__SANITIZE_ADDRESS__)
  GTEST_SKIP() << "under AddressSanitizer the peak is its quarantine and redzones, not the daemon's own memory";
#endif
  fs::path dir = rigtest::temp_dir("peak");
  fs::path store = dir / "store";
  const int w = 1600, h = 1064;
  auto d = DaemonProcess::start(store, {"--size", std::to_string(w) + "x" + std::to_string(h), "--preview-size", "160x106"});
  ASSERT_TRUE(d && d->port() != 0) << (d ? d->log() : "");
  auto c = connect(*d, store);
  ASSERT_TRUE(c);
  const double idle_mib = d->rss_mib("VmHWM");
  ASSERT_GT(idle_mib, 0);
  const double frame_mib = static_cast<double>(w) * h * 3 * sizeof(float) / 1048576.0;
  using K = veneer::rig::Event::Kind;
  std::vector<std::string> ids;
  for (const char* role : {"destination", "source"}) {
    auto id = c->capture();
    ASSERT_TRUE(id) << id.message();
    auto done = c->wait_event([&](const veneer::rig::Event& e) {
      return e.set_id == *id && (e.kind == K::set_stored || e.kind == K::capture_failed);
    }, 120);
    ASSERT_TRUE(done) << done.message() << d->log();
    ASSERT_EQ(done->kind, K::set_stored) << done->reason;
    const double peak_mib = d->rss_mib("VmHWM");
    EXPECT_LT(peak_mib - idle_mib, 16 * frame_mib)
        << "after the " << role << ": idle " << idle_mib << " MiB, peak " << peak_mib << " MiB, one float frame "
        << frame_mib << " MiB";
    ids.push_back(*id);
  }
  // ... and the sets are whole: every photo, RAW file and the truth.
  for (size_t i = 0; i < ids.size(); ++i) {
    auto set = veneer::io::read_set(store / ids[i], {});
    ASSERT_TRUE(set) << set.message();
    EXPECT_EQ(set->role, i == 0 ? veneer::io::Role::destination : veneer::io::Role::source);
    EXPECT_EQ(set->size, cv::Size(w, h));
    EXPECT_EQ(set->images.size(), 7u);
    EXPECT_FALSE(set->ambient.empty());
    EXPECT_TRUE(set->truth.present());
  }
  fs::remove_all(dir);
}
