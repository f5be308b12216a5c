// `veneer` commands report one way (viewer/cli/output.hpp): one error line
// "veneer <cmd>: ..." on stderr with exit 1 (2 for bad usage), and a closing
// "wrote <folder>: <files>" that names exactly the files that were written.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <set>
#include <sstream>
#include <string>

#include <sys/wait.h>
#include <unistd.h>

#include <gtest/gtest.h>

namespace fs = std::filesystem;

namespace {

struct Run {
  int code = -1;
  std::string out, err;
};

Run veneer(const std::string& args, const fs::path& dir) {
  const fs::path err_file = dir / "stderr.txt";
  const std::string cmd = "cd '" + dir.string() + "' && " VENEER_BIN_DIR "/veneer " + args + " 2>'" + err_file.string() + "'";
  Run r;
  FILE* p = ::popen(cmd.c_str(), "r");
  if (!p) return r;
  char buf[4096];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, p)) > 0) r.out.append(buf, n);
  const int status = ::pclose(p);
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  FILE* e = std::fopen(err_file.c_str(), "r");
  if (e) {
    while ((n = std::fread(buf, 1, sizeof buf, e)) > 0) r.err.append(buf, n);
    std::fclose(e);
  }
  return r;
}

std::string last_line(const std::string& text) {
  std::string t = text;
  while (!t.empty() && t.back() == '\n') t.pop_back();
  const auto nl = t.rfind('\n');
  return nl == std::string::npos ? t : t.substr(nl + 1);
}

class CliOutput : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("veneer-cli-output-" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

TEST_F(CliOutput, NormalsNamesExactlyTheFilesItWrote) {
  auto sim = veneer("simulate --scene orange --size 96x64 --out set --role destination", dir_);
  ASSERT_EQ(sim.code, 0) << sim.err;
  EXPECT_EQ(last_line(sim.out).rfind("wrote set: scene orange, 7 lamps + ambient, 96x64", 0), 0u) << sim.out;

  auto n = veneer("normals set --out normals", dir_);
  ASSERT_EQ(n.code, 0) << n.err;
  const std::string line = last_line(n.out);
  ASSERT_EQ(line.rfind("wrote normals: ", 0), 0u) << n.out;
  std::set<std::string> listed;
  std::istringstream files(line.substr(std::string("wrote normals: ").size()));
  for (std::string f; files >> f;) listed.insert(f);
  std::set<std::string> on_disk;
  for (const auto& e : fs::directory_iterator(dir_ / "normals")) on_disk.insert(e.path().filename().string());
  EXPECT_EQ(listed, on_disk);
  EXPECT_TRUE(listed.count("normals.pfm") && listed.count("metrics.json")) << line;
}

TEST_F(CliOutput, ErrorsAreOneLineNamingTheCommandWithExitCodes) {
  auto missing = veneer("normals no-such-set --out x", dir_);
  EXPECT_EQ(missing.code, 1);
  EXPECT_EQ(missing.err, "veneer normals: no-such-set: no such folder\n");
  EXPECT_FALSE(fs::exists(dir_ / "x")) << "no half-written output";

  auto usage = veneer("normals no-such-set", dir_);
  EXPECT_EQ(usage.code, 2);
  EXPECT_EQ(usage.err, "veneer normals: --out is required\n");

  auto info = veneer("info no-such-set", dir_);
  EXPECT_EQ(info.code, 1);
  EXPECT_EQ(info.err, "veneer info: no-such-set: no such folder\n");

  auto bad_size = veneer("simulate --scene orange --size 9x --out s", dir_);
  EXPECT_EQ(bad_size.code, 2);
  EXPECT_EQ(bad_size.err.rfind("veneer simulate: --size '9x'", 0), 0u) << bad_size.err;

  // The output folder cannot be made: the error names it.
  ASSERT_EQ(veneer("simulate --scene orange --size 64x48 --motion rotate=5 --frames 1 --out m", dir_).code, 0);
  { std::FILE* f = std::fopen((dir_ / "blocker").c_str(), "w"); ASSERT_NE(f, nullptr); std::fclose(f); }
  auto blocked = veneer("simulate --scene orange --size 64x48 --motion rotate=5 --frames 1 --out blocker/m", dir_);
  EXPECT_EQ(blocked.code, 1);
  EXPECT_EQ(blocked.err.rfind("veneer simulate: blocker/m: cannot create: ", 0), 0u) << blocked.err;
  EXPECT_EQ(std::count(blocked.err.begin(), blocked.err.end(), '\n'), 1) << blocked.err;
}

// veneer transfer --rti: the repainted destination as a PTM, its residual on
// stdout and in metrics.json; a bad --rti-format is a usage error before any work.
TEST_F(CliOutput, TransferWritesARelightableFileAndReportsItsResidual) {
  ASSERT_EQ(veneer("simulate --scene cup-white --size 96x64 --out dst --role destination", dir_).code, 0);
  ASSERT_EQ(veneer("simulate --scene orange --size 96x64 --out src --role source", dir_).code, 0);
  auto t = veneer("transfer --dst dst --src src --out out --no-cache --rti cup.ptm", dir_);
  ASSERT_EQ(t.code, 0) << t.err;
  EXPECT_NE(t.out.find("relightable file cup.ptm (PTM_FORMAT_LRGB"), std::string::npos) << t.out;
  EXPECT_NE(t.out.find("levels RMS"), std::string::npos) << t.out;
  std::FILE* f = std::fopen((dir_ / "cup.ptm").c_str(), "rb");
  ASSERT_NE(f, nullptr);
  char head[160] = {};
  const std::string text(head, std::fread(head, 1, sizeof head, f));
  std::fclose(f);
  EXPECT_EQ(text.rfind("PTM_1.2\nPTM_FORMAT_LRGB\n96 64\n", 0), 0u) << text.substr(0, 40);
  size_t header = 0;
  for (int line = 0; line < 5; ++line) header = text.find('\n', header) + 1;
  EXPECT_EQ(fs::file_size(dir_ / "cup.ptm"), header + 96u * 64u * 9u) << "five header lines, then 6 + 3 bytes per pixel";
  std::FILE* m = std::fopen((dir_ / "out" / "metrics.json").c_str(), "r");
  ASSERT_NE(m, nullptr);
  std::string metrics(1 << 20, '\0');
  metrics.resize(std::fread(metrics.data(), 1, metrics.size(), m));
  std::fclose(m);
  EXPECT_NE(metrics.find("\"residual_rms_levels\""), std::string::npos);

  auto bad = veneer("transfer --dst dst --src src --out out2 --rti x.ptm --rti-format xyz", dir_);
  EXPECT_EQ(bad.code, 2);
  EXPECT_EQ(bad.err, "veneer transfer: --rti-format must be lrgb (or ptm), rgb or hsh, got \"xyz\"\n");
  EXPECT_FALSE(fs::exists(dir_ / "out2"));
}

std::string file_text(const fs::path& file) {
  std::FILE* f = std::fopen(file.c_str(), "rb");
  if (!f) return {};
  std::string text;
  char buf[65536];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, f)) > 0) text.append(buf, n);
  std::fclose(f);
  return text;
}

// Issue 48: nothing computed that is not written. metrics.json's look (the
// per-lamp shading error, texture_corr) only with --figures, and the pictures
// the same either way.
TEST_F(CliOutput, TransferMeasuresTheLookOnlyWithFigures) {
  ASSERT_EQ(veneer("simulate --scene bull --size 96x64 --out dst --role destination", dir_).code, 0);
  ASSERT_EQ(veneer("simulate --scene orange --size 96x64 --out src --role source", dir_).code, 0);
  auto plain = veneer("transfer --dst dst --src src --out plain --no-cache", dir_);
  ASSERT_EQ(plain.code, 0) << plain.err;
  auto asked = veneer("transfer --dst dst --src src --out asked --no-cache --figures", dir_);
  ASSERT_EQ(asked.code, 0) << asked.err;
  const std::string without = file_text(dir_ / "plain" / "metrics.json"), with = file_text(dir_ / "asked" / "metrics.json");
  EXPECT_EQ(without.find("\"look\": {"), std::string::npos) << without;
  EXPECT_NE(without.find("\"quality\""), std::string::npos) << without;
  EXPECT_NE(with.find("\"look\": {"), std::string::npos) << with;
  EXPECT_NE(with.find("\"shading_mean\""), std::string::npos) << with;
  for (const char* name : {"map.pfm", "result_light_00.png", "result_light_06.png", "result_median.png", "reuse.png",
                           "confidence.png", "map.png"}) {
    const std::string a = file_text(dir_ / "plain" / name), b = file_text(dir_ / "asked" / name);
    EXPECT_FALSE(a.empty()) << name;
    EXPECT_TRUE(a == b) << name << " differs with --figures";
  }
}

// Issue 48: `veneer` starts without OpenCV's image codecs (and the ~110
// libraries they pull in); it opens them when a file needs them.
TEST_F(CliOutput, VeneerStartsWithoutOpenCVsImageCodecs) {
  const std::string cmd = "LD_TRACE_LOADED_OBJECTS=1 " VENEER_BIN_DIR "/veneer";
  FILE* p = ::popen(cmd.c_str(), "r");
  ASSERT_NE(p, nullptr);
  std::string libs;
  char buf[4096];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, p)) > 0) libs.append(buf, n);
  ::pclose(p);
  EXPECT_NE(libs.find("libopencv_core"), std::string::npos) << libs;
  EXPECT_EQ(libs.find("libopencv_imgcodecs"), std::string::npos) << libs;
  EXPECT_EQ(libs.find("libgdal"), std::string::npos) << libs;
  // a JPEG set needs them: read through the codecs opened then
  ASSERT_EQ(veneer("simulate --scene bull --size 96x64 --out dst --role destination --optics --dng", dir_).code, 0);
  ASSERT_EQ(veneer("simulate --scene orange --size 96x64 --out src --role source --optics --dng", dir_).code, 0);
  auto t = veneer("transfer --dst dst --src src --out out --no-cache --photos developed", dir_);
  ASSERT_EQ(t.code, 0) << t.err;
  EXPECT_NE(t.out.find("photos from jpeg"), std::string::npos) << t.out;
}

}  // namespace
