// What a transfer holds: `veneer transfer` (a child process, as a user runs
// it) on a pair of moderate size peaks below a bound set by the bytes of the
// frames it reads, over the memory of a veneer process that does nothing.
// The pictures are painted and written one at a time and the photos released
// as they are: holding every repainted photo at once, or a blend plan of
// up to 25 terms a pixel, went over it (3.0x the frames' bytes at 1600x1064
// before, 2.1x after).
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "test_util.hpp"
#include "veneer/io/imageset.hpp"
#include "veneer/sim/simulator.hpp"

namespace veneer {
namespace {

using test::Scratch;

// Runs the veneer binary with `args`; its peak RSS in bytes (wait4), or -1
// when it did not exit with 0.
double peak_of(const std::vector<std::string>& args) {
  const std::string bin = std::string(VENEER_BIN_DIR) + "/veneer";
  std::vector<char*> argv{const_cast<char*>(bin.c_str())};
  for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  const pid_t pid = ::fork();
  if (pid == 0) {
    if (std::FILE* null = std::fopen("/dev/null", "w")) ::dup2(::fileno(null), 1);
    ::execv(bin.c_str(), argv.data());
    std::_Exit(127);
  }
  if (pid < 0) return -1;
  int status = 0;
  rusage u{};
  if (::wait4(pid, &status, 0, &u) != pid || !WIFEXITED(status) || WEXITSTATUS(status) != 0) return -1;
  return static_cast<double>(u.ru_maxrss) * 1024.0;
}

TEST(Pipeline, TransferPeakStaysWithinTheFramesBytes) {
#if defined(__SANITIZE_ADDRESS__)
  GTEST_SKIP() << "under AddressSanitizer the peak is its quarantine and redzones, not the program's own memory";
#endif
  Scratch dir;
  const cv::Size size(1600, 1064);
  int frames = 0;
  for (auto [scene, role, name] : {std::tuple{"bull", io::Role::destination, "dst"}, {"orange", io::Role::source, "src"}}) {
    sim::RenderOptions o;
    o.size = size;
    o.noise_sigma = 0.005;
    o.scale = 2.5;
    auto set = sim::simulate_set(scene, o, role);
    ASSERT_TRUE(set) << set.message();
    ASSERT_TRUE(io::write_set(*set, dir / name));
    frames += static_cast<int>(set->images.size()) + (set->ambient.empty() ? 0 : 1);
  }
  const double frame_bytes = frames * static_cast<double>(size.area()) * 3 * sizeof(float);
  const double idle = peak_of({"transfer", "--help"});
  ASSERT_GT(idle, 0);
  const double peak = peak_of({"transfer", "--dst", (dir / "dst").string(), "--src", (dir / "src").string(), "--out",
                               (dir / "out").string(), "--no-cache"});
  ASSERT_GT(peak, 0) << "veneer transfer failed";
  EXPECT_TRUE(std::filesystem::exists(dir / "out" / "result_light_06.png"));
  EXPECT_TRUE(std::filesystem::exists(dir / "out" / "metrics.json"));
  const double ratio = (peak - idle) / frame_bytes;
  std::printf("frames %.0f MB as float, idle %.0f MB, transfer peak %.0f MB: %.2fx the frames\n", frame_bytes / 1e6,
              idle / 1e6, peak / 1e6, ratio);
  EXPECT_LT(ratio, 2.5) << "the transfer held more than 2.5x the bytes of its frames as float";
}

}  // namespace
}  // namespace veneer
