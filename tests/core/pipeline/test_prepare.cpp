// Preparing sets through the per-set result cache: a second preparation of
// the same set is a hit with the same results; a hand-drawn mask is keyed by
// its content; the prepared photos are the frames less ambient.
#include <cstdlib>

#include <gtest/gtest.h>

#include "test_util.hpp"
#include "veneer/io/cache.hpp"
#include "veneer/io/dng.hpp"
#include "veneer/io/raw.hpp"
#include "veneer/pipeline/prepare.hpp"
#include "veneer/pipeline/transfer.hpp"
#include "veneer/sim/simulator.hpp"

namespace veneer {
namespace {

using test::Scratch;

void write_simulated(const std::filesystem::path& folder, const std::string& scene) {
  sim::RenderOptions o;
  o.size = {256, 170};
  o.noise_sigma = 0.005;
  o.scale = 2.5;
  auto set = sim::simulate_set(scene, o, io::Role::destination);
  ASSERT_TRUE(set) << set.message();
  ASSERT_TRUE(io::write_set(*set, folder));
}

// One demosaic by default everywhere (issue 42): the io library's RawOptions,
// every read_set without options and the product's prepare options (the CLI,
// the viewer) all decode RAW with our MHC; a caller that builds its own
// options cannot get another by accident. The read through the defaults is
// MHC's bit for bit and differs from DCB's (what the io default was).
TEST(Prepare, OneDefaultDemosaicEverywhere) {
  const pipeline::PrepareOptions product = pipeline::default_prepare_options();
  EXPECT_EQ(io::RawOptions{}.demosaic, io::Demosaic::mhc);
  EXPECT_EQ(product.read.raw.demosaic, io::Demosaic::mhc);
  EXPECT_EQ(io::ReadOptions{}.raw.demosaic, product.read.raw.demosaic);
  EXPECT_EQ(pipeline::PrepareOptions{}.read.raw.demosaic, product.read.raw.demosaic);
  EXPECT_EQ(io::RawOptions{}.half_size, product.read.raw.half_size);
  EXPECT_EQ(io::ReadOptions{}.photos, product.read.photos);

  Scratch dir;
  sim::RenderOptions o;
  o.size = {256, 170};
  o.noise_sigma = 0.005;
  o.scale = 2.5;
  o.camera_optics();
  auto set = sim::simulate_set("orange", o, io::Role::destination);
  ASSERT_TRUE(set) << set.message();
  ASSERT_TRUE(io::add_dng_raw_files(*set));
  ASSERT_TRUE(io::write_set(*set, dir / "orange"));
  auto by_default = io::read_set(dir / "orange");
  ASSERT_TRUE(by_default) << by_default.message();
  ASSERT_EQ(by_default->photos_from, "raw");
  auto read_as = [&](io::Demosaic d) {
    io::ReadOptions r;
    r.raw.demosaic = d;
    auto s = io::read_set(dir / "orange", r);
    EXPECT_TRUE(s) << s.message();
    return s ? s->images[0] : cv::Mat();
  };
  EXPECT_EQ(cv::norm(by_default->images[0], read_as(io::Demosaic::mhc), cv::NORM_INF), 0.0);
  EXPECT_GT(cv::norm(by_default->images[0], read_as(io::Demosaic::dcb), cv::NORM_INF), 0.0);
}

TEST(Cache, SecondPreparationIsAHitWithTheSameResults) {
  Scratch dir;
  const char* before = std::getenv("XDG_CACHE_HOME");  // the test run's (never the user's), put back below
  const std::string previous = before ? before : "";
  ::setenv("XDG_CACHE_HOME", (dir / "xdg").c_str(), 1);
  EXPECT_EQ(io::default_cache_dir(), dir / "xdg" / "veneer");
  write_simulated(dir / "bull", "bull");
  pipeline::PrepareOptions options;
  auto first = pipeline::prepare_set(dir / "bull", 1.0, false, options);
  ASSERT_TRUE(first) << first.message();
  EXPECT_FALSE(first->report.cache_hit);
  EXPECT_FALSE(first->report.checksum.empty());
  auto second = pipeline::prepare_set(dir / "bull", 1.0, false, options);
  ASSERT_TRUE(second) << second.message();
  EXPECT_TRUE(second->report.cache_hit);
  EXPECT_EQ(second->report.photos_from, "png");
  EXPECT_EQ(cv::norm(first->object.view.normals, second->object.view.normals, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(first->object.view.mask, second->object.view.mask, cv::NORM_INF), 0.0);
  ASSERT_EQ(second->object.view.images.size(), first->object.view.images.size());
  // photos are kept as half floats: relative error < 1e-3
  EXPECT_LT(cv::norm(first->object.view.images[3], second->object.view.images[3], cv::NORM_INF), 1e-3);
  EXPECT_EQ(second->set.size, first->set.size);
  EXPECT_TRUE(second->set.truth.present());

  // Another read option is another entry.
  options.read.photos = io::PhotoSource::developed;
  auto other = pipeline::prepare_set(dir / "bull", 1.0, false, options);
  ASSERT_TRUE(other);
  EXPECT_FALSE(other->report.cache_hit);
  // A damaged entry is dropped and recomputed.
  const auto entry = io::default_cache_dir() / second->report.checksum;
  test::spit(entry / "normals", "garbage");
  options.read.photos = io::PhotoSource::automatic;
  auto again = pipeline::prepare_set(dir / "bull", 1.0, false, options);
  ASSERT_TRUE(again) << again.message();
  EXPECT_FALSE(again->report.cache_hit);
  EXPECT_TRUE(pipeline::prepare_set(dir / "bull", 1.0, false, options)->report.cache_hit);
  // Off means off.
  options.cache.enabled = false;
  auto off = pipeline::prepare_set(dir / "bull", 1.0, false, options);
  ASSERT_TRUE(off);
  EXPECT_TRUE(off->report.checksum.empty());
  if (before) ::setenv("XDG_CACHE_HOME", previous.c_str(), 1);
  else ::unsetenv("XDG_CACHE_HOME");
}

// A mask drawn by hand is part of the key: the same mask again is a hit with
// the masked results, another mask (or none) is another entry.
TEST(Cache, AHandDrawnMaskIsKeyedByItsContent) {
  Scratch dir;
  pipeline::PrepareOptions options;
  options.cache.dir = dir / "cache";
  write_simulated(dir / "bull", "bull");
  auto plain = pipeline::prepare_set(dir / "bull", 1.0, false, options);
  ASSERT_TRUE(plain) << plain.message();
  cv::Mat right = plain->object.view.mask.clone();
  right(cv::Rect(0, 0, right.cols / 2, right.rows)).setTo(0);  // the right half of the object
  ASSERT_GT(cv::countNonZero(right), 100);
  options.mask = right;
  auto first = pipeline::prepare_set(dir / "bull", 1.0, false, options);
  ASSERT_TRUE(first) << first.message();
  EXPECT_FALSE(first->report.cache_hit);
  EXPECT_NE(first->report.checksum, plain->report.checksum);
  const cv::Rect left(0, 0, right.cols / 2, right.rows);
  EXPECT_EQ(cv::countNonZero(first->object.view.mask(left)), 0);
  (void)pipeline::finish_cache_writes();
  // the same mask, made anew (another Mat of the same content): a hit
  options.mask = right.clone();
  auto second = pipeline::prepare_set(dir / "bull", 1.0, false, options);
  ASSERT_TRUE(second) << second.message();
  EXPECT_TRUE(second->report.cache_hit);
  EXPECT_EQ(second->report.checksum, first->report.checksum);
  EXPECT_EQ(cv::norm(first->object.view.mask, second->object.view.mask, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(first->object.view.normals, second->object.view.normals, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::countNonZero(second->set.mask != (right > 127)), 0);
  // one pixel more is another mask
  cv::Mat more = right.clone();
  more.at<uchar>(right.rows / 2, right.cols / 2 - 1) = 255;
  options.mask = more;
  auto third = pipeline::prepare_set(dir / "bull", 1.0, false, options);
  ASSERT_TRUE(third) << third.message();
  EXPECT_FALSE(third->report.cache_hit);
  // a mask of another size is refused, naming both sizes
  options.mask = cv::Mat(10, 10, CV_8UC1, cv::Scalar(255));
  auto bad = pipeline::prepare_set(dir / "bull", 1.0, false, options);
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.message().find("10x10"), std::string::npos) << bad.message();
  (void)pipeline::finish_cache_writes();
}

// The photos a preparation hands on are the frames as read minus the
// ambient frame, clamped at 0 (done in the median's pass), and the median is
// the median of those.
TEST(Pipeline, PhotosAreTheFramesLessAmbientAndTheMedianIsTheirs) {
  Scratch dir;
  sim::RenderOptions o;
  o.size = {256, 170};
  o.noise_sigma = 0.005;
  o.scale = 2.5;
  o.ambient = 0.05;  // enough that the subtraction (and its clamp) shows
  auto sim_set = sim::simulate_set("bull", o, io::Role::destination);
  ASSERT_TRUE(sim_set) << sim_set.message();
  ASSERT_TRUE(io::write_set(*sim_set, dir / "bull"));
  auto raw = io::read_set(dir / "bull");
  ASSERT_TRUE(raw) << raw.message();
  ASSERT_FALSE(raw->ambient.empty());
  pipeline::PrepareOptions options;
  options.cache.enabled = false;
  auto prepared = pipeline::prepare_set(dir / "bull", 1.0, false, options);
  ASSERT_TRUE(prepared) << prepared.message();
  const auto& photos = prepared->object.view.images;
  ASSERT_EQ(photos.size(), raw->images.size());
  bool clamped = false;
  for (size_t i = 0; i < photos.size(); ++i) {
    cv::Mat expect;
    cv::subtract(raw->images[i], raw->ambient, expect);
    clamped = clamped || cv::countNonZero(expect.reshape(1) < 0) > 0;
    expect = cv::max(expect, 0.0);
    EXPECT_EQ(cv::norm(photos[i], expect, cv::NORM_INF), 0.0) << i;
  }
  EXPECT_TRUE(clamped);  // the noise takes some samples below the ambient level
  EXPECT_TRUE(prepared->set.ambient.empty());
  EXPECT_EQ(cv::norm(prepared->median, repaint::median_photo(photos), cv::NORM_INF), 0.0);
}

TEST(Cache, MedianOfPhotosEqualsTheMatchersMedian) {
  for (int n : {1, 2, 7, 8}) {
    std::vector<cv::Mat> photos(static_cast<size_t>(n));
    for (int i = 0; i < n; ++i) {
      photos[static_cast<size_t>(i)].create(13, 17, CV_32FC3);
      cv::RNG(static_cast<uint64_t>(40 + i)).fill(photos[static_cast<size_t>(i)], cv::RNG::UNIFORM, 0.0, 1.0);
    }
    photos[0].at<cv::Vec3f>(3, 4) = photos[n - 1].at<cv::Vec3f>(3, 4);  // ties
    EXPECT_EQ(cv::norm(pipeline::median_of(photos), repaint::median_photo(photos), cv::NORM_INF), 0.0) << n;
  }
}

}  // namespace
}  // namespace veneer
