// core/PhotometricStereo.*: normals against analytic truth, robust and
// near-light modes, bad input.
#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

#include "synth.hpp"
#include "veneer/ps/photometric_stereo.hpp"

namespace veneer::ps {
namespace {

using test::SynthOptions;
using test::synth_sphere;

AngularError solve_error(const io::ImageSet& set, const PsOptions& opt, PsResult* out = nullptr) {
  auto r = photometric_stereo(set, set.truth.mask, opt);
  EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.message());
  if (!r.ok()) return {};
  AngularError e = angular_error(r->normals, set.truth.normals, set.truth.mask);
  if (out) *out = std::move(*r);
  return e;
}

TEST(PhotometricStereo, DistantLightsExactSphere) {
  SynthOptions o;
  o.distant = true;
  io::ImageSet set = synth_sphere(o);
  PsOptions opt;
  opt.light_model = LightModel::distant;
  opt.robust = true;
  PsResult r;
  AngularError e = solve_error(set, opt, &r);
  EXPECT_GT(e.pixels, 1500);
  EXPECT_LT(e.mean_deg, 0.1);
  EXPECT_LT(e.p95_deg, 0.3);
  EXPECT_EQ(r.model_used, LightModel::distant);
  // Albedo per channel is recovered (BGR).
  cv::Scalar mean_albedo = cv::mean(r.albedo, r.reliable);
  EXPECT_NEAR(mean_albedo[0], 0.5, 0.01);
  EXPECT_NEAR(mean_albedo[1], 0.6, 0.01);
  EXPECT_NEAR(mean_albedo[2], 0.7, 0.01);
  // The fit is exact where no sample is shadowed: tiny residual.
  EXPECT_LT(cv::mean(r.residual, r.reliable)[0], 0.01);
  // Outside the mask normals are zero.
  EXPECT_EQ(r.normals.at<cv::Vec3f>(0, 0), cv::Vec3f(0, 0, 0));
}

TEST(PhotometricStereo, PlainLeastSquaresIsBiasedByShadows) {
  // Attached shadows near the limb violate the linear model: the robust mode
  // drops those samples, plain least squares does not.
  SynthOptions o;
  o.distant = true;
  io::ImageSet set = synth_sphere(o);
  PsOptions robust, plain;
  robust.light_model = plain.light_model = LightModel::distant;
  plain.robust = false;
  AngularError er = solve_error(set, robust), ep = solve_error(set, plain);
  EXPECT_LT(er.mean_deg, ep.mean_deg);
  EXPECT_GT(ep.p95_deg, 3 * er.p95_deg);
}

TEST(PhotometricStereo, AmbientIsSubtracted) {
  SynthOptions o;
  o.distant = true;
  o.ambient = 0.05;
  io::ImageSet set = synth_sphere(o);
  PsOptions opt;
  opt.light_model = LightModel::distant;
  EXPECT_LT(solve_error(set, opt).mean_deg, 0.1);
  opt.subtract_ambient = false;
  EXPECT_GT(solve_error(set, opt).mean_deg, 1.0);
}

TEST(PhotometricStereo, NearLightModelCorrectsOffCentreSphere) {
  SynthOptions o;
  o.center = cv::Vec3d(0.10, 0.0, 0.0);
  io::ImageSet set = synth_sphere(o);
  PsOptions near_opt, distant_opt;
  near_opt.light_model = LightModel::near;
  distant_opt.light_model = LightModel::distant;
  PsResult r;
  AngularError en = solve_error(set, near_opt, &r), ed = solve_error(set, distant_opt);
  EXPECT_EQ(r.model_used, LightModel::near);
  EXPECT_LT(en.mean_deg, 1.0);
  EXPECT_GT(ed.mean_deg, 2 * en.mean_deg);
  EXPECT_GT(ed.mean_deg, 3.0);
  // The refined depth follows the sphere: the centre pixel of the sphere is
  // nearer the camera than its silhouette by about a radius.
  ASSERT_FALSE(r.depth.empty());
  cv::Mat diff;
  cv::absdiff(r.depth, set.truth.depth, diff);
  EXPECT_LT(cv::mean(diff, set.truth.mask)[0], 0.02);
}

TEST(PhotometricStereo, AutomaticPicksNearWhenLampPositionsKnown) {
  SynthOptions o;
  io::ImageSet set = synth_sphere(o);
  auto r = photometric_stereo(set, set.truth.mask, {});
  ASSERT_TRUE(r.ok()) << r.message();
  EXPECT_EQ(r->model_used, LightModel::near);
  for (auto& l : set.lights) l.position_m.reset();
  r = photometric_stereo(set, set.truth.mask, {});
  ASSERT_TRUE(r.ok()) << r.message();
  EXPECT_EQ(r->model_used, LightModel::distant);
}

TEST(PhotometricStereo, RobustBeatsPlainUnderNoise) {
  SynthOptions o;
  o.noise = 0.01;
  o.seed = 7;
  io::ImageSet set = synth_sphere(o);
  PsOptions robust, plain;
  plain.robust = false;
  AngularError er = solve_error(set, robust), ep = solve_error(set, plain);
  EXPECT_LT(er.mean_deg, 3.0);
  EXPECT_LT(er.mean_deg, ep.mean_deg);
}

TEST(PhotometricStereo, SaturatedSamplesAreDropped) {
  SynthOptions o;
  o.distant = true;
  o.lamp_intensity = 1.6;  // bright lamps clip the facing part of the sphere
  io::ImageSet set = synth_sphere(o);
  PsOptions robust, plain;
  robust.light_model = plain.light_model = LightModel::distant;
  plain.robust = false;
  AngularError er = solve_error(set, robust), ep = solve_error(set, plain);
  EXPECT_LT(er.mean_deg, 0.5);
  EXPECT_LT(er.mean_deg, ep.mean_deg);
}

TEST(PhotometricStereo, OutlierSampleIsDropped) {
  // A highlight-like bright patch in one photo: the robust fit drops it.
  SynthOptions o;
  o.distant = true;
  io::ImageSet set = synth_sphere(o);
  cv::Mat patch(set.images[0].size(), CV_8UC1, cv::Scalar(0));
  cv::circle(patch, {128, 85}, 8, cv::Scalar(255), cv::FILLED);
  for (int y = 0; y < patch.rows; ++y)
    for (int x = 0; x < patch.cols; ++x)
      if (patch.at<uint8_t>(y, x)) set.images[2].at<cv::Vec3f>(y, x) += cv::Vec3f(0.3f, 0.3f, 0.3f);
  PsOptions with, without;
  with.light_model = without.light_model = LightModel::distant;
  with.outlier_fraction = 0.1f;
  without.outlier_fraction = 0.f;
  cv::Mat m;
  cv::bitwise_and(patch, set.truth.mask, m);
  auto rw = photometric_stereo(set, set.truth.mask, with), ro = photometric_stereo(set, set.truth.mask, without);
  ASSERT_TRUE(rw.ok() && ro.ok());
  const double ew = angular_error(rw->normals, set.truth.normals, m).mean_deg;
  const double eo = angular_error(ro->normals, set.truth.normals, m).mean_deg;
  EXPECT_LT(ew, 0.5);
  EXPECT_GT(eo, 4 * ew) << "with " << ew << " without " << eo;
}

TEST(PhotometricStereo, GlossyColouredSurfaceIsSolvedOffItsHighlights) {
  // A red glazed sphere under tinted lamps: every lamp's highlight (in the
  // lamp's colour) lands near the middle. Solved on the colour's off-grey
  // part, the highlights are gone; on grey they bend the normals.
  SynthOptions o;
  o.distant = true;
  o.albedo_bgr = {0.05f, 0.07f, 0.70f};
  o.lamp_tint = {1.0f, 0.85f, 0.7f};
  o.specular = 0.6;
  o.shininess = 60;
  o.noise = 0.002;
  io::ImageSet set = synth_sphere(o);
  PsOptions with, without;
  with.light_model = without.light_model = LightModel::distant;
  without.diffuse_chroma = 0.f;
  const AngularError ew = solve_error(set, with), eo = solve_error(set, without);
  EXPECT_LT(ew.mean_deg, 0.5);
  EXPECT_LT(ew.p95_deg, 1.0);
  EXPECT_GT(eo.mean_deg, 3 * ew.mean_deg) << "with " << ew.mean_deg << " without " << eo.mean_deg;
  EXPECT_GT(eo.p95_deg, 3 * ew.p95_deg) << "with " << ew.p95_deg << " without " << eo.p95_deg;
}

TEST(PhotometricStereo, GreySurfaceKeepsItsGreySolve) {
  // A grey glossy sphere has no off-grey part to solve on: the option leaves
  // it exactly as it was.
  SynthOptions o;
  o.distant = true;
  o.albedo_bgr = {0.6f, 0.6f, 0.6f};
  o.specular = 0.4;
  io::ImageSet set = synth_sphere(o);
  PsOptions with, without;
  with.light_model = without.light_model = LightModel::distant;
  without.diffuse_chroma = 0.f;
  auto rw = photometric_stereo(set, set.truth.mask, with), ro = photometric_stereo(set, set.truth.mask, without);
  ASSERT_TRUE(rw.ok() && ro.ok());
  EXPECT_EQ(cv::norm(rw->normals, ro->normals, cv::NORM_INF), 0.0);
}

TEST(PhotometricStereo, UnreliablePixelsAreMarked) {
  // Three lamps only: every attached shadow leaves < 3 samples.
  SynthOptions o;
  o.distant = true;
  io::ImageSet set = synth_sphere(o);
  set.images.resize(3);
  set.lights.resize(3);
  PsOptions opt;
  opt.light_model = LightModel::distant;
  auto r = photometric_stereo(set, set.truth.mask, opt);
  ASSERT_TRUE(r.ok()) << r.message();
  EXPECT_GT(r->unreliable_pixels, 0);
  EXPECT_LT(r->unreliable_pixels, r->solved_pixels);
  EXPECT_EQ(r->unreliable_pixels, r->solved_pixels - cv::countNonZero(r->reliable));
  // Where all three see the surface the answer is exact.
  EXPECT_LT(angular_error(r->normals, set.truth.normals, r->reliable).mean_deg, 0.1);
}

TEST(PhotometricStereo, ManyLightsUseNormalEquations) {
  // More lamps than the pattern cache holds: the same answer by another path.
  SynthOptions o;
  o.distant = true;
  io::ImageSet set = synth_sphere(o);
  io::ImageSet big = set;
  for (int rep = 0; rep < 2; ++rep)
    for (size_t i = 0; i < set.images.size(); ++i) {
      big.images.push_back(set.images[i]);
      big.lights.push_back(set.lights[i]);
    }
  PsOptions opt;
  opt.light_model = LightModel::distant;
  ASSERT_GT(big.images.size(), 12u);
  EXPECT_LT(solve_error(big, opt).mean_deg, 0.1);
  opt.robust = false;
  EXPECT_NEAR(solve_error(big, opt).mean_deg, solve_error(set, opt).mean_deg, 1e-3);
}

TEST(PhotometricStereo, CancelIsHonoured) {
  io::ImageSet set = synth_sphere({});
  std::atomic<bool> cancel{true};
  Progress p;
  p.cancel = &cancel;
  auto r = photometric_stereo(set, {}, {}, p);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.message().find("cancel"), std::string::npos);
}

TEST(PhotometricStereo, ProgressReachesOne) {
  io::ImageSet set = synth_sphere({});
  double last = -1;
  Progress p;
  p.on_progress = [&](double f, const std::string&) {
    EXPECT_GE(f, last);
    last = f;
  };
  ASSERT_TRUE(photometric_stereo(set, set.truth.mask, {}, p).ok());
  EXPECT_DOUBLE_EQ(last, 1.0);
}

// ---- bad input ----

TEST(PhotometricStereoBadInput, FewerThanThreeLights) {
  io::ImageSet set = synth_sphere({});
  set.images.resize(2);
  set.lights.resize(2);
  auto r = photometric_stereo(set, {}, {});
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.message().find("at least 3 lights"), std::string::npos) << r.message();
}

TEST(PhotometricStereoBadInput, IdenticalDirections) {
  SynthOptions o;
  o.distant = true;
  io::ImageSet set = synth_sphere(o);
  for (auto& l : set.lights) l.direction = set.lights[0].direction;
  PsOptions opt;
  opt.light_model = LightModel::distant;
  auto r = photometric_stereo(set, {}, opt);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.message().find("degenerate"), std::string::npos) << r.message();
}

TEST(PhotometricStereoBadInput, CoplanarDirections) {
  SynthOptions o;
  o.distant = true;
  io::ImageSet set = synth_sphere(o);
  // All directions in the x-z plane.
  for (size_t i = 0; i < set.lights.size(); ++i) {
    const double a = 0.2 * double(i) - 0.6;
    set.lights[i].direction = cv::Vec3d(std::sin(a), 0, std::cos(a));
  }
  PsOptions opt;
  opt.light_model = LightModel::distant;
  auto r = photometric_stereo(set, {}, opt);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.message().find("degenerate"), std::string::npos) << r.message();
}

TEST(PhotometricStereoBadInput, EmptyMask) {
  io::ImageSet set = synth_sphere({});
  cv::Mat mask(set.images[0].size(), CV_8UC1, cv::Scalar(0));
  auto r = photometric_stereo(set, mask, {});
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.message().find("mask is empty"), std::string::npos) << r.message();
}

TEST(PhotometricStereoBadInput, MaskOfWrongSize) {
  io::ImageSet set = synth_sphere({});
  cv::Mat mask(10, 10, CV_8UC1, cv::Scalar(255));
  auto r = photometric_stereo(set, mask, {});
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.message().find("10x10"), std::string::npos) << r.message();
}

TEST(PhotometricStereoBadInput, ImagesOfDifferentSizes) {
  io::ImageSet set = synth_sphere({});
  set.images[3] = cv::Mat(20, 30, CV_32FC3, cv::Scalar::all(0));
  auto r = photometric_stereo(set, {}, {});
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.message().find("image 3"), std::string::npos) << r.message();
}

TEST(PhotometricStereoBadInput, NearWithoutPositions) {
  io::ImageSet set = synth_sphere({});
  set.lights[2].position_m.reset();
  PsOptions opt;
  opt.light_model = LightModel::near;
  auto r = photometric_stereo(set, {}, opt);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.message().find("position"), std::string::npos) << r.message();
}

TEST(PhotometricStereoBadInput, BadOptions) {
  io::ImageSet set = synth_sphere({});
  PsOptions opt;
  opt.shadow_fraction = 1.5f;
  EXPECT_FALSE(opt.check().ok());
  auto r = photometric_stereo(set, {}, opt);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.message().find("shadow_fraction"), std::string::npos) << r.message();
  opt = {};
  opt.near_iterations = 9;
  EXPECT_FALSE(opt.check().ok());
  opt = {};
  opt.saturation = 0.f;
  EXPECT_FALSE(opt.check().ok());
  opt = {};
  opt.diffuse_chroma = -0.1f;
  r = photometric_stereo(set, {}, opt);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.message().find("diffuse_chroma"), std::string::npos) << r.message();
}

TEST(AngularError, KnownAngles) {
  cv::Mat a(1, 4, CV_32FC3), t(1, 4, CV_32FC3);
  for (int i = 0; i < 4; ++i) {
    const double deg = 10.0 * i, r = deg * CV_PI / 180;
    a.at<cv::Vec3f>(0, i) = cv::Vec3f(float(std::sin(r)), 0, float(std::cos(r)));
    t.at<cv::Vec3f>(0, i) = cv::Vec3f(0, 0, 1);
  }
  AngularError e = angular_error(a, t, {});
  EXPECT_EQ(e.pixels, 4);
  EXPECT_NEAR(e.mean_deg, 15.0, 1e-3);
  EXPECT_NEAR(e.max_deg, 30.0, 1e-3);
}

}  // namespace
}  // namespace veneer::ps
