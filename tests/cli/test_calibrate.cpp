// cli/Calibrate.*: `veneer calibrate` on the real chrome sphere writes a
// lights file (and picture) whose directions agree with the set's, stores the
// lamps' positions in a rig config, refuses a config with another lamp count
// without writing anything; `veneer normals --lights` solves with them.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <sys/wait.h>
#include <unistd.h>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

namespace fs = std::filesystem;

namespace {

const fs::path kChrome = fs::path(VENEER_SHARED_DATA) / "real" / "chrome";
const fs::path kCat = fs::path(VENEER_SHARED_DATA) / "real" / "cat";

struct CmdRun {
  int code = -1;
  std::string out, err;
};

CmdRun veneer(const std::string& args, const fs::path& dir) {
  const fs::path err_file = dir / "stderr.txt";
  const std::string cmd =
      "cd '" + dir.string() + "' && " VENEER_BIN_DIR "/veneer " + args + " 2>'" + err_file.string() + "'";
  CmdRun r;
  FILE* p = ::popen(cmd.c_str(), "r");
  if (!p) return r;
  char buf[4096];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, p)) > 0) r.out.append(buf, n);
  const int status = ::pclose(p);
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  std::ifstream e(err_file);
  std::stringstream ss;
  ss << e.rdbuf();
  r.err = ss.str();
  return r;
}

nlohmann::json read_json(const fs::path& f) {
  std::ifstream in(f);
  return nlohmann::json::parse(in);
}

class Calibrate : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!fs::exists(kChrome / "filenames.txt")) GTEST_SKIP() << "no " << kChrome;
    dir_ = fs::temp_directory_path() / ("veneer-cli-calibrate-" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override {
    if (!dir_.empty()) fs::remove_all(dir_);
  }
  fs::path dir_;
};

TEST_F(Calibrate, WritesLightsNearTheSetsDirectionsAndARigConfig) {
  // A rig config naming 12 lamps.
  nlohmann::json cfg = {{"name", "test-rig"}, {"lamps", {{"backend", "simulated"}, {"lamps", nlohmann::json::array()}}}};
  for (int i = 0; i < 12; ++i) cfg["lamps"]["lamps"].push_back(std::to_string(i + 3));
  std::ofstream(dir_ / "veneerd.json") << cfg.dump(2);
  const CmdRun r = veneer("calibrate '" + kChrome.string() + "' --out lights.json --distance 1.5 --rig-config veneerd.json",
                       dir_);
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.out.find("mean "), std::string::npos) << r.out;
  ASSERT_TRUE(fs::exists(dir_ / "lights.png"));
  const auto lights = read_json(dir_ / "lights.json");
  ASSERT_EQ(lights["format"], "veneer-lights/1");
  ASSERT_EQ(lights["lamps"].size(), 12u);
  // Within a few degrees of light_directions.txt, lamp by lamp on average.
  std::ifstream dirs(kChrome / "light_directions.txt");
  double sum = 0;
  for (int i = 0; i < 12; ++i) {
    double x, y, z;
    ASSERT_TRUE(dirs >> x >> y >> z);
    const auto& d = lights["lamps"][i]["direction"];
    const double dot = (x * d[0].get<double>() + y * d[1].get<double>() + z * d[2].get<double>()) /
                       std::sqrt(x * x + y * y + z * z);
    sum += std::acos(std::clamp(dot, -1.0, 1.0)) * 180 / M_PI;
    const auto& p = lights["lamps"][i]["position_m"];
    EXPECT_NEAR(p[2].get<double>(), 1.5 * d[2].get<double>(), 1e-9);
  }
  EXPECT_LT(sum / 12, 3.2);
  // The rig's config now holds the positions, the rest as it was.
  const auto stored = read_json(dir_ / "veneerd.json");
  EXPECT_EQ(stored["name"], "test-rig");
  ASSERT_EQ(stored["lamps"]["positions_m"].size(), 12u);
  EXPECT_DOUBLE_EQ(stored["lamps"]["positions_m"][4][0].get<double>(),
                   lights["lamps"][4]["position_m"][0].get<double>());
}

TEST_F(Calibrate, RefusesAMismatchedRigConfigWithoutWritingAnything) {
  const std::string cfg = R"({"lamps": {"backend": "simulated", "lamps": ["1", "2", "3"]}})";
  std::ofstream(dir_ / "veneerd.json") << cfg;
  CmdRun r = veneer("calibrate '" + kChrome.string() + "' --out lights.json --distance 1 --rig-config veneerd.json", dir_);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("lamps.lamps names 3 lamps, the calibration found 12"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir_ / "lights.json"));
  EXPECT_FALSE(fs::exists(dir_ / "lights.png"));
  std::ifstream in(dir_ / "veneerd.json");
  std::stringstream ss;
  ss << in.rdbuf();
  EXPECT_EQ(ss.str(), cfg);
  // The rig's config stores positions: without a distance there are none.
  r = veneer("calibrate '" + kChrome.string() + "' --out lights.json --rig-config veneerd.json", dir_);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("--distance"), std::string::npos) << r.err;
  r = veneer("calibrate '" + kChrome.string() + "' --out lights.json --highlight 1.5", dir_);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("highlight_fraction"), std::string::npos) << r.err;
}

TEST_F(Calibrate, NormalsUseTheLightsFile) {
  if (!fs::exists(kCat / "filenames.txt")) GTEST_SKIP() << "no " << kCat;
  ASSERT_EQ(veneer("calibrate '" + kChrome.string() + "' --out lights.json", dir_).code, 0);
  CmdRun r = veneer("normals '" + kCat.string() + "' --lights lights.json --recorded-lights --out cat", dir_);
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_EQ(read_json(dir_ / "cat" / "metrics.json")["lights_file"], "lights.json");
  // A lights file for another number of lamps is refused with the reason.
  auto lights = read_json(dir_ / "lights.json");
  lights["lamps"].erase(lights["lamps"].size() - 1);
  std::ofstream(dir_ / "eleven.json") << lights.dump();
  r = veneer("normals '" + kCat.string() + "' --lights eleven.json --out cat2", dir_);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("11 directions, the set has 12 lights"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir_ / "cat2" / "normals.pfm"));
}

}  // namespace
