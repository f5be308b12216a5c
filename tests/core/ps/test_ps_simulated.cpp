// core/PsSimulated.*: the headline numbers on the scene simulator's
// sphere-gray at 1024x680 (the simulator's truth is the oracle).
#include <gtest/gtest.h>

#include "veneer/ps/photometric_stereo.hpp"
#include "veneer/ps/segmentation.hpp"
#include "veneer/sim/simulator.hpp"

namespace veneer::ps {
namespace {

io::ImageSet simulate(double noise, cv::Vec3d offset = {0, 0, 0}, cv::Size size = {1024, 680}) {
  sim::RenderOptions o;
  o.size = size;
  o.noise_sigma = noise;
  o.offset_m = offset;
  o.seed = 3;
  auto s = sim::simulate_set("sphere-gray", o);
  EXPECT_TRUE(s.ok()) << (s.ok() ? "" : s.message());
  return s.ok() ? std::move(*s) : io::ImageSet{};
}

AngularError error_of(const io::ImageSet& set, const PsOptions& opt) {
  auto seg = segment(set, {});
  EXPECT_TRUE(seg.ok()) << (seg.ok() ? "" : seg.message());
  if (!seg.ok()) return {};
  auto r = photometric_stereo(set, seg->mask, opt);
  EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.message());
  if (!r.ok()) return {};
  cv::Mat both;
  cv::bitwise_and(seg->mask, set.truth.mask, both);
  // The segmentation finds the sphere: nearly all truth pixels are in it.
  EXPECT_GT(cv::countNonZero(both), 0.97 * cv::countNonZero(set.truth.mask));
  return angular_error(r->normals, set.truth.normals, both);
}

TEST(PsSimulated, SphereGrayWithoutNoiseBelowOneDegree) {
  io::ImageSet set = simulate(0.0);
  ASSERT_FALSE(set.images.empty());
  AngularError e = error_of(set, {});
  EXPECT_GT(e.pixels, 15000);
  EXPECT_LT(e.mean_deg, 1.0) << "median " << e.median_deg << " p95 " << e.p95_deg;
}

TEST(PsSimulated, SphereGrayNoisyRobustBelowThreeDegreesAndBeatsPlain) {
  io::ImageSet set = simulate(0.005);  // `veneer simulate`'s default noise
  ASSERT_FALSE(set.images.empty());
  PsOptions robust, plain;
  plain.robust = false;
  AngularError er = error_of(set, robust), ep = error_of(set, plain);
  EXPECT_LT(er.mean_deg, 3.0);
  EXPECT_LT(er.mean_deg, ep.mean_deg) << "robust " << er.mean_deg << " plain " << ep.mean_deg;
  EXPECT_LT(er.p95_deg, ep.p95_deg);
}

TEST(PsSimulated, SphereTenCentimetresOffCentreNeedsNearLight) {
  io::ImageSet set = simulate(0.005, {0.10, 0, 0});
  ASSERT_FALSE(set.images.empty());
  PsOptions near_opt, distant_opt;
  near_opt.light_model = LightModel::near;
  distant_opt.light_model = LightModel::distant;
  AngularError en = error_of(set, near_opt), ed = error_of(set, distant_opt);
  EXPECT_LT(en.mean_deg, 2.5);
  EXPECT_GT(ed.mean_deg, 2.0 * en.mean_deg) << "near " << en.mean_deg << " distant " << ed.mean_deg;
}

TEST(PsSimulated, DepthRefinementHelpsOffCentre) {
  // Small image: the near model with refinement beats the z = 0 plane alone.
  io::ImageSet set = simulate(0.0, {0.10, 0.05, 0}, {512, 340});
  ASSERT_FALSE(set.images.empty());
  PsOptions refined, flat;
  refined.light_model = flat.light_model = LightModel::near;
  flat.near_iterations = 0;
  EXPECT_LT(error_of(set, refined).mean_deg, error_of(set, flat).mean_deg);
}

}  // namespace
}  // namespace veneer::ps
