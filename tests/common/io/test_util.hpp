#pragma once
// Helpers shared by the io tests: a scratch folder per test and small synthetic sets.
#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <unistd.h>

#include "veneer/io/imageset.hpp"

namespace veneer::test {

// A fresh folder under the system temp dir, removed at the end of the test.
class Scratch {
 public:
  Scratch() {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    std::string name = std::string("veneer-io-") + info->test_suite_name() + "-" + info->name() + "-" +
                       std::to_string(::getpid());
    path_ = std::filesystem::temp_directory_path() / name;
    std::filesystem::remove_all(path_);
    std::filesystem::create_directories(path_);
  }
  ~Scratch() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  const std::filesystem::path& path() const { return path_; }
  std::filesystem::path operator/(const std::string& s) const { return path_ / s; }

 private:
  std::filesystem::path path_;
};

inline std::string slurp(const std::filesystem::path& file) {
  std::ifstream in(file, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

inline void spit(const std::filesystem::path& file, const std::string& bytes) {
  std::ofstream out(file, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

// A small synthetic set with every optional part filled in; pixels from a fixed seed.
inline io::ImageSet synthetic_set(cv::Size size = {64, 48}, int lights = 4, uint64_t seed = 7, bool truth = true) {
  cv::RNG rng(seed);
  io::ImageSet set;
  set.id = "test-set";
  set.role = io::Role::destination;
  set.object = "synthetic";
  set.created = "2026-01-02T03:04:05Z";
  set.size = size;
  set.camera = {"sim-camera", 0.125, 8.0, 200, 900.0, size.width / 2.0, size.height / 2.0};
  set.scene = "synthetic";
  set.warnings = {"ambient frame is bright"};
  for (int i = 0; i < lights; ++i) {
    io::Light l;
    l.index = i;
    l.lamp_id = "sim-" + std::to_string(i);
    double a = 2 * CV_PI * i / lights;
    cv::Vec3d pos(0.47 * std::cos(a), 0.47 * std::sin(a), 1.0);
    l.position_m = pos;
    l.direction = pos / cv::norm(pos);
    l.intensity = cv::Vec3f(1.0f, 0.9f + 0.01f * i, 0.8f);
    set.lights.push_back(l);
    cv::Mat im(size, CV_32FC3);
    rng.fill(im, cv::RNG::UNIFORM, cv::Scalar::all(0.0), cv::Scalar::all(1.0));
    set.images.push_back(im);
  }
  set.ambient = cv::Mat(size, CV_32FC3);
  rng.fill(set.ambient, cv::RNG::UNIFORM, cv::Scalar::all(0.0), cv::Scalar::all(0.05));
  set.mask = cv::Mat::zeros(size, CV_8UC1);
  cv::circle(set.mask, {size.width / 2, size.height / 2}, size.height / 3, cv::Scalar(255), -1);
  if (truth) {
    set.truth.normals = cv::Mat(size, CV_32FC3);
    rng.fill(set.truth.normals, cv::RNG::UNIFORM, cv::Scalar::all(-1.0), cv::Scalar::all(1.0));
    set.truth.mask = set.mask.clone();
    set.truth.albedo = cv::Mat(size, CV_32FC3);
    rng.fill(set.truth.albedo, cv::RNG::UNIFORM, cv::Scalar::all(0.0), cv::Scalar::all(1.0));
    set.truth.depth = cv::Mat(size, CV_32FC1);
    rng.fill(set.truth.depth, cv::RNG::UNIFORM, cv::Scalar::all(0.9), cv::Scalar::all(1.1));
  }
  return set;
}

}  // namespace veneer::test
