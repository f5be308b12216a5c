// The per-set result cache's store: the size cap evicts the least recently
// used entry, keys cannot escape the cache folder, matrices round-trip through
// blobs and files and damaged files are refused.
#include <chrono>
#include <filesystem>
#include <string>

#include <gtest/gtest.h>

#include "test_util.hpp"
#include "veneer/io/cache.hpp"

namespace veneer {
namespace {

using test::Scratch;

TEST(Cache, SizeCapEvictsTheLeastRecentlyUsed) {
  Scratch dir;
  io::CacheOptions o;
  o.dir = dir / "cache";
  o.max_bytes = 3u << 20;
  io::ResultCache cache(o);
  const std::string mib(1u << 20, 'x');
  ASSERT_TRUE(cache.store("a", {{"blob", mib}}));
  ASSERT_TRUE(cache.store("b", {{"blob", mib}}));
  // mark "a" used later than "b"
  std::filesystem::last_write_time(o.dir / "b", std::filesystem::file_time_type::clock::now() - std::chrono::hours(1));
  ASSERT_TRUE(cache.load("a"));
  ASSERT_TRUE(cache.store("c", {{"blob", mib + mib}}));
  EXPECT_TRUE(cache.load("a"));
  EXPECT_FALSE(cache.load("b"));
  EXPECT_TRUE(cache.load("c"));
  EXPECT_LE(cache.size_bytes(), o.max_bytes);
  EXPECT_FALSE(cache.store("../escape", {{"blob", "x"}}));
  EXPECT_FALSE(cache.load("../escape"));
}

TEST(Cache, MatricesRoundTrip) {
  cv::Mat m(5, 7, CV_32FC3, cv::Scalar(0.25f, -1.5f, 3.0f));
  auto back = io::decode_mat(io::encode_mat(m), "m");
  ASSERT_TRUE(back);
  EXPECT_EQ(cv::norm(m, *back, cv::NORM_INF), 0.0);
  auto half = io::decode_mat(io::encode_mat(m, true), "h");
  ASSERT_TRUE(half);
  EXPECT_EQ(half->type(), CV_32FC3);
  EXPECT_LT(cv::norm(m, *half, cv::NORM_INF), 1e-3);
  EXPECT_FALSE(io::decode_mat(io::encode_mat(m).substr(0, 30), "cut"));
  EXPECT_FALSE(io::decode_mat("MAT1", "short"));
}

TEST(Cache, MatrixFilesRoundTripAndRefuseDamage) {
  Scratch dir;
  cv::Mat m(300, 211, CV_32FC3);
  cv::RNG(3).fill(m, cv::RNG::UNIFORM, 0.0, 1.0);
  ASSERT_TRUE(io::write_mat_file(dir / "f", m));
  auto back = io::read_mat_file(dir / "f");
  ASSERT_TRUE(back) << back.message();
  EXPECT_EQ(cv::norm(*back, m, cv::NORM_INF), 0.0);
  ASSERT_TRUE(io::write_mat_file(dir / "h", m, true));
  auto half = io::read_mat_file(dir / "h");
  ASSERT_TRUE(half) << half.message();
  ASSERT_EQ(half->type(), CV_32FC3);
  EXPECT_LT(cv::norm(*half, m, cv::NORM_INF), 1e-3);
  // The file is the blob encode_mat makes, byte for byte.
  EXPECT_EQ(test::slurp(dir / "h"), io::encode_mat(m, true));
  test::spit(dir / "cut", io::encode_mat(m).substr(0, 5000));
  auto cut = io::read_mat_file(dir / "cut");
  ASSERT_FALSE(cut);
  EXPECT_NE(cut.message().find("cut"), std::string::npos);
  EXPECT_NE(cut.message().find("size does not match"), std::string::npos) << cut.message();
}

}  // namespace
}  // namespace veneer
