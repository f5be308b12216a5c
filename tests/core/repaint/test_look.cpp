// core/repaint: the shaded look (issue 35) on simulated pairs against the
// truth look -- the destination's shape rendered in the source's material.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numeric>
#include <atomic>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "veneer/eval/look.hpp"
#include "veneer/pipeline/transfer.hpp"
#include "veneer/repaint/gloss.hpp"
#include "veneer/repaint/look.hpp"
#include "veneer/sim/simulator.hpp"

using namespace veneer;

namespace {

// eval/look.hpp's figures (look.py's), over `mask`
double shading_error(const std::vector<cv::Mat>& result, const std::vector<cv::Mat>& reference, const cv::Mat& mask) {
  auto e = eval::shading_error(result, reference, mask);
  EXPECT_TRUE(e) << e.message();
  return e ? e->mean : 1e9;
}

double texture_correlation(const cv::Mat& result_median, const std::vector<cv::Mat>& source_photos,
                           const match::Map& map, const cv::Mat& mask) {
  std::vector<cv::Mat> grey;
  for (const cv::Mat& p : source_photos) grey.push_back(eval::look_gray(p));
  auto t = eval::texture_corr(result_median, eval::median_image(grey), map.xy, mask);
  EXPECT_TRUE(t) << t.message();
  return t ? *t : 0;
}


sim::RenderOptions small() {
  sim::RenderOptions o;
  o.size = {512, 340};
  o.noise_sigma = 0.005;  // veneer simulate's default
  return o;
}

struct Pair {
  io::ImageSet destination, source, truth;  // truth: the destination's shape in the source's material
};

Pair simulated(const char* destination, const char* source) {
  Pair p;
  auto d = sim::simulate_set(destination, small(), io::Role::destination);
  auto s = sim::simulate_set(source, small(), io::Role::source);
  auto t = sim::simulate_set_with_material(destination, source, small());
  EXPECT_TRUE(d && s && t);
  if (d && s && t) p = {std::move(*d), std::move(*s), std::move(*t)};
  return p;
}

}  // namespace

TEST(ShadedLook, NamesRoundTripAndOptionsAreChecked) {
  for (repaint::Look l : {repaint::Look::shaded, repaint::Look::copy}) {
    auto back = repaint::parse_look(repaint::look_name(l));
    ASSERT_TRUE(back);
    EXPECT_EQ(*back, l);
  }
  EXPECT_FALSE(repaint::parse_look("shiny"));
  EXPECT_TRUE(repaint::LookOptions{}.check());
  repaint::LookOptions o;
  o.seam_feather = -1;
  EXPECT_FALSE(o.check());
  o = {};
  o.gloss.exponents = {};
  EXPECT_FALSE(o.check());
  pipeline::TransferOptions t;
  EXPECT_EQ(t.look, repaint::Look::shaded);  // the default
  t.look_options.max_correction = 0.5;
  EXPECT_FALSE(t.check());
}

TEST(ShadedLook, RefusesAMapOfAnotherSizeAndCancels) {
  match::ObjectView v;
  v.mask = cv::Mat(20, 30, CV_8UC1, cv::Scalar(255));
  v.normals = cv::Mat(20, 30, CV_32FC3, cv::Scalar(0, 0, 1));
  std::vector<cv::Vec3d> lamps;
  for (int i = 0; i < 4; ++i) {
    v.images.push_back(cv::Mat(20, 30, CV_32FC3, cv::Scalar::all(0.3 + 0.1 * i)));
    lamps.push_back(cv::normalize(cv::Vec3d(std::cos(i * 1.6), std::sin(i * 1.6), 2)));
  }
  match::Map wrong(cv::Mat(10, 10, CV_32FC2, cv::Scalar::all(1)), cv::Mat(10, 10, CV_32F, cv::Scalar(0)));
  auto bad = repaint::ShadedLook::make({v, lamps}, {v, lamps}, wrong);
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.message().find("map"), std::string::npos) << bad.message();
  std::vector<cv::Vec3d> three(lamps.begin(), lamps.begin() + 3);
  match::Map same(cv::Mat(20, 30, CV_32FC2, cv::Scalar::all(2)), cv::Mat(20, 30, CV_32F, cv::Scalar(0)));
  EXPECT_FALSE(repaint::ShadedLook::make({v, three}, {v, lamps}, same));
  std::atomic<bool> stop{true};
  Progress cancel;
  cancel.cancel = &stop;
  auto cancelled = repaint::ShadedLook::make({v, lamps}, {v, lamps}, same, {}, cancel);
  ASSERT_FALSE(cancelled);
  EXPECT_NE(cancelled.message().find("cancelled"), std::string::npos) << cancelled.message();
  auto fine = repaint::ShadedLook::make({v, lamps}, {v, lamps}, same);
  ASSERT_TRUE(fine) << fine.message();
  // a flat grey source onto a flat grey destination: the look is the destination's own photo
  auto painted = fine->paint(2, v.images[2]);
  ASSERT_TRUE(painted);
  EXPECT_LT(cv::norm(*painted, v.images[2], cv::NORM_INF), 1e-3);
}

// The demo pair, smaller: the default transfer against the truth look, beside
// the exact nearest normal's pixel copy (`linear`, the floor of pixel copying).
TEST(ShadedLook, DemoPairTextureWholeAndShadingRight) {
  const Pair p = simulated("bull", "orange");
  ASSERT_FALSE(p.truth.images.empty());
  pipeline::TransferOptions shaded;  // the default: shaded, the default map
  shaded.match = pipeline::default_match_options();
  auto pair = pipeline::prepare_pair(p.destination, p.source, shaded);
  ASSERT_TRUE(pair) << pair.message();
  auto result = pipeline::transfer(*pair, shaded);
  ASSERT_TRUE(result) << result.message();
  pipeline::TransferOptions floor = shaded;
  floor.look = repaint::Look::copy;
  floor.match.method = match::Method::linear;
  auto copied = pipeline::transfer(*pair, floor);
  ASSERT_TRUE(copied) << copied.message();
  ASSERT_TRUE(result->look);
  EXPECT_FALSE(copied->look);

  const cv::Mat& mask = p.truth.truth.mask;
  const double e_shaded = shading_error(result->repainted, p.truth.images, mask);
  const double e_floor = shading_error(copied->repainted, p.truth.images, mask);
  const double texture = texture_correlation(result->repainted_median, pair->src.view.images, result->map, mask);
  ASSERT_TRUE(result->quality);
  const eval::Quality q = *result->quality;
  // coverage of the object the transfer found (segmentation), as the map sees it
  const eval::Quality seen = eval::evaluate(result->map, pair->dst.view.mask, pair->src.view.mask);
  std::printf("shaded: shading %.4f (linear copy %.4f, %.3fx), coherence %.3f, coverage %.4f of the truth, "
              "%.4f of the segmentation, texture %.3f\n",
              e_shaded, e_floor, e_shaded / e_floor, q.coherence, q.coverage, seen.coverage, texture);
  EXPECT_LE(e_shaded, 0.62 * e_floor);  // measured 0.554x (issue 40: it asserted 1.10x)
  EXPECT_GE(q.coherence, 0.85);
  EXPECT_GE(seen.coverage, 0.995);
  EXPECT_GT(texture, 0.5);
  // the linear copy is no texture at all: it scatters the source
  EXPECT_LT(copied->quality->coherence, 0.3);
}

// A glossy source (the red sphere, a white highlight on dark red): the
// highlights sit where the destination's normals put them -- the blue
// channel holds almost only the highlight, and follows the truth's; the
// source's photos copied through the same map of large chunks put the
// sphere's highlights where the sphere had them.
TEST(ShadedLook, GlossySourceHighlightsFollowTheDestinationsNormals) {
  const Pair p = simulated("bull", "sphere-red-gloss");
  ASSERT_FALSE(p.truth.images.empty());
  pipeline::TransferOptions shaded;
  shaded.match = pipeline::default_match_options();
  auto pair = pipeline::prepare_pair(p.destination, p.source, shaded);
  ASSERT_TRUE(pair) << pair.message();
  auto result = pipeline::transfer(*pair, shaded);
  ASSERT_TRUE(result) << result.message();
  ASSERT_TRUE(result->look);
  EXPECT_EQ(result->look->source_exponent(), 64);  // the sphere's lobe is sharp (shininess 80); measured 64
  pipeline::TransferOptions copy = shaded;
  copy.look = repaint::Look::copy;
  auto copied = pipeline::transfer(*pair, copy, result->map);
  ASSERT_TRUE(copied) << copied.message();
  // the truth's object where the map reaches (the plinth is not segmented)
  cv::Mat mask = p.truth.truth.mask.clone();
  for (int y = 0; y < mask.rows; ++y)
    for (int x = 0; x < mask.cols; ++x)
      if (!result->map.valid(x, y)) mask.at<uchar>(y, x) = 0;
  auto blue_correlation = [&](const std::vector<cv::Mat>& pictures) {
    double sum = 0;
    for (size_t l = 0; l < pictures.size(); ++l) {
      std::vector<double> a, b;
      for (int y = 0; y < mask.rows; ++y)
        for (int x = 0; x < mask.cols; ++x)
          if (mask.at<uchar>(y, x))
            a.push_back(pictures[l].at<cv::Vec3f>(y, x)[0]), b.push_back(p.truth.images[l].at<cv::Vec3f>(y, x)[0]);
      const double ma = std::accumulate(a.begin(), a.end(), 0.0) / a.size();
      const double mb = std::accumulate(b.begin(), b.end(), 0.0) / b.size();
      double ab = 0, aa = 0, bb = 0;
      for (size_t i = 0; i < a.size(); ++i)
        ab += (a[i] - ma) * (b[i] - mb), aa += (a[i] - ma) * (a[i] - ma), bb += (b[i] - mb) * (b[i] - mb);
      sum += ab / std::max(std::sqrt(aa * bb), 1e-12);
    }
    return sum / pictures.size();
  };
  const double shaded_corr = blue_correlation(result->repainted), copy_corr = blue_correlation(copied->repainted);
  std::printf("highlights (blue) against the truth: shaded %.3f, copy through the same map %.3f\n", shaded_corr,
              copy_corr);
  EXPECT_GT(shaded_corr, 0.6);
  EXPECT_GT(shaded_corr, copy_corr + 0.1);
}

TEST(ShadedLook, GlossFitFindsTheSpheresLobe) {
  auto s = sim::simulate_set("sphere-red-gloss", small(), io::Role::source);
  ASSERT_TRUE(s);
  std::vector<cv::Vec3d> lamps;
  for (const io::Light& l : s->lights) lamps.push_back(l.direction);
  auto g = repaint::fit_gloss(s->images, s->truth.normals, s->truth.mask, lamps);
  ASSERT_TRUE(g) << g.message();
  std::printf("the sphere's lobe: exponent %.0f (shininess 80; tried %s)\n", g->exponent, "4, 8, ..., 128");
  // of the exponents tried (powers of 2), 64 is the one nearest the true 80 in log (128 is 1.6x off);
  // measured 64 (issue 40: it accepted 32..128)
  EXPECT_EQ(g->exponent, 64);
  // the diffuse albedo is the sphere's red (0.70, 0.07, 0.05 as R, G, B), highlights passed by
  const cv::Scalar albedo = cv::mean(g->albedo, s->truth.mask);
  EXPECT_GT(albedo[2], 4 * albedo[0]);
  EXPECT_GT(cv::mean(g->weight, s->truth.mask)[0], 0.1);
  // a matte object has (almost) none
  auto m = sim::simulate_set("sphere-gray", small(), io::Role::source);
  ASSERT_TRUE(m);
  auto gm = repaint::fit_gloss(m->images, m->truth.normals, m->truth.mask, lamps);
  ASSERT_TRUE(gm) << gm.message();
  EXPECT_LT(cv::mean(gm->weight, m->truth.mask)[0], 0.25 * cv::mean(g->weight, s->truth.mask)[0]);
}
