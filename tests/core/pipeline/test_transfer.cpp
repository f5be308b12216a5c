// Transfer end to end on small simulated sets (the simulator's truth is the oracle).
#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include <tbb/global_control.h>

#include <atomic>
#include <filesystem>
#include <fstream>
#include <set>

#include "veneer/eval/metrics.hpp"
#include "veneer/pipeline/transfer.hpp"
#include "veneer/sim/simulator.hpp"

namespace veneer::match {
namespace {

using namespace veneer::eval;
using namespace veneer::pipeline;
using namespace veneer::repaint;

io::ImageSet simulated(const std::string& scene, io::Role role, cv::Size size = {160, 106}) {
  sim::RenderOptions o;
  o.size = size;
  auto set = sim::simulate_set(scene, o, role);
  EXPECT_TRUE(set.ok()) << (set.ok() ? "" : set.message());
  return set.ok() ? *set : io::ImageSet{};
}

TransferOptions options(Method m, bool truth = true) {
  TransferOptions o;
  o.match.method = m;
  o.match.fast = false;
  o.truth_normals = truth;
  return o;
}

TEST(Transfer, WritesEverythingAndMeasuresQuality) {
  const io::ImageSet dst = simulated("cup-white", io::Role::destination);
  const io::ImageSet src = simulated("sphere-gray", io::Role::source);
  auto r = transfer(dst, src, options(Method::linear));
  ASSERT_TRUE(r.ok()) << r.message();
  ASSERT_TRUE(r->quality.has_value());
  const Quality& q = *r->quality;
  EXPECT_GT(q.coverage, 0.999);
  EXPECT_EQ(q.background_hits, 0);
  // a sphere shows every visible normal: exact matching on true normals agrees closely
  ASSERT_TRUE(q.normal_mean_deg.has_value());
  EXPECT_LT(*q.normal_mean_deg, 3.0);
  ASSERT_TRUE(q.psnr_db.has_value());
  EXPECT_GT(*q.psnr_db, 20.0);
  EXPECT_EQ(r->repainted.size(), dst.images.size());

  const auto dir = std::filesystem::temp_directory_path() / ("veneer-transfer-test-" + std::to_string(::getpid()));
  ASSERT_TRUE(write_transfer(*r, dir).ok());
  for (const char* f : {"map.pfm", "map.png", "confidence.png", "result_light_00.png", "result_median.png", "reuse.png",
                        "metrics.json"})
    EXPECT_TRUE(std::filesystem::exists(dir / f)) << f;
  std::ifstream json(dir / "metrics.json");
  const std::string text((std::istreambuf_iterator<char>(json)), std::istreambuf_iterator<char>());
  EXPECT_NE(text.find("\"coverage\""), std::string::npos);
  EXPECT_NE(text.find("\"match_s\""), std::string::npos);
  auto back = read_map(dir / "map.pfm");
  ASSERT_TRUE(back.ok());
  auto again = evaluate_sets(*back, dst, src);
  ASSERT_TRUE(again.ok()) << again.message();
  EXPECT_NEAR(again->coverage, q.coverage, 1e-9);
  EXPECT_NEAR(*again->normal_mean_deg, *q.normal_mean_deg, 1e-6);
  std::filesystem::remove_all(dir);
}

TEST(Transfer, RelightingRewardsMatchingNormals) {
  // the relighting PSNR must tell a normal-matched map from the bounding-box baseline
  const io::ImageSet dst = simulated("bull", io::Role::destination);
  const io::ImageSet src = simulated("sphere-red-gloss", io::Role::source);
  auto matched = transfer(dst, src, options(Method::linear));
  auto baseline = transfer(dst, src, options(Method::baseline));
  ASSERT_TRUE(matched.ok() && baseline.ok());
  ASSERT_TRUE(matched->quality->psnr_db && baseline->quality->psnr_db);
  EXPECT_GT(*matched->quality->psnr_db, *baseline->quality->psnr_db + 1.0);
  EXPECT_LT(*matched->quality->normal_mean_deg, *baseline->quality->normal_mean_deg);
}

TEST(Transfer, RelightingLeavesOutTheCastShadowsNoMapCanCarry) {
  // the bull casts shadows under the relighting lamp (on its plinth, its legs);
  // the sphere has none, so even the map of exactly matching normals errs there
  const io::ImageSet dst = simulated("bull", io::Role::destination, {320, 212});
  const io::ImageSet src = simulated("sphere-red-gloss", io::Role::source, {320, 212});
  auto exact = transfer(dst, src, options(Method::linear));
  ASSERT_TRUE(exact.ok()) << exact.message();
  ASSERT_TRUE(exact->relit.has_value());
  const Relit& relit = *exact->relit;
  const int object = cv::countNonZero(dst.truth.mask), lit = cv::countNonZero(relit.lit);
  EXPECT_GT(object - lit, object / 50) << "the bull's cast shadows";
  EXPECT_LT(object - lit, object / 5);
  cv::Mat outside;
  cv::bitwise_and(relit.lit, ~dst.truth.mask, outside);
  EXPECT_EQ(cv::countNonZero(outside), 0) << "lit is a part of the destination's mask";
  // the shadowed pixels are dark in the reference, where the carried source is lit
  cv::Mat shadowed;
  cv::bitwise_and(dst.truth.mask, ~relit.lit, shadowed);
  const cv::Scalar in_shadow = cv::mean(relit.reference, shadowed), carried = cv::mean(relit.transferred, shadowed);
  EXPECT_LT(in_shadow[2], 0.5 * carried[2]);
  // they hold most of the exact map's error, not the baseline's
  ASSERT_TRUE(exact->quality->psnr_lit_db.has_value());
  EXPECT_GT(*exact->quality->psnr_lit_db, *exact->quality->psnr_db + 5.0);
  EXPECT_NEAR(relit.psnr_lit_db, psnr(relit.transferred, relit.reference, relit.lit), 1e-9);
  auto baseline = transfer(dst, src, options(Method::baseline));
  ASSERT_TRUE(baseline.ok()) << baseline.message();
  EXPECT_GT(*exact->quality->psnr_lit_db, *baseline->quality->psnr_lit_db + 5.0);
}

TEST(Transfer, PipelineWithPhotometricStereoAndScale) {
  const io::ImageSet dst = simulated("bull", io::Role::destination, {320, 212});
  const io::ImageSet src = simulated("orange", io::Role::source, {320, 212});
  auto o = options(Method::flann, false);
  o.scale = 0.5;
  auto r = transfer(dst, src, o);
  ASSERT_TRUE(r.ok()) << r.message();
  EXPECT_EQ(r->map.xy.cols, 160);
  ASSERT_TRUE(r->quality.has_value());
  const Quality& q = *r->quality;
  std::printf("photometric stereo + segmentation at 160x106: coverage %.3f, background hits %d of %d, normal %.2f deg\n",
              q.coverage, q.background_hits, q.destination_pixels, *q.normal_mean_deg);
  // measured against the truth masks: segmentation differs from them only at the rim
  EXPECT_GT(q.coverage, 0.85);
  EXPECT_LT(q.background_hits, 0.03 * q.destination_pixels);
  EXPECT_LT(*q.normal_mean_deg, 15.0);
}

// Blending keeps a chunk's inside exactly as repaint::repaint() has it and softens
// only where two chunks meet; radius 0 is repaint::repaint() itself.
TEST(Transfer, RepaintBlendedKeepsChunksSharp) {
  const cv::Size size(40, 30);
  cv::Mat photo(size, CV_32FC3);
  cv::randu(photo, cv::Scalar::all(0), cv::Scalar::all(1));
  Map map;
  map.xy = cv::Mat(size, CV_32FC2, cv::Scalar(-1, -1));
  map.distance = cv::Mat(size, CV_32FC1, cv::Scalar(0));
  for (int y = 5; y < 25; ++y)
    for (int x = 5; x < 35; ++x)  // two chunks: (+2, +1) left of x = 20, (-3, 0) right
      map.xy.at<cv::Vec2f>(y, x) = x < 20 ? cv::Vec2f(x + 2.f, y + 1.f) : cv::Vec2f(x - 3.f, y + 0.f);
  const cv::Mat backdrop(size, CV_32FC3, cv::Scalar::all(0.5));
  const cv::Mat plain = repaint::repaint(map, photo, backdrop);
  auto same_as_plain = repaint_blended(map, photo, {}, 0, backdrop);
  ASSERT_TRUE(same_as_plain.ok());
  EXPECT_EQ(cv::norm(*same_as_plain, plain, cv::NORM_INF), 0.0);
  auto blended = repaint_blended(map, photo, {}, 2, backdrop);
  ASSERT_TRUE(blended.ok()) << blended.message();
  const cv::Mat soft = *blended;
  auto same = [&](int x, int y) { return cv::norm(soft.at<cv::Vec3f>(y, x) - plain.at<cv::Vec3f>(y, x)) < 1e-5; };
  EXPECT_TRUE(same(10, 15));  // inside the left chunk
  EXPECT_TRUE(same(28, 15));  // inside the right chunk
  EXPECT_TRUE(same(0, 0));    // unmapped: the backdrop
  EXPECT_FALSE(same(19, 15));  // at the seam, the two chunks mixed
  EXPECT_FALSE(same(20, 15));
  // a mask that does not fit the photo is an error, not a silent plain repaint
  auto misfit = repaint_blended(map, photo, cv::Mat(5, 5, CV_8UC1, cv::Scalar(255)), 2, backdrop);
  ASSERT_FALSE(misfit.ok());
  EXPECT_NE(misfit.message().find("mask"), std::string::npos) << misfit.message();
  // through transfer: the options reach the result, and a bad radius is refused
  const io::ImageSet dst = simulated("cup-white", io::Role::destination);
  const io::ImageSet src = simulated("cup-dots", io::Role::source);
  auto o = options(Method::linear);
  o.blend = 2;
  o.look = repaint::Look::copy;  // the blend paints the copy's pictures
  auto r = transfer(dst, src, o);
  ASSERT_TRUE(r.ok()) << r.message();
  EXPECT_NE(r->metrics_json.find("\"blend\": 2"), std::string::npos);
  // matched on normals, the blend is guided by them (the default), and that
  // changes the pictures: the guided and the plain blend differ
  EXPECT_NE(r->metrics_json.find("\"blend_guide\": 0.1"), std::string::npos) << r->metrics_json;
  // every matching option is recorded, the refinement's round limit too
  EXPECT_NE(r->metrics_json.find("\"coherent_sweeps\": " + std::to_string(o.match.coherent_sweeps)), std::string::npos);
  auto plain_blend = o;
  plain_blend.blend_guide = 0;
  auto rp = transfer(dst, src, plain_blend);
  ASSERT_TRUE(rp.ok()) << rp.message();
  EXPECT_NE(rp->metrics_json.find("\"blend_guide\": 0.0"), std::string::npos);
  EXPECT_EQ(cv::norm(r->map.xy, rp->map.xy, cv::NORM_INF), 0.0);
  EXPECT_GT(cv::norm(r->repainted_median, rp->repainted_median, cv::NORM_INF), 0.0);
  auto bad_guide = o;
  bad_guide.blend_guide = 3;
  auto refused = transfer(dst, src, bad_guide);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.message().find("blend_guide"), std::string::npos) << refused.message();
  o.blend = 17;
  auto bad = transfer(dst, src, o);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.message().find("blend radius"), std::string::npos) << bad.message();
}

// A prepared pair repainted from a map computed earlier (the viewer's blend
// slider): the same pictures as a full transfer with those options, the map
// untouched, no matching time; a map of another size is refused.
TEST(Transfer, FromAGivenMapRepaintsWithoutMatching) {
  const io::ImageSet dst = simulated("cup-white", io::Role::destination);
  const io::ImageSet src = simulated("cup-dots", io::Role::source);
  auto o = options(Method::coherent);
  o.blend = 0;  // first without blending
  o.look = repaint::Look::copy;  // the blend paints the copy's pictures
  auto pair = prepare_pair(dst, src, o);
  ASSERT_TRUE(pair.ok()) << pair.message();
  auto first = transfer(*pair, o);
  ASSERT_TRUE(first.ok()) << first.message();
  EXPECT_FALSE(first->map_given);
  EXPECT_TRUE(first->match_options == o.match);
  o.blend = 2;
  auto full = transfer(*pair, o);
  auto kept = transfer(*pair, o, first->map);
  ASSERT_TRUE(full.ok() && kept.ok()) << kept.message();
  EXPECT_TRUE(kept->map_given);
  EXPECT_EQ(kept->match_seconds, 0.0);
  EXPECT_EQ(cv::norm(kept->map.xy, first->map.xy, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(kept->repainted_median, full->repainted_median, cv::NORM_INF), 0.0);
  // The blend shows at a seam (this pair's map is one coherent chunk, which
  // the blend leaves as it is): the right half continued 3 px further.
  Map seamed{first->map.xy.clone(), first->map.distance.clone()};
  for (int y = 0; y < seamed.xy.rows; ++y)
    for (int x = seamed.xy.cols / 2; x < seamed.xy.cols; ++x)
      if (seamed.valid(x, y)) seamed.xy.at<cv::Vec2f>(y, x)[0] += 3;
  auto soft = transfer(*pair, o, seamed);
  o.blend = 0;
  auto sharp = transfer(*pair, o, seamed);
  ASSERT_TRUE(soft.ok() && sharp.ok());
  EXPECT_GT(cv::norm(soft->repainted_median, sharp->repainted_median, cv::NORM_INF), 0.0) << "the blend shows";
  o.blend = 2;
  EXPECT_NE(kept->metrics_json.find("\"map_given\": true"), std::string::npos);
  Map small;
  cv::resize(first->map.xy, small.xy, {}, 0.5, 0.5, cv::INTER_NEAREST);
  cv::resize(first->map.distance, small.distance, {}, 0.5, 0.5, cv::INTER_NEAREST);
  auto bad = transfer(*pair, o, small);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.message().find("map given"), std::string::npos) << bad.message();
}

// A cancel while the result is written stops the files not yet begun: here,
// one file at a time, after the first -- that one is whole, nothing else is
// there (no temporary), no metrics.json, and the call says "cancelled".
TEST(Transfer, WritingStopsBetweenFilesWhenCancelled) {
  const io::ImageSet dst = simulated("cup-white", io::Role::destination);
  const io::ImageSet src = simulated("cup-dots", io::Role::source);
  auto r = transfer(dst, src, options(Method::coherent));
  ASSERT_TRUE(r.ok()) << r.message();
  const auto dir = std::filesystem::temp_directory_path() / ("veneer-cancel-write-" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  std::atomic<bool> cancel{false};
  int files_done = 0;
  Progress p;
  p.cancel = &cancel;
  p.on_progress = [&](double f, const std::string&) {
    if (f > 0 && ++files_done == 1) cancel = true;
  };
  {
    tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);  // the files one after another
    auto s = write_transfer(*r, dir, p);
    ASSERT_FALSE(s.ok());
    EXPECT_NE(s.message().find("cancelled"), std::string::npos) << s.message();
  }
  std::set<std::string> names;
  for (const auto& e : std::filesystem::directory_iterator(dir)) names.insert(e.path().filename().string());
  EXPECT_EQ(names, std::set<std::string>{"map.pfm"}) << "the first file only, no temporary";
  auto back = read_map(dir / "map.pfm");
  ASSERT_TRUE(back.ok()) << back.message();
  EXPECT_EQ(cv::norm(back->xy, r->map.xy, cv::NORM_INF), 0.0) << "whole";
  // not cancelled: everything, metrics.json last
  cancel = false;
  files_done = 2;
  ASSERT_TRUE(write_transfer(*r, dir, p).ok());
  EXPECT_TRUE(std::filesystem::exists(dir / "metrics.json"));
  std::filesystem::remove_all(dir);
}

// What the live view needs to repaint frames as the stills were: the options
// back from metrics.json, and the same blend plan from them.
TEST(Transfer, OptionsComeBackFromMetricsAndGiveTheStillsBlend) {
  const io::ImageSet dst = simulated("bull", io::Role::destination);
  const io::ImageSet src = simulated("orange", io::Role::source);
  auto o = options(Method::coherent);
  o.match.fast = true;
  o.match.coherent_threshold = 0.15, o.match.seed = 7, o.match.coherent_sweeps = 3;
  o.scale = 0.75, o.blend = 3, o.blend_guide = 0.2;
  auto r = transfer(dst, src, o);
  ASSERT_TRUE(r.ok()) << r.message();
  ASSERT_TRUE(r->blend);
  const auto dir = std::filesystem::temp_directory_path() / ("veneer-options-test-" + std::to_string(::getpid()));
  ASSERT_TRUE(write_transfer(*r, dir).ok());
  auto back = read_transfer_options(dir / "metrics.json");
  ASSERT_TRUE(back.ok()) << back.message();
  EXPECT_TRUE(back->match == o.match);
  EXPECT_EQ(back->scale, o.scale);
  EXPECT_EQ(back->truth_normals, o.truth_normals);
  EXPECT_EQ(back->blend, o.blend);
  EXPECT_EQ(back->blend_guide, o.blend_guide);

  // the plan from the options read back and the map read back: the stills' own
  auto map = read_map(dir / "map.pfm");
  ASSERT_TRUE(map.ok()) << map.message();
  auto pair = prepare_pair(dst, src, *back);
  ASSERT_TRUE(pair.ok()) << pair.message();
  auto plan = blend_plan_for(*pair, *back, *map);
  ASSERT_TRUE(plan.ok()) << plan.message();
  ASSERT_TRUE(*plan);
  const fast::BlendPlan &a = **plan, &b = *r->blend;
  EXPECT_EQ(a.pixels, b.pixels);
  EXPECT_EQ(a.first, b.first);
  ASSERT_EQ(a.terms.size(), b.terms.size());
  for (size_t i = 0; i < a.terms.size(); ++i) {
    ASSERT_EQ(a.terms[i].source, b.terms[i].source) << i;
    ASSERT_EQ(a.terms[i].weight, b.terms[i].weight) << i;
  }
  // plain when asked, and none at radius 0
  TransferOptions plain = *back;
  plain.blend_guide = 0;
  auto p = blend_plan_for(*pair, plain, *map);
  ASSERT_TRUE(p.ok() && *p);
  bool differs = (*p)->terms.size() != a.terms.size();
  for (size_t i = 0; !differs && i < a.terms.size(); ++i) differs = (*p)->terms[i].weight != a.terms[i].weight;
  EXPECT_TRUE(differs) << "the guide changes the weights";
  plain.blend = 0;
  auto none = blend_plan_for(*pair, plain, *map);
  ASSERT_TRUE(none.ok());
  EXPECT_FALSE(*none);
  // a map of another size is named
  Map small;
  cv::resize(map->xy, small.xy, {}, 0.5, 0.5, cv::INTER_NEAREST);
  auto wrong = blend_plan_for(*pair, *back, small);
  ASSERT_FALSE(wrong.ok());
  EXPECT_NE(wrong.message().find("the map is"), std::string::npos) << wrong.message();

  // bad files: each error names the file and what is wrong; nothing else is touched
  auto write = [&](const std::string& text) {
    std::ofstream(dir / "bad.json") << text;
    return read_transfer_options(dir / "bad.json");
  };
  auto not_json = write("{ \"options\": ");
  ASSERT_FALSE(not_json.ok());
  EXPECT_NE(not_json.message().find("bad.json: not a JSON object"), std::string::npos) << not_json.message();
  auto wrong_type = write(R"({"options": {"blend": "two"}})");
  ASSERT_FALSE(wrong_type.ok());
  EXPECT_NE(wrong_type.message().find("options.blend"), std::string::npos) << wrong_type.message();
  auto negative_seed = write(R"({"options": {"seed": -1}})");
  ASSERT_FALSE(negative_seed.ok());
  EXPECT_NE(negative_seed.message().find("options.seed"), std::string::npos) << negative_seed.message();
  auto huge = write(R"({"options": {"patch": 4294967297}})");
  ASSERT_FALSE(huge.ok());
  EXPECT_NE(huge.message().find("options.patch"), std::string::npos) << huge.message();
  auto range = write(R"({"options": {"blend": 40}})");
  ASSERT_FALSE(range.ok());
  EXPECT_NE(range.message().find("blend"), std::string::npos) << range.message();
  auto method = write(R"({"options": {"method": "magic"}})");
  ASSERT_FALSE(method.ok());
  EXPECT_NE(method.message().find("options.method"), std::string::npos) << method.message();
  auto missing = read_transfer_options(dir / "none.json");
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.message().find("none.json"), std::string::npos) << missing.message();
  // no options recorded: the defaults
  auto bare = write(R"({"quality": {}})");
  ASSERT_TRUE(bare.ok()) << bare.message();
  EXPECT_TRUE(bare->match == TransferOptions{}.match);
  EXPECT_EQ(bare->blend, TransferOptions{}.blend);
  std::filesystem::remove_all(dir);
}

TEST(Transfer, BadInput) {
  const io::ImageSet dst = simulated("apple", io::Role::destination);
  io::ImageSet src = simulated("banana", io::Role::source);
  src.images.pop_back();
  src.lights.pop_back();
  auto o = options(Method::linear);
  o.match.feature = Feature::intensities;
  auto r = transfer(dst, src, o);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.message().find("same lamps"), std::string::npos) << r.message();
  o.scale = 0;
  EXPECT_FALSE(transfer(dst, src, o).ok());
  io::ImageSet no_truth = dst;
  no_truth.truth = {};
  auto t = transfer(no_truth, src, options(Method::linear));
  ASSERT_FALSE(t.ok());
  EXPECT_NE(t.message().find("truth"), std::string::npos);
}

}  // namespace
}  // namespace veneer::match
