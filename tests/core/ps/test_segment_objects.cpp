// core/SegmentObjects.*: the default segmentation on simulated scenes (the
// simulator's truth mask is the object without its base) and on the real cat
// (its supplied mask as the truth): dark parts kept, plinths left out, the
// backdrop never taken in.
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>

#include "veneer/io/imageset.hpp"
#include "veneer/ps/photometric_stereo.hpp"
#include "veneer/ps/segmentation.hpp"
#include "veneer/sim/simulator.hpp"

namespace veneer::ps {
namespace {

io::ImageSet simulate(const std::string& scene, double ambient = 0.02, bool optics = false) {
  sim::RenderOptions o;
  o.size = {512, 340};
  o.seed = 5;
  o.ambient = ambient;
  if (optics) o.camera_optics();
  auto s = sim::simulate_set(scene, o);
  EXPECT_TRUE(s.ok()) << (s.ok() ? "" : s.message());
  return s.ok() ? std::move(*s) : io::ImageSet{};
}

struct Overlap {
  double missed = 0, extra = 0;  // of the truth's pixels
};
Overlap overlap(const cv::Mat& mask, const cv::Mat& truth) {
  const double t = cv::countNonZero(truth);
  return {cv::countNonZero(truth & ~mask) / t, cv::countNonZero(mask & ~truth) / t};
}

// The object, its base dropped after the normals are solved (what the
// transfer and `veneer normals` do).
cv::Mat object_of(const io::ImageSet& set, SupportRemoval* base = nullptr) {
  auto seg = segment(set, {});
  EXPECT_TRUE(seg.ok()) << (seg.ok() ? "" : seg.message());
  if (!seg.ok()) return {};
  EXPECT_EQ(seg->method_used, SegmentMethod::contrast);
  auto r = photometric_stereo(set, seg->mask, {});
  EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.message());
  if (!r.ok()) return {};
  SupportRemoval b = drop_supports(*r);
  if (base) *base = b;
  return r->mask;
}

TEST(SegmentObjects, TheBullWithoutItsPlinthWithItsShadowedLegsAndTail) {
  io::ImageSet set = simulate("bull");
  SupportRemoval base;
  const cv::Mat m = object_of(set, &base);
  const Overlap o = overlap(m, set.truth.mask);
  std::printf("bull: missed %.2f %%, extra %.2f %%, base %d px on %d faces\n", 100 * o.missed, 100 * o.extra,
              base.removed_pixels, base.planes);
  EXPECT_GT(base.removed_pixels, 1000);
  // measured 0.92 % (was 1.96 % before the dim outline was kept and the
  // hooves' and legs' pixels beside the plinth went back to the bull)
  EXPECT_LT(o.missed, 0.012);
  EXPECT_LT(o.extra, 0.03);  // specks of the plinth in the legs' shadows at most (measured 1.21 %)
}

// Through a camera's optics (the rig twin's: a lens-blurred crease between
// the plinth's faces, penumbrae of the legs' shadows across its top, its edge
// mixed with the backdrop) the plinth is still found whole: its faces join
// across the seams, and the seams and rim go with it.
TEST(SegmentObjects, ThePlinthThroughACamerasOpticsSeamsAndRimIncluded) {
  io::ImageSet set = simulate("bull", 0.02, true);
  SupportRemoval base;
  const cv::Mat m = object_of(set, &base);
  const Overlap o = overlap(m, set.truth.mask);
  std::printf("bull through optics: missed %.2f %%, extra %.2f %%, base %d px on %d faces\n", 100 * o.missed,
              100 * o.extra, base.removed_pixels, base.planes);
  EXPECT_GT(base.removed_pixels, 1000);
  EXPECT_LT(o.missed, 0.006);  // measured 0.34 % (0.83 % before the legs' pixels beside the plinth stayed)
  // The truth is where the object covers half a pixel or more; the contrast
  // threshold also keeps the outline's mixed pixels (a ring of ~1 px: 4-7 %
  // of objects this small, see below), and a patch of the plinth in the hind
  // legs' shadow (no lamp lights it: its normals are filled from the legs')
  // stays with them: 9.8 % in all (9.4 % before the mixed pixels where a
  // hoof meets the plinth went to the side whose normal they share). Before the seams were crossed, no base
  // was found here at all.
  EXPECT_LT(o.extra, 0.11);
}

// Objects without a base keep every pixel, flat faces included (also through optics).
TEST(SegmentObjects, ObjectsWithoutABaseStayWhole) {
  for (const char* scene : {"blocks", "cup-white", "stone", "two-spheres", "banana"})
   for (const bool optics : {false, true}) {
    SCOPED_TRACE(optics ? "camera optics" : "point-sampled");
    io::ImageSet set = simulate(scene, 0.02, optics);
    SupportRemoval base;
    const cv::Mat m = object_of(set, &base);
    const Overlap o = overlap(m, set.truth.mask);
    std::printf("%s: missed %.2f %%, extra %.2f %%, base %d px\n", scene, 100 * o.missed, 100 * o.extra,
                base.removed_pixels);
    EXPECT_EQ(base.removed_pixels, 0) << scene;
    EXPECT_LT(o.missed, 0.01) << scene;
    EXPECT_LT(o.extra, optics ? 0.08 : 0.01) << scene;  // through optics: the outline's mixed pixels
  }
}

// The thesis's summed threshold (Otsu on the mean) lost a dark object's
// shadowed parts; the brightest lamp's photo keeps them.
TEST(SegmentObjects, ContrastKeepsWhatOtsuOnTheMeanLoses) {
  io::ImageSet set = simulate("bull", 0.0);
  SegmentOptions otsu;
  otsu.method = SegmentMethod::otsu;
  auto a = segment(set, otsu), b = segment(set, {});
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_LT(overlap(b->mask, set.truth.mask).missed, overlap(a->mask, set.truth.mask).missed);
  EXPECT_GT(b->backdrop, 0.0);
}

// The real cat on black cloth before a dim wall: the contrast method alone
// (its supplied mask ignored) finds the cat and neither the wall nor the cloth.
TEST(SegmentObjects, RealCatAgainstItsSuppliedMask) {
  const auto folder = std::filesystem::path(VENEER_SHARED_DATA) / "real" / "cat";
  if (!std::filesystem::exists(folder / "filenames.txt")) GTEST_SKIP() << "no " << folder;
  auto set = io::read_set(folder);
  ASSERT_TRUE(set.ok()) << set.message();
  ASSERT_FALSE(set->mask.empty());
  SegmentOptions so;
  so.method = SegmentMethod::contrast;
  auto seg = segment(*set, so);
  ASSERT_TRUE(seg.ok()) << seg.message();
  const Overlap o = overlap(seg->mask, set->mask);
  std::printf("cat: missed %.2f %%, extra %.2f %%\n", 100 * o.missed, 100 * o.extra);
  EXPECT_LT(o.missed, 0.02);
  EXPECT_LT(o.extra, 0.02);
  SegmentOptions ot;
  ot.method = SegmentMethod::otsu;  // what the issue saw: the wall taken in
  auto seg2 = segment(*set, ot);
  ASSERT_TRUE(seg2.ok());
  EXPECT_GT(overlap(seg2->mask, set->mask).extra, 0.5);
}

TEST(SegmentObjects, BadContrastOptions) {
  io::ImageSet set = simulate("orange");
  SegmentOptions so;
  so.method = SegmentMethod::contrast;
  so.contrast_low = 0.9;
  auto r = segment(set, so);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.message().find("contrast"), std::string::npos) << r.message();
  EXPECT_EQ(parse_segment_method("contrast").value(), SegmentMethod::contrast);
  so = {};
  so.outline_sigmas = -1;
  r = segment(set, so);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.message().find("outline_sigmas"), std::string::npos) << r.message();
}

// drop_supports works within the mask's bounding box (issue 48: the whole
// frame was 2.2 of its 2.3 s at 5600x3750): the bull and its plinth framed
// in a frame four times as large, off centre, lose the same pixels as in
// their own frame, to the bit.
TEST(SegmentObjects, TheBaseDroppedIsTheSameInALargerFrame) {
  io::ImageSet set = simulate("bull");
  auto seg = segment(set, {});
  ASSERT_TRUE(seg.ok()) << seg.message();
  auto r = photometric_stereo(set, seg->mask, {});
  ASSERT_TRUE(r.ok()) << r.message();
  cv::Mat small_mask = r->mask.clone();
  const SupportRemoval small = drop_supports(small_mask, r->normals);
  ASSERT_GT(small.removed_pixels, 1000);
  const cv::Rect at(cv::Point(700, 37), r->mask.size());
  cv::Mat big_mask(r->mask.rows * 2, r->mask.cols * 2 + 300, CV_8UC1, cv::Scalar(0));
  cv::Mat big_normals(big_mask.size(), CV_32FC3, cv::Scalar::all(0));
  r->mask.copyTo(big_mask(at));
  r->normals.copyTo(big_normals(at));
  const SupportRemoval big = drop_supports(big_mask, big_normals);
  EXPECT_EQ(big.removed_pixels, small.removed_pixels);
  EXPECT_EQ(big.planes, small.planes);
  EXPECT_EQ(cv::countNonZero(big_mask), cv::countNonZero(small_mask));
  EXPECT_EQ(cv::countNonZero(big_mask(at) != small_mask), 0);
}

}  // namespace
}  // namespace veneer::ps
