// Image sets: veneer-set/1 round trips, atomic writes, DiLiGenT and thesis
// imports, and one clear error (naming the file) for every kind of bad input.
#include <csignal>
#include <cstdio>
#include <functional>
#include <thread>

#include <sys/resource.h>
#include <sys/wait.h>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "test_util.hpp"
#include "veneer/io/image_io.hpp"
#include "veneer/io/imageset.hpp"

namespace veneer {
namespace {
namespace fs = std::filesystem;
using nlohmann::json;
using test::Scratch;
using test::slurp;
using test::spit;
using test::synthetic_set;

constexpr double kQuant = 0.5 / 65535 + 1e-7;

// Names in `dir` that are not `keep` (temporary leftovers).
std::vector<std::string> others(const fs::path& dir, const std::string& keep) {
  std::vector<std::string> out;
  for (const auto& e : fs::directory_iterator(dir)) {
    if (e.path().filename() != keep) out.push_back(e.path().filename().string());
  }
  return out;
}

TEST(ImageSet, RoundTripKeepsPixelsAndManifest) {
  Scratch dir;
  io::ImageSet set = synthetic_set({256, 170}, 5);
  ASSERT_TRUE(io::write_set(set, dir / "s"));
  auto back = io::read_set(dir / "s");
  ASSERT_TRUE(back) << back.message();
  EXPECT_EQ(back->id, set.id);
  EXPECT_EQ(back->role, io::Role::destination);
  EXPECT_EQ(back->object, set.object);
  EXPECT_EQ(back->created, set.created);
  EXPECT_EQ(back->size, set.size);
  EXPECT_EQ(back->scene, set.scene);
  EXPECT_EQ(back->warnings, set.warnings);
  EXPECT_EQ(back->camera.model, set.camera.model);
  EXPECT_EQ(back->camera.exposure_s, set.camera.exposure_s);
  EXPECT_EQ(back->camera.aperture, set.camera.aperture);
  EXPECT_EQ(back->camera.iso, set.camera.iso);
  EXPECT_EQ(back->camera.focal_px, set.camera.focal_px);
  EXPECT_EQ(back->camera.cx, set.camera.cx);
  ASSERT_EQ(back->lights.size(), 5u);
  for (size_t i = 0; i < 5; ++i) {
    const io::Light &a = set.lights[i], &b = back->lights[i];
    EXPECT_EQ(b.index, static_cast<int>(i));
    EXPECT_EQ(b.lamp_id, a.lamp_id);
    ASSERT_TRUE(b.position_m.has_value());
    EXPECT_LT(cv::norm(*b.position_m - *a.position_m), 1e-12);
    EXPECT_LT(cv::norm(b.direction - a.direction), 1e-12);
    EXPECT_LT(cv::norm(b.intensity - a.intensity), 1e-6);
    EXPECT_LE(cv::norm(back->images[i], set.images[i], cv::NORM_INF), kQuant) << "image " << i;
  }
  EXPECT_LE(cv::norm(back->ambient, set.ambient, cv::NORM_INF), kQuant);
  EXPECT_EQ(cv::norm(back->mask, set.mask, cv::NORM_INF), 0.0);
  ASSERT_TRUE(back->truth.present());
  EXPECT_EQ(cv::norm(back->truth.normals, set.truth.normals, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(back->truth.depth, set.truth.depth, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(back->truth.mask, set.truth.mask, cv::NORM_INF), 0.0);
  EXPECT_LE(cv::norm(back->truth.albedo, set.truth.albedo, cv::NORM_INF), kQuant);

  // the truth's geometry only: normals and mask, no albedo or depth decoded
  io::ReadOptions geometry;
  geometry.load_truth_appearance = false;
  auto shape = io::read_set(dir / "s", geometry);
  ASSERT_TRUE(shape);
  EXPECT_EQ(cv::norm(shape->truth.normals, set.truth.normals, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(shape->truth.mask, set.truth.mask, cv::NORM_INF), 0.0);
  EXPECT_TRUE(shape->truth.albedo.empty());
  EXPECT_TRUE(shape->truth.depth.empty());

  io::ReadOptions without_truth;
  without_truth.load_truth = false;
  auto no_truth = io::read_set(dir / "s", without_truth);
  ASSERT_TRUE(no_truth);
  EXPECT_FALSE(no_truth->truth.present());
}

TEST(ImageSet, ManifestOnDiskHasTheDesignFields) {
  Scratch dir;
  io::ImageSet set = synthetic_set({32, 24}, 3);
  ASSERT_TRUE(io::write_set(set, dir / "s"));
  for (const char* f : {"set.json", "light_00.png", "light_01.png", "light_02.png", "ambient.png", "mask.png",
                        "truth/normals.pfm", "truth/mask.png", "truth/albedo.png", "truth/depth.pfm"})
    EXPECT_TRUE(fs::exists(dir / "s" / f)) << f;
  json j = json::parse(slurp(dir / "s" / "set.json"));
  EXPECT_EQ(j["format"], "veneer-set/1");
  EXPECT_EQ(j["role"], "destination");
  EXPECT_EQ(j["size"], json::array({32, 24}));
  EXPECT_EQ(j["camera"]["iso"], 200);
  EXPECT_EQ(j["camera"]["focal_px"], 900.0);
  EXPECT_EQ(j["lights"].size(), 3u);
  EXPECT_EQ(j["lights"][1]["lamp_id"], "sim-1");
  EXPECT_EQ(j["lights"][1]["position_m"].size(), 3u);
  EXPECT_EQ(j["images"][2], (json{{"light", 2}, {"file", "light_02.png"}}));
  EXPECT_EQ(j["ambient"], "ambient.png");
  // 16-bit linear RGB on disk.
  EXPECT_EQ(cv::imread((dir / "s" / "light_00.png").string(), cv::IMREAD_UNCHANGED).type(), CV_16UC3);
  // The truth normals are x,y,z in the file's R,G,B slots.
  auto raw = io::read_pfm(dir / "s" / "truth/normals.pfm", false);
  ASSERT_TRUE(raw);
  EXPECT_EQ(raw->at<cv::Vec3f>(3, 4)[2], set.truth.normals.at<cv::Vec3f>(3, 4)[0]);
}

TEST(ImageSet, TextFieldsWithBracketsQuotesAndUnicodeSurvive) {
  Scratch dir;
  io::ImageSet set = synthetic_set({16, 12}, 3, 1, false);
  set.lights[0].lamp_id = "hue [3, 4] \"left\" \\ back";
  set.object = "tasse \u00e0 caf\u00e9 [blue]";
  set.warnings = {"[", "]", "{\"x\": [1, 2]}"};
  ASSERT_TRUE(io::write_set(set, dir / "s"));
  auto back = io::read_set(dir / "s");
  ASSERT_TRUE(back) << back.message();
  EXPECT_EQ(back->lights[0].lamp_id, set.lights[0].lamp_id);
  EXPECT_EQ(back->object, set.object);
  EXPECT_EQ(back->warnings, set.warnings);
  // Number arrays are written on one line.
  EXPECT_NE(slurp(dir / "s" / "set.json").find("\"size\": [16, 12]"), std::string::npos);
}

TEST(ImageSet, WritesFillCreatedAndIdAndOmitEmptyParts) {
  Scratch dir;
  io::ImageSet set = synthetic_set({16, 12}, 3, 1, false);
  set.created.clear();
  set.id.clear();
  set.ambient = cv::Mat();
  set.mask = cv::Mat();
  ASSERT_TRUE(io::write_set(set, dir / "plain"));
  EXPECT_FALSE(fs::exists(dir / "plain" / "truth"));
  EXPECT_FALSE(fs::exists(dir / "plain" / "ambient.png"));
  auto back = io::read_set(dir / "plain");
  ASSERT_TRUE(back) << back.message();
  EXPECT_EQ(back->id, "plain");
  ASSERT_EQ(back->created.size(), 20u);  // 2026-01-02T03:04:05Z
  EXPECT_EQ(back->created.back(), 'Z');
  EXPECT_TRUE(back->ambient.empty());
}

TEST(ImageSet, RefusesToOverwriteUnlessAskedThenSwaps) {
  Scratch dir;
  io::ImageSet a = synthetic_set({16, 12}, 3, 1);
  io::ImageSet b = synthetic_set({16, 12}, 4, 2);
  ASSERT_TRUE(io::write_set(a, dir / "s"));
  auto refused = io::write_set(b, dir / "s");
  ASSERT_FALSE(refused);
  EXPECT_NE(refused.message().find("already exists"), std::string::npos);
  EXPECT_EQ(io::read_set(dir / "s")->lights.size(), 3u);
  ASSERT_TRUE(io::write_set(b, dir / "s", true));
  auto back = io::read_set(dir / "s");
  ASSERT_TRUE(back);
  EXPECT_EQ(back->lights.size(), 4u);
  EXPECT_TRUE(others(dir.path(), "s").empty());
}

// Writes with the process's file-size limit at `limit` bytes: writes past it fail (EFBIG).
Status write_with_file_limit(const io::ImageSet& set, const fs::path& folder, rlim_t limit, bool overwrite) {
  rlimit old{};
  getrlimit(RLIMIT_FSIZE, &old);
  auto old_handler = std::signal(SIGXFSZ, SIG_IGN);
  rlimit low = old;
  low.rlim_cur = limit;
  setrlimit(RLIMIT_FSIZE, &low);
  Status s = io::write_set(set, folder, overwrite);
  setrlimit(RLIMIT_FSIZE, &old);
  std::signal(SIGXFSZ, old_handler);
  return s;
}

TEST(ImageSet, FailedWriteLeavesNoFolderAndNoTemporary) {
  Scratch dir;
  // Flat images compress to a few hundred bytes; light 2 is noise and does not
  // fit under the limit, so the write fails midway, after light 0 and 1.
  io::ImageSet set = synthetic_set({96, 64}, 4, 9, false);
  for (size_t i = 0; i < set.images.size(); ++i) {
    if (i != 2) set.images[i].setTo(cv::Scalar::all(0.25));
  }
  set.ambient = cv::Mat();
  auto s = write_with_file_limit(set, dir / "s", 8000, false);
  ASSERT_FALSE(s);
  EXPECT_NE(s.message().find("light_02.png"), std::string::npos) << s.message();
  EXPECT_FALSE(fs::exists(dir / "s"));
  EXPECT_TRUE(others(dir.path(), "").empty());

  // The same failure while overwriting keeps the old set intact.
  io::ImageSet old = synthetic_set({16, 12}, 3, 1, false);
  ASSERT_TRUE(io::write_set(old, dir / "s"));
  auto s2 = write_with_file_limit(set, dir / "s", 8000, true);
  ASSERT_FALSE(s2);
  auto still = io::read_set(dir / "s");
  ASSERT_TRUE(still) << still.message();
  EXPECT_EQ(still->lights.size(), 3u);
  EXPECT_TRUE(others(dir.path(), "s").empty());
}

TEST(ImageSet, ConcurrentWritersOfOneFolderOneWins) {
  Scratch dir;
  io::ImageSet a = synthetic_set({32, 24}, 3, 1, false), b = synthetic_set({32, 24}, 4, 2, false);
  Status sa, sb;
  std::thread ta([&] { sa = io::write_set(a, dir / "s"); });
  std::thread tb([&] { sb = io::write_set(b, dir / "s"); });
  ta.join();
  tb.join();
  EXPECT_NE(sa.ok(), sb.ok()) << "exactly one writer must win";
  const Status& lost = sa.ok() ? sb : sa;
  if (!lost.ok()) {
    EXPECT_NE(lost.message().find("already exists"), std::string::npos) << lost.message();
  }
  auto back = io::read_set(dir / "s");
  ASSERT_TRUE(back) << back.message();
  EXPECT_EQ(back->lights.size(), sa.ok() ? 3u : 4u);
  EXPECT_TRUE(others(dir.path(), "s").empty());
}

TEST(ImageSet, StaleTemporaryOfADeadWriterIsCleaned) {
  Scratch dir;
  // A pid above the kernel's maximum (2^22) belongs to no process.
  fs::create_directories(dir / ".s.tmp-2147483000-0" / "truth");
  fs::create_directories(dir / ".other.tmp-2147483000-0");
  ASSERT_TRUE(io::write_set(synthetic_set({16, 12}, 3, 1, false), dir / "s"));
  EXPECT_FALSE(fs::exists(dir / ".s.tmp-2147483000-0"));
  EXPECT_TRUE(fs::exists(dir / ".other.tmp-2147483000-0"));  // not ours to touch
}

TEST(ImageSet, ValidateAndWriteRefuseBadInMemorySets) {
  Scratch dir;
  struct Case {
    std::function<void(io::ImageSet&)> spoil;
    std::string expect;
  };
  std::vector<Case> cases = {
      {[](io::ImageSet& s) { s.lights[1].direction = cv::Vec3d(std::nan(""), 0, 1); }, "light 1"},
      {[](io::ImageSet& s) { s.lights[1].direction = cv::Vec3d(0, 0, 2); }, "unit"},
      {[](io::ImageSet& s) { s.lights[2].intensity[0] = std::nanf(""); }, "light 2"},
      {[](io::ImageSet& s) { s.lights[0].position_m = cv::Vec3d(INFINITY, 0, 1); }, "position_m"},
      {[](io::ImageSet& s) { s.images.pop_back(); }, "3 lights but 2 images"},
      {[](io::ImageSet& s) { s.images[1] = cv::Mat(5, 5, CV_32FC3); }, "image 1"},
      {[](io::ImageSet& s) { s.images[1].convertTo(s.images[1], CV_16UC3); }, "CV_32FC3"},
      {[](io::ImageSet& s) { s.lights[2].index = 7; }, "index"},
      {[](io::ImageSet& s) { s.size = {0, 12}; }, "size"},
      {[](io::ImageSet& s) { s.mask = cv::Mat(12, 16, CV_32FC1); }, "mask"},
      {[](io::ImageSet& s) { s.truth.depth = cv::Mat(12, 16, CV_32FC3); }, "truth depth"},
      {[](io::ImageSet& s) { s.lights.clear(); s.images.clear(); }, "no lights"},
  };
  for (const Case& c : cases) {
    io::ImageSet set = synthetic_set({16, 12}, 3, 1);
    c.spoil(set);
    auto v = io::validate(set);
    ASSERT_FALSE(v) << c.expect;
    EXPECT_NE(v.message().find(c.expect), std::string::npos) << v.message();
    auto w = io::write_set(set, dir / "s");
    ASSERT_FALSE(w);
    EXPECT_FALSE(fs::exists(dir / "s"));
  }
  EXPECT_TRUE(io::validate(synthetic_set({16, 12}, 3, 1)));
}

// --- bad veneer sets: each produces one error naming the file ---------------------

class BadVeneerSet : public ::testing::Test {
 protected:
  void SetUp() override { ASSERT_TRUE(io::write_set(synthetic_set({32, 24}, 4, 3), folder())); }
  fs::path folder() const { return dir_ / "s"; }
  json manifest() const { return json::parse(slurp(folder() / "set.json")); }
  void set_manifest(const json& j) const { spit(folder() / "set.json", j.dump()); }
  // read_set fails, and the message contains every one of `parts`.
  void expect_error(std::initializer_list<std::string> parts) const {
    auto r = io::read_set(folder());
    ASSERT_FALSE(r) << "read_set accepted a bad set";
    for (const auto& p : parts) EXPECT_NE(r.message().find(p), std::string::npos) << "'" << p << "' not in: " << r.message();
  }
  Scratch dir_;
};

TEST_F(BadVeneerSet, MissingImage) {
  fs::remove(folder() / "light_02.png");
  expect_error({"light_02.png", "not found"});
}

TEST_F(BadVeneerSet, ImageOfADifferentSize) {
  ASSERT_TRUE(io::write_png16(folder() / "light_01.png", cv::Mat(20, 30, CV_32FC3, cv::Scalar::all(0.5))));
  expect_error({"light_01.png", "30x20", "32x24"});
}

TEST_F(BadVeneerSet, ManifestListsMoreLightsThanImages) {
  json j = manifest();
  j["images"].erase(3);
  set_manifest(j);
  expect_error({"set.json", "4 lights but 3 images"});
}

TEST_F(BadVeneerSet, ManifestImageForAMissingLight) {
  json j = manifest();
  j["images"][3]["light"] = 9;
  set_manifest(j);
  expect_error({"set.json", "light 9"});
}

TEST_F(BadVeneerSet, TruncatedPng) {
  std::string bytes = slurp(folder() / "light_03.png");
  spit(folder() / "light_03.png", bytes.substr(0, bytes.size() * 2 / 3));
  expect_error({"light_03.png", "truncated"});
}

TEST_F(BadVeneerSet, CorruptPng) {
  spit(folder() / "light_00.png", "this is not a picture at all");
  expect_error({"light_00.png", "not a PNG"});
}

TEST_F(BadVeneerSet, CorruptAmbientAndTruth) {
  spit(folder() / "ambient.png", "");
  expect_error({"ambient.png", "empty"});
  ASSERT_TRUE(io::write_png16(folder() / "ambient.png", cv::Mat(24, 32, CV_32FC3, cv::Scalar::all(0))));
  std::string pfm = slurp(folder() / "truth" / "normals.pfm");
  spit(folder() / "truth" / "normals.pfm", pfm.substr(0, 100));
  expect_error({"normals.pfm", "truncated"});
}

TEST_F(BadVeneerSet, NonUnitLightDirection) {
  json j = manifest();
  j["lights"][2]["direction"] = json::array({0.5, 0.0, 0.5});
  set_manifest(j);
  expect_error({"set.json", "light 2", "unit"});
}

TEST_F(BadVeneerSet, NonFiniteLightValues) {
  // JSON has no NaN; an overflowing literal is how a non-finite number would
  // get in, and the parser refuses it, naming the file and the literal.
  json j = manifest();
  j["lights"][0]["direction"] = json::array({7.0, 0.0, 0.0});
  std::string text = j.dump();
  auto d = text.find("[7.0,0.0,0.0]");
  ASSERT_NE(d, std::string::npos);
  text.replace(d, 13, "[1e999,0.0,0.0]");
  spit(folder() / "set.json", text);
  expect_error({"set.json", "1e999"});
  // A null where a number belongs.
  j["lights"][1]["intensity"] = json::array({1.0, nullptr, 1.0});
  j["lights"][0]["direction"] = json::array({0.0, 0.0, 1.0});
  set_manifest(j);
  expect_error({"set.json", "light 1", "intensity"});
}

TEST_F(BadVeneerSet, MalformedJson) {
  std::string text = slurp(folder() / "set.json");
  spit(folder() / "set.json", text.substr(0, text.size() / 2));
  expect_error({"set.json", "malformed JSON"});
}

TEST_F(BadVeneerSet, WrongFormatString) {
  json j = manifest();
  j["format"] = "veneer-set/2";
  set_manifest(j);
  expect_error({"set.json", "veneer-set/2", "veneer-set/1"});
}

TEST_F(BadVeneerSet, ZeroAndNegativeSize) {
  json j = manifest();
  j["size"] = json::array({0, 24});
  set_manifest(j);
  expect_error({"set.json", "size"});
  j["size"] = json::array({32, -24});
  set_manifest(j);
  expect_error({"set.json", "size"});
  j["size"] = json::array({32.5, 24});
  set_manifest(j);
  expect_error({"set.json", "size"});
}

TEST_F(BadVeneerSet, SizeThatDisagreesWithTheImages) {
  json j = manifest();
  j["size"] = json::array({33, 24});
  set_manifest(j);
  expect_error({"light_00.png", "32x24", "33x24"});
}

TEST_F(BadVeneerSet, DuplicateLightIndex) {
  json j = manifest();
  j["lights"][3]["index"] = 1;
  set_manifest(j);
  expect_error({"set.json", "duplicate light index 1"});
}

TEST_F(BadVeneerSet, GapInLightIndices) {
  json j = manifest();
  j["lights"][3]["index"] = 5;
  j["images"][3]["light"] = 5;
  set_manifest(j);
  expect_error({"set.json", "light 3 is missing"});
}

TEST_F(BadVeneerSet, FileOutsideTheSet) {
  json j = manifest();
  j["images"][0]["file"] = "../elsewhere.png";
  set_manifest(j);
  expect_error({"set.json", "leaves the set folder"});
  j["images"][0]["file"] = "/etc/passwd";
  set_manifest(j);
  expect_error({"set.json", "absolute"});
}

TEST_F(BadVeneerSet, WrongTypesAndMissingFields) {
  const json original = manifest();
  for (auto [key, value, expect] : std::vector<std::tuple<std::string, json, std::string>>{
           {"lights", json::array(), "lights"},
           {"lights", "many", "lights"},
           {"images", nullptr, "images"},
           {"role", "target", "role"},
           {"camera", json::array({1}), "camera"},
           {"warnings", json::array({1}), "warnings"},
       }) {
    json j = original;
    j[key] = value;
    set_manifest(j);
    expect_error({"set.json", expect});
  }
  json j = original;
  j.erase("size");
  set_manifest(j);
  expect_error({"set.json", "missing field \"size\""});
  spit(folder() / "set.json", "[1,2,3]");
  expect_error({"set.json", "object"});
}

TEST_F(BadVeneerSet, ParseManifestNeedsNoFiles) {
  auto m = io::parse_manifest(slurp(folder() / "set.json"), "/nowhere/at/all");
  ASSERT_TRUE(m) << m.message();
  EXPECT_EQ(m->image_files.size(), 4u);
  EXPECT_EQ(m->image_files[1], "light_01.png");
  EXPECT_EQ(m->ambient_file, "ambient.png");
  EXPECT_TRUE(m->set.images.empty());
  // manifest_json of a read set parses back to the same lights.
  auto set = io::read_set(folder());
  ASSERT_TRUE(set);
  auto again = io::parse_manifest(io::manifest_json(*set), "/x");
  ASSERT_TRUE(again) << again.message();
  EXPECT_EQ(again->set.lights.size(), 4u);
  EXPECT_EQ(again->set.lights[3].direction, set->lights[3].direction);
}

// --- DiLiGenT --------------------------------------------------------------------

fs::path real_set(const char* name) { return fs::path(VENEER_SHARED_DATA) / "real" / name; }

TEST(DiLiGenT, ImportsTheRealCatSet) {
  if (!fs::exists(real_set("cat") / "filenames.txt")) GTEST_SKIP() << "no " << real_set("cat");
  auto set = io::read_set(real_set("cat"));
  ASSERT_TRUE(set) << set.message();
  EXPECT_EQ(set->lights.size(), 12u);
  EXPECT_EQ(set->images.size(), 12u);
  EXPECT_EQ(set->size, cv::Size(512, 340));
  ASSERT_FALSE(set->mask.empty());
  EXPECT_EQ(set->mask.type(), CV_8UC1);
  const double object = cv::countNonZero(set->mask) / static_cast<double>(set->mask.total());
  EXPECT_GT(object, 0.1);
  EXPECT_LT(object, 0.9);
  for (size_t i = 0; i < set->lights.size(); ++i) {
    EXPECT_EQ(set->lights[i].index, static_cast<int>(i));
    EXPECT_NEAR(cv::norm(set->lights[i].direction), 1.0, 1e-3);
    EXPECT_GT(set->lights[i].direction[2], 0.0);  // lamps are on the camera's side
    EXPECT_EQ(set->lights[i].intensity, cv::Vec3f(1, 1, 1));
    // Lit object pixels are brighter than the background.
    cv::Scalar inside = cv::mean(set->images[i], set->mask);
    EXPECT_GT(inside[0] + inside[1] + inside[2], 0.05) << "image " << i;
  }
  EXPECT_EQ(set->lights[0].direction, cv::Vec3d(0.403259, 0.480808, 0.778592));
  EXPECT_EQ(set->lights[0].lamp_id, "001");
  EXPECT_EQ(set->object, "cat");
  EXPECT_EQ(set->role, io::Role::unknown);
}

TEST(DiLiGenT, ImportsChromeAndConvertsToAVeneerSet) {
  if (!fs::exists(real_set("chrome") / "filenames.txt")) GTEST_SKIP() << "no " << real_set("chrome");
  Scratch dir;
  auto set = io::read_set(real_set("chrome"));
  ASSERT_TRUE(set) << set.message();
  ASSERT_TRUE(io::write_set(*set, dir / "chrome"));
  auto back = io::read_set(dir / "chrome");
  ASSERT_TRUE(back) << back.message();
  EXPECT_EQ(back->lights.size(), 12u);
  EXPECT_EQ(cv::norm(back->mask, set->mask, cv::NORM_INF), 0.0);
  // 8-bit values survive 16-bit storage exactly (k/255 is a multiple of 257/65535).
  EXPECT_LE(cv::norm(back->images[5], set->images[5], cv::NORM_INF), 1e-6);
}

class BadDiLiGenT : public ::testing::Test {
 protected:
  void SetUp() override {
    cv::Mat im(24, 32, CV_8UC3, cv::Scalar(40, 80, 120));
    std::string names, dirs, ints;
    for (int i = 1; i <= 4; ++i) {
      char name[16];
      std::snprintf(name, sizeof name, "%03d.png", i);
      cv::imwrite((dir_ / name).string(), im);
      names += std::string(name) + "\n";
      ints += "1 1 1\n";
    }
    dirs = "0 0 1\n0.6 0 0.8\n0 0.6 0.8\n-0.6 0 0.8\n";
    spit(dir_ / "filenames.txt", names);
    spit(dir_ / "light_directions.txt", dirs);
    spit(dir_ / "light_intensities.txt", ints);
    cv::imwrite((dir_ / "mask.png").string(), cv::Mat(24, 32, CV_8UC1, cv::Scalar(255)));
  }
  void expect_error(std::initializer_list<std::string> parts) const {
    auto r = io::read_set(dir_.path());
    ASSERT_FALSE(r) << "read_set accepted a bad set";
    for (const auto& p : parts) EXPECT_NE(r.message().find(p), std::string::npos) << "'" << p << "' not in: " << r.message();
  }
  Scratch dir_;
};

TEST_F(BadDiLiGenT, GoodFolderReads) {
  auto r = io::read_set(dir_.path());
  ASSERT_TRUE(r) << r.message();
  EXPECT_EQ(r->lights.size(), 4u);
  EXPECT_NEAR(r->images[0].at<cv::Vec3f>(0, 0)[2], 120.0f / 255, 1e-6);
}

TEST_F(BadDiLiGenT, MissingImage) {
  fs::remove(dir_ / "003.png");
  expect_error({"003.png", "not found"});
}

TEST_F(BadDiLiGenT, ImagesOfDifferentSizes) {
  cv::imwrite((dir_ / "002.png").string(), cv::Mat(10, 10, CV_8UC3, cv::Scalar::all(9)));
  expect_error({"002.png", "10x10", "32x24"});
}

TEST_F(BadDiLiGenT, FewerDirectionsThanImages) {
  spit(dir_ / "light_directions.txt", "0 0 1\n0.6 0 0.8\n0 0.6 0.8\n");
  expect_error({"light_directions.txt", "3 directions", "4 images"});
}

TEST_F(BadDiLiGenT, IntensityCountDisagrees) {
  spit(dir_ / "light_intensities.txt", "1 1 1\n");
  expect_error({"light_intensities.txt", "1 intensities"});
}

TEST_F(BadDiLiGenT, NonUnitDirection) {
  spit(dir_ / "light_directions.txt", "0 0 1\n0.6 0 0.8\n0 0.5 0.8\n-0.6 0 0.8\n");
  expect_error({"light_directions.txt", "line 3", "unit"});
}

TEST_F(BadDiLiGenT, NearlyUnitDirectionIsAccepted) {
  spit(dir_ / "light_directions.txt", "0 0 1.0004\n0.6 0 0.8\n0 0.6 0.8\n-0.6 0 0.8\n");
  EXPECT_TRUE(io::read_set(dir_.path()));
}

TEST_F(BadDiLiGenT, NaNDirection) {
  spit(dir_ / "light_directions.txt", "0 0 1\nnan 0 0.8\n0 0.6 0.8\n-0.6 0 0.8\n");
  expect_error({"light_directions.txt", "line 2", "not finite"});
}

TEST_F(BadDiLiGenT, GarbageDirectionLine) {
  spit(dir_ / "light_directions.txt", "0 0 1\n0.6 0 zero\n0 0.6 0.8\n-0.6 0 0.8\n");
  expect_error({"light_directions.txt", "line 2"});
}

TEST_F(BadDiLiGenT, NegativeIntensity) {
  spit(dir_ / "light_intensities.txt", "1 1 1\n1 -1 1\n1 1 1\n1 1 1\n");
  expect_error({"light_intensities.txt", "line 2", "negative"});
}

TEST_F(BadDiLiGenT, TruncatedPngAndMask) {
  std::string bytes = slurp(dir_ / "004.png");
  spit(dir_ / "004.png", bytes.substr(0, bytes.size() - 20));
  expect_error({"004.png", "truncated"});
  spit(dir_ / "004.png", bytes);
  cv::imwrite((dir_ / "mask.png").string(), cv::Mat(5, 5, CV_8UC1, cv::Scalar(255)));
  expect_error({"mask.png", "5x5"});
}

TEST_F(BadDiLiGenT, FileNameLeavingTheFolder) {
  spit(dir_ / "filenames.txt", "001.png\n../002.png\n003.png\n004.png\n");
  expect_error({"filenames.txt", "line 2"});
}

// --- thesis layout -------------------------------------------------------------

TEST(Thesis, ReadsNumberedPpmAndPfmWithLightsAndNormals) {
  Scratch dir;
  const cv::Size size(20, 10);
  // Images 1..3 as 16-bit PPM, 4 as PFM; numbering with and without leading zeros.
  for (int i = 1; i <= 3; ++i) {
    cv::Mat u16(size, CV_16UC3, cv::Scalar(1000 * i, 2000 * i, 3000 * i));  // BGR in memory
    cv::imwrite((dir / (i == 1 ? "1.ppm" : "0" + std::to_string(i) + ".ppm")).string(), u16);
  }
  cv::Mat f(size, CV_32FC3, cv::Scalar(0.25, 0.5, 0.75));
  ASSERT_TRUE(io::write_pfm(dir / "4.pfm", f, false));
  spit(dir / "lights.txt", "# thesis rig\n0 0 1\n0.6 0 0.8  2 2 2\n0 0.6 0.8\n\n0 -0.6 0.8\n");
  cv::imwrite((dir / "mask.pgm").string(), cv::Mat(size, CV_8UC1, cv::Scalar(255)));
  cv::Mat n(size, CV_32FC3, cv::Scalar(0, 0, 1));
  ASSERT_TRUE(io::write_pfm(dir / "normals.pfm", n, true));
  spit(dir / "notes.txt", "not an image");

  auto set = io::read_set(dir.path());
  ASSERT_TRUE(set) << set.message();
  ASSERT_EQ(set->lights.size(), 4u);
  EXPECT_EQ(set->size, size);
  EXPECT_EQ(set->lights[1].direction, cv::Vec3d(0.6, 0, 0.8));
  EXPECT_EQ(set->lights[1].intensity, cv::Vec3f(2, 2, 2));
  EXPECT_EQ(set->lights[3].lamp_id, "4");
  EXPECT_NEAR(set->images[1].at<cv::Vec3f>(0, 0)[2], 6000.0f / 65535, 1e-6);  // "02.ppm" red
  EXPECT_NEAR(set->images[3].at<cv::Vec3f>(5, 5)[2], 0.75f, 1e-7);
  EXPECT_FALSE(set->mask.empty());
  ASSERT_TRUE(set->truth.present());
  EXPECT_EQ(set->truth.normals.at<cv::Vec3f>(2, 2), cv::Vec3f(0, 0, 1));
}

TEST(Thesis, BadFoldersNameTheProblem) {
  Scratch dir;
  auto none = io::read_set(dir.path());
  ASSERT_FALSE(none);
  EXPECT_NE(none.message().find("not an image set"), std::string::npos) << none.message();

  cv::imwrite((dir / "1.ppm").string(), cv::Mat(4, 4, CV_8UC3, cv::Scalar::all(7)));
  cv::imwrite((dir / "2.ppm").string(), cv::Mat(4, 4, CV_8UC3, cv::Scalar::all(7)));
  spit(dir / "lights.txt", "0 0 1\n0.6 0 0.8\n0 0.6 0.8\n");
  auto count = io::read_set(dir.path());
  ASSERT_FALSE(count);
  EXPECT_NE(count.message().find("lights.txt"), std::string::npos) << count.message();
  EXPECT_NE(count.message().find("3 lights"), std::string::npos) << count.message();

  cv::imwrite((dir / "3.ppm").string(), cv::Mat(5, 4, CV_8UC3, cv::Scalar::all(7)));
  auto sizes = io::read_set(dir.path());
  ASSERT_FALSE(sizes);
  EXPECT_NE(sizes.message().find("3.ppm"), std::string::npos) << sizes.message();

  cv::imwrite((dir / "03.ppm").string(), cv::Mat(4, 4, CV_8UC3, cv::Scalar::all(7)));
  auto twice = io::read_set(dir.path());
  ASSERT_FALSE(twice);
  EXPECT_NE(twice.message().find("number 3"), std::string::npos) << twice.message();

  auto missing = io::read_set(dir / "nope");
  ASSERT_FALSE(missing);
  EXPECT_NE(missing.message().find("nope"), std::string::npos);
}

}  // namespace
}  // namespace veneer

namespace veneer {
namespace {

// Runs `veneer` (when it has been built) and returns its stdout and exit code.
std::pair<std::string, int> run_veneer(const std::string& args) {
  std::string cmd = std::string(VENEER_BIN_DIR) + "/veneer " + args + " 2>&1";
  std::string out;
  FILE* pipe = ::popen(cmd.c_str(), "r");
  if (!pipe) return {"", -1};
  char buf[4096];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, pipe)) > 0) out.append(buf, n);
  int status = ::pclose(pipe);
  return {out, WIFEXITED(status) ? WEXITSTATUS(status) : -1};
}

TEST(InfoCommand, SummaryJsonAndErrors) {
  if (!fs::exists(fs::path(VENEER_BIN_DIR) / "veneer")) GTEST_SKIP() << "veneer is not built in " << VENEER_BIN_DIR;
  Scratch dir;
  io::ImageSet set = synthetic_set({32, 24}, 3, 5);
  ASSERT_TRUE(io::write_set(set, dir / "s"));
  auto [summary, rc] = run_veneer("info " + (dir / "s").string());
  EXPECT_EQ(rc, 0) << summary;
  for (const char* part : {"veneer-set/1", "destination", "32x24", "sim-2", "normals, mask, albedo, depth",
                           "ambient frame is bright"})
    EXPECT_NE(summary.find(part), std::string::npos) << part << " not in:\n" << summary;
  auto [manifest, rc2] = run_veneer("info --json " + (dir / "s").string());
  EXPECT_EQ(rc2, 0);
  EXPECT_EQ(manifest, slurp(dir / "s" / "set.json"));
  fs::remove(dir / "s" / "light_01.png");
  auto [error, rc3] = run_veneer("info " + (dir / "s").string());
  EXPECT_EQ(rc3, 1);
  EXPECT_EQ(error.rfind("veneer info: ", 0), 0u) << error;
  EXPECT_NE(error.find("light_01.png"), std::string::npos) << error;
}

}  // namespace
}  // namespace veneer
