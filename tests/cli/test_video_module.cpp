// `veneer` reads and writes videos through libveneer_video.so, opened only
// by `repaint --video` (viewer/cli/video/): a command without video maps no
// OpenCV videoio (nor the ffmpeg and GStreamer libraries it pulls in).
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include <sys/wait.h>

#include <gtest/gtest.h>

namespace fs = std::filesystem;

namespace {

struct Ran {
  int code = -1;
  std::string out;  // stdout and stderr together
};

Ran shell(const std::string& cmd) {
  Ran r;
  FILE* p = ::popen((cmd + " 2>&1").c_str(), "r");
  if (!p) return r;
  char buf[4096];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, p)) > 0) r.out.append(buf, n);
  const int status = ::pclose(p);
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

const std::string veneer = VENEER_BIN_DIR "/veneer";

}  // namespace

TEST(CliVideoModule, VersionAndHelpMapNoVideoio) {
  for (const std::string args : {"--version", "--help", "transfer --help"}) {
    // the dynamic loader's own account of every library it initialises
    const Ran r = shell("LD_DEBUG=libs " + veneer + " " + args);
    ASSERT_EQ(r.code, 0) << args;
    if (r.out.find("calling init:") == std::string::npos) GTEST_SKIP() << "LD_DEBUG gives no library list here";
    EXPECT_EQ(r.out.find("libopencv_videoio"), std::string::npos) << "veneer " << args << " maps videoio";
    EXPECT_EQ(r.out.find("libveneer_video"), std::string::npos) << "veneer " << args << " opens the video module";
    EXPECT_NE(r.out.find("libopencv_core"), std::string::npos) << args;  // the check sees what is mapped
  }
}

TEST(CliVideoModule, RepaintOpensVideosThroughTheModule) {
  const fs::path dir = fs::path(::testing::TempDir()) / "cli_video_module";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const fs::path fake = dir / "not_a_video.mp4";
  std::ofstream(fake) << "this is text, not a video\n";
  // the video is checked first: the module is loaded, and OpenCV's refusal comes back as a usage error
  const Ran r = shell("LD_DEBUG=libs " + veneer + " repaint --src a --dst b --map c --out " + (dir / "out").string() +
                      " --video " + fake.string());
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_NE(r.out.find("veneer repaint: --video " + fake.string() + ": OpenCV cannot read it as a video"),
            std::string::npos)
      << r.out;
  if (r.out.find("calling init:") != std::string::npos) {
    EXPECT_NE(r.out.find("libveneer_video.so"), std::string::npos);
    EXPECT_NE(r.out.find("libopencv_videoio"), std::string::npos);
  }
  EXPECT_FALSE(fs::exists(dir / "out"));
}
