// bench_io: loading and writing an image set of 8 16-bit PNGs at 1024x680,
// against plain OpenCV (cv::imread / cv::imwrite of the same files) measured
// in the same run. Prints a markdown table; never fails on a number.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include <fcntl.h>
#include <unistd.h>

#include <opencv2/core/utility.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "veneer/io/imageset.hpp"

namespace fs = std::filesystem;
using veneer::io::ImageSet;

namespace {

double median_ms(int repeats, const std::function<void()>& fn) {
  std::vector<double> ms;
  for (int i = 0; i < repeats; ++i) {
    auto t0 = std::chrono::steady_clock::now();
    fn();
    ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  }
  std::sort(ms.begin(), ms.end());
  return ms[ms.size() / 2];
}

// Smooth shading times a textured albedo plus sensor noise: compresses like a photo.
ImageSet make_set(cv::Size size, int lights) {
  cv::RNG rng(42);
  ImageSet set;
  set.id = "bench";
  set.object = "synthetic";
  set.size = size;
  cv::Mat albedo(size, CV_32FC3);
  rng.fill(albedo, cv::RNG::UNIFORM, cv::Scalar::all(0.3), cv::Scalar::all(0.9));
  cv::GaussianBlur(albedo, albedo, {0, 0}, 3.0);
  for (int i = 0; i < lights; ++i) {
    veneer::io::Light l;
    l.index = i;
    double a = 2 * CV_PI * i / lights;
    cv::Vec3d p(0.47 * std::cos(a), 0.47 * std::sin(a), 1.0);
    l.position_m = p;
    l.direction = p / cv::norm(p);
    set.lights.push_back(l);
    cv::Mat im(size, CV_32FC3);
    for (int y = 0; y < size.height; ++y) {
      auto* row = im.ptr<cv::Vec3f>(y);
      for (int x = 0; x < size.width; ++x) {
        double nx = (x - size.width / 2.0) / size.width, ny = (size.height / 2.0 - y) / size.height;
        float shade = static_cast<float>(std::max(0.0, l.direction[0] * nx + l.direction[1] * ny + l.direction[2] * 0.7));
        row[x] = albedo.at<cv::Vec3f>(y, x) * shade;
      }
    }
    cv::Mat noise(size, CV_32FC3);
    rng.fill(noise, cv::RNG::NORMAL, cv::Scalar::all(0), cv::Scalar::all(0.005));
    set.images.push_back(im + noise);
  }
  return set;
}

}  // namespace

int main() {
  const cv::Size size(1024, 680);
  const int lights = 8;
  const int repeats = 5;
  fs::path root = fs::temp_directory_path() / (std::string("veneer-bench-io-").append(std::to_string(::getpid())));
  fs::remove_all(root);
  fs::create_directories(root);
  ImageSet set = make_set(size, lights);

  int n = 0;
  double write_ms = median_ms(repeats, [&] {
    fs::path out = root / (std::string("w").append(std::to_string(n++)));
    if (auto s = veneer::io::write_set(set, out); !s) std::fprintf(stderr, "write_set: %s\n", s.message().c_str());
  });
  const fs::path folder = root / "w0";
  std::vector<cv::Mat> u16;
  for (const auto& im : set.images) {
    cv::Mat u;
    im.convertTo(u, CV_16UC3, 65535.0);
    u16.push_back(u);
  }
  fs::create_directories(root / "cv");
  double imwrite_ms = median_ms(repeats, [&] {
    for (int i = 0; i < lights; ++i) cv::imwrite((root / "cv" / (std::to_string(i) + ".png")).string(), u16[static_cast<size_t>(i)]);
  });

  double imwrite_sync_ms = median_ms(repeats, [&] {
    for (int i = 0; i < lights; ++i) {
      std::string f = (root / "cv" / (std::to_string(i) + ".png")).string();
      cv::imwrite(f, u16[static_cast<size_t>(i)]);
      int fd = ::open(f.c_str(), O_RDONLY);
      if (fd >= 0) {
        ::fsync(fd);
        ::close(fd);
      }
    }
  });

  double read_ms = median_ms(repeats, [&] {
    auto r = veneer::io::read_set(folder);
    if (!r) std::fprintf(stderr, "read_set: %s\n", r.message().c_str());
  });
  std::vector<std::string> files;
  for (int i = 0; i < lights; ++i) {
    char name[32];
    std::snprintf(name, sizeof name, "light_%02d.png", i);
    files.push_back((folder / name).string());
  }
  double imread_ms = median_ms(repeats, [&] {
    for (const auto& f : files) {
      cv::Mat m = cv::imread(f, cv::IMREAD_UNCHANGED);
      if (m.empty()) std::fprintf(stderr, "imread failed: %s\n", f.c_str());
    }
  });
  double imread_float_ms = median_ms(repeats, [&] {
    for (const auto& f : files) {
      cv::Mat m = cv::imread(f, cv::IMREAD_UNCHANGED), out;
      m.convertTo(out, CV_32FC3, 1.0 / 65535);
    }
  });
  uintmax_t bytes = 0;
  for (const auto& f : files) bytes += fs::file_size(f);
  fs::remove_all(root);

  std::printf("## Image set I/O: %d lights, %dx%d, 16-bit PNG (%.1f MB on disk), %d threads, median of %d\n\n", lights,
              size.width, size.height, bytes / 1e6, cv::getNumThreads(), repeats);
  std::printf("| step | veneer | ms | peer (same run) | peer ms | veneer / peer |\n");
  std::printf("|---|---|---:|---|---:|---:|\n");
  std::printf("| load set | read_set (decode, to float, checks) | %.1f | cv::imread x%d (16-bit, no conversion) | %.1f | %.2f |\n",
              read_ms, lights, imread_ms, read_ms / imread_ms);
  std::printf("| load set | read_set | %.1f | cv::imread x%d + convertTo float | %.1f | %.2f |\n", read_ms, lights,
              imread_float_ms, read_ms / imread_float_ms);
  std::printf("| write set | write_set (encode, fsync, atomic rename) | %.1f | cv::imwrite x%d (no fsync) | %.1f | %.2f |\n",
              write_ms, lights, imwrite_ms, write_ms / imwrite_ms);
  std::printf("| write set | write_set | %.1f | cv::imwrite x%d + fsync each | %.1f | %.2f |\n", write_ms, lights,
              imwrite_sync_ms, write_ms / imwrite_sync_ms);
  return 0;
}
