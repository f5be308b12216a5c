#include <gtest/gtest.h>

#include <algorithm>
#include <fstream>
#include <limits>

#include "rig_test_util.hpp"
#include "veneerd/store.hpp"

namespace fs = std::filesystem;

namespace {
veneer::io::ImageSet tiny_set(const std::string& id, veneer::io::Role role) {
  veneer::io::ImageSet s;
  s.id = id;
  s.role = role;
  s.object = "cube";
  s.created = "2026-11-22T08:00:00Z";
  s.size = {8, 6};
  for (int i = 0; i < 3; ++i) {
    veneer::io::Light l;
    l.index = i;
    l.lamp_id = std::to_string(i + 1);
    l.direction = cv::Vec3d(0.1 * i, 0, 1) / cv::norm(cv::Vec3d(0.1 * i, 0, 1));
    s.lights.push_back(l);
    s.images.push_back(cv::Mat(s.size, CV_32FC3, cv::Scalar(0.1 * (i + 1), 0.2, 0.3)));
  }
  s.ambient = cv::Mat(s.size, CV_32FC3, cv::Scalar(0.01, 0.01, 0.01));
  return s;
}
}  // namespace

TEST(Store, SavesListsAndFindsSetsAfterReopening) {
  fs::path root = rigtest::temp_dir("store");
  {
    auto store = veneerd::Store::open(root);
    ASSERT_TRUE(store) << store.message();
    std::string id = (*store)->new_id(veneer::io::Role::destination, "my cube!");
    EXPECT_TRUE(veneerd::valid_set_id(id)) << id;
    EXPECT_NE(id.find("destination-my_cube_"), std::string::npos) << id;
    ASSERT_TRUE((*store)->save(tiny_set("a1", veneer::io::Role::destination)));
    ASSERT_TRUE((*store)->save(tiny_set("b2", veneer::io::Role::source)));
    EXPECT_FALSE((*store)->save(tiny_set("a1", veneer::io::Role::destination))) << "ids are unique";
    // A second daemon on the same store is refused.
    auto second = veneerd::Store::open(root);
    EXPECT_FALSE(second);
  }
  // A crashed writer's leftovers and the debris of an interrupted delete.
  fs::create_directories(root / ".c3.tmp-999999-0" / "truth");
  fs::create_directories(root / ".a0.deleted-999998-0");
  auto store = veneerd::Store::open(root);
  ASSERT_TRUE(store) << store.message();
  auto sets = (*store)->list();
  ASSERT_EQ(sets.size(), 2u);
  EXPECT_EQ(sets[0].id, "a1");
  EXPECT_EQ(sets[0].lights, 3);
  EXPECT_EQ(sets[1].role, veneer::io::Role::source);
  EXPECT_FALSE(fs::exists(root / ".c3.tmp-999999-0"));
  EXPECT_FALSE(fs::exists(root / ".a0.deleted-999998-0"));
  auto files = (*store)->files("a1", true);
  ASSERT_TRUE(files);
  EXPECT_EQ(files->front(), "set.json");
  EXPECT_EQ(files->size(), 5u);  // set.json, 3 photos, ambient
  ASSERT_TRUE((*store)->remove("a1"));
  EXPECT_FALSE((*store)->find("a1"));
  EXPECT_FALSE(fs::exists(root / "a1"));
  EXPECT_FALSE((*store)->find("../etc"));
  fs::remove_all(root);
}

// A deleted set goes into the trash, is listed there with its deletion
// time, comes back whole, and is purged when old or when space is needed.
TEST(Store, DeleteMovesIntoTheTrashWhereTheSetCanBeRestoredUntilPurged) {
  fs::path root = rigtest::temp_dir("store-trash");
  auto store = veneerd::Store::open(root);
  ASSERT_TRUE(store) << store.message();
  veneerd::Store& st = **store;
  ASSERT_TRUE(st.save(tiny_set("a1", veneer::io::Role::destination)));
  ASSERT_TRUE(st.save(tiny_set("b2", veneer::io::Role::source)));
  EXPECT_TRUE(st.trash().empty());
  ASSERT_TRUE(st.remove("a1"));
  EXPECT_FALSE(st.find("a1"));
  auto trash = st.trash();
  ASSERT_EQ(trash.size(), 1u);
  EXPECT_EQ(trash[0].id, "a1");
  EXPECT_EQ(trash[0].role, veneer::io::Role::destination);
  EXPECT_EQ(trash[0].created, "2026-11-22T08:00:00Z");
  EXPECT_EQ(trash[0].deleted.size(), 20u) << trash[0].deleted;  // 2026-11-25T20:00:00Z
  EXPECT_FALSE(st.restore("no-such-set"));
  ASSERT_TRUE(st.restore("a1"));
  EXPECT_TRUE(st.trash().empty());
  ASSERT_TRUE(st.find("a1"));
  EXPECT_EQ(st.list().front().id, "a1") << "in its place, oldest first";
  auto files = st.files("a1", false);
  ASSERT_TRUE(files);
  EXPECT_EQ(files->size(), 5u) << "every photo came back";
  // restoring over a stored set of the same id is refused
  ASSERT_TRUE(st.remove("b2"));
  ASSERT_TRUE(st.save(tiny_set("b2", veneer::io::Role::source)));
  auto clash = st.restore("b2");
  ASSERT_FALSE(clash);
  EXPECT_NE(clash.message().find("a set of that id is stored"), std::string::npos) << clash.message();
  // young sets stay, old ones go; space wanted takes the oldest first
  EXPECT_EQ(st.purge_trash(), 0);
  ASSERT_TRUE(st.remove("a1"));
  st.set_trash_keep(-1);  // everything is "old"
  EXPECT_EQ(st.purge_trash(), 2);
  EXPECT_TRUE(st.trash().empty());
  EXPECT_FALSE(fs::exists(st.trash_folder() / "a1"));
  st.set_trash_keep(3600);
  ASSERT_TRUE(st.remove("b2"));
  EXPECT_EQ(st.purge_trash(std::numeric_limits<uint64_t>::max()), 1) << "no space would do: the trash empties";
  fs::remove_all(root);
}

TEST(Store, IdsThatAreNotFileNamesAreRefused) {
  for (const char* bad : {"", ".", "..", "a/b", "../x", ".hidden", "a b", "x\n"}) {
    EXPECT_FALSE(veneerd::valid_set_id(bad)) << bad;
  }
  EXPECT_TRUE(veneerd::valid_set_id("20261122-081530-destination-bull-2"));
}

// A leftover of an interrupted write is removed at the first start, even when
// the pid in its name is alive again: the old writer's unreaped zombie, or the
// pid reused by an unrelated process (both used to make it survive a restart).
TEST(Store, LeftoverTemporariesGoAtTheFirstOpenWhateverPidTheyName) {
  fs::path root = rigtest::temp_dir("store-stale");
  {
    auto store = veneerd::Store::open(root);
    ASSERT_TRUE(store) << store.message();
    ASSERT_TRUE((*store)->save(tiny_set("kept", veneer::io::Role::destination)));
  }
  pid_t zombie = ::fork();  // exits at once and stays unreaped until the end of the test
  if (zombie == 0) ::_exit(0);
  pid_t alive = ::fork();  // a live process that is not a veneerd
  if (alive == 0) {
    ::pause();
    ::_exit(0);
  }
  ASSERT_GT(zombie, 0);
  ASSERT_GT(alive, 0);
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  const std::vector<std::string> stale = {
      ".20261122-000000-source-stone.tmp-" + std::to_string(zombie) + "-0",
      ".20261122-000001-destination-bull.tmp-" + std::to_string(alive) + "-3",
      ".kept.old-" + std::to_string(alive) + "-1",
      ".kept.deleted-" + std::to_string(::getppid()) + "-0",
  };
  for (const auto& name : stale) fs::create_directories(root / name / "truth");
  { std::ofstream(root / (".token.tmp-" + std::to_string(alive) + "-0")) << "half"; }
  {
    auto store = veneerd::Store::open(root);
    ASSERT_TRUE(store) << store.message();
    ASSERT_EQ((*store)->list().size(), 1u);
  }
  ::kill(alive, SIGKILL);
  ::waitpid(alive, nullptr, 0);
  ::waitpid(zombie, nullptr, 0);
  std::vector<std::string> left;
  for (const auto& entry : fs::directory_iterator(root)) left.push_back(entry.path().filename().string());
  std::sort(left.begin(), left.end());
  EXPECT_EQ(left, (std::vector<std::string>{".lock", "kept"}));
  fs::remove_all(root);
}

TEST(Store, TheCamerasRawFilesAreStoredAndListedForTransfer) {
  fs::path root = rigtest::temp_dir("store-raw");
  auto store = veneerd::Store::open(root);
  ASSERT_TRUE(store) << store.message();
  veneer::io::ImageSet set = tiny_set("r1", veneer::io::Role::destination);
  for (int i = 0; i < 3; ++i) set.raw.push_back({"dng", "RAW bytes of shot " + std::to_string(i)});
  set.ambient_raw = {"dng", "RAW bytes of the ambient frame"};
  ASSERT_TRUE((*store)->save(set));
  auto files = (*store)->files("r1", false);
  ASSERT_TRUE(files) << files.message();
  for (const char* f : {"light_00.dng", "light_02.dng", "ambient.dng", "light_00.png", "ambient.png"})
    EXPECT_NE(std::find(files->begin(), files->end(), f), files->end()) << f;
  EXPECT_EQ(files->size(), 9u);  // set.json, 3 photos + 3 RAW, ambient + its RAW
  std::ifstream in(root / "r1" / "light_02.dng", std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_EQ(bytes, "RAW bytes of shot 2");
  fs::remove_all(root);
}

namespace {
std::string file_bytes(const fs::path& f) {
  std::ifstream in(f, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

// A set with what a simulated capture brings: noisy photos, RAW files, a
// mask and the truth.
veneer::io::ImageSet full_set(const std::string& id) {
  veneer::io::ImageSet s = tiny_set(id, veneer::io::Role::source);
  cv::RNG rng(29);
  for (auto& img : s.images) {
    img = cv::Mat(s.size, CV_32FC3);
    rng.fill(img, cv::RNG::UNIFORM, 0.0, 1.0);
  }
  rng.fill(s.ambient, cv::RNG::UNIFORM, 0.0, 0.02);
  for (size_t i = 0; i < s.images.size(); ++i) s.raw.push_back({"dng", "raw bytes of shot " + std::to_string(i)});
  s.ambient_raw = {"dng", "the ambient's raw bytes"};
  s.mask = cv::Mat(s.size, CV_8UC1, cv::Scalar(255));
  s.truth.normals = cv::Mat(s.size, CV_32FC3, cv::Scalar(0, 0.6, 0.8));
  s.truth.mask = cv::Mat(s.size, CV_8UC1, cv::Scalar(255));
  s.truth.albedo = cv::Mat(s.size, CV_32FC3);
  rng.fill(s.truth.albedo, cv::RNG::UNIFORM, 0.0, 1.0);
  s.truth.depth = cv::Mat(s.size, CV_32FC1, cv::Scalar(1.25));
  s.warnings = {"bright ambient frame"};
  s.scene = "bull";
  return s;
}
}  // namespace

// A capture's frames go into the store one by one (a full-resolution set is
// 2 GiB as float): the folder is byte for byte what save() writes.
TEST(Store, ASetWrittenFrameByFrameIsTheSetSaveWrites) {
  fs::path root = rigtest::temp_dir("writer");
  auto store = veneerd::Store::open(root);
  ASSERT_TRUE(store) << store.message();
  veneer::io::ImageSet whole = full_set("whole");
  ASSERT_TRUE((*store)->save(whole));

  veneer::io::ImageSet framed = full_set("framed");
  auto writer = (*store)->begin("framed");
  ASSERT_TRUE(writer) << writer.message();
  const int photos = static_cast<int>(framed.images.size()) + 1;
  ASSERT_TRUE((*writer)->add_frame(0, framed.ambient, framed.ambient_raw, photos));
  for (size_t i = 0; i < framed.images.size(); ++i)
    ASSERT_TRUE((*writer)->add_frame(static_cast<int>(i) + 1, framed.images[i], framed.raw[i], photos));
  EXPECT_FALSE((*store)->find("framed")) << "not listed before commit";
  veneer::io::ImageSet meta = framed;  // what the rig has at the end: no photos
  meta.images.clear();
  meta.ambient.release();
  meta.raw.clear();
  meta.ambient_raw = {};
  auto committed = (*writer)->commit(meta);
  ASSERT_TRUE(committed) << committed.message();
  EXPECT_TRUE(meta.truth.albedo.empty()) << "the truth is let go once written";
  ASSERT_TRUE((*store)->find("framed"));

  auto a = (*store)->files("whole", true), b = (*store)->files("framed", true);
  ASSERT_TRUE(a && b);
  ASSERT_EQ(*a, *b);
  EXPECT_EQ(a->size(), 1u + 3 + 1 + 3 + 1 + 1 + 4);  // set.json, photos, ambient, RAW files, mask, truth
  for (const auto& f : *a) {
    std::string x = file_bytes(root / "whole" / f), y = file_bytes(root / "framed" / f);
    if (f == "set.json") {
      // the same but for the id
      const std::string from = "\"id\": \"whole\"", to = "\"id\": \"framed\"";
      ASSERT_NE(x.find(from), std::string::npos);
      x.replace(x.find(from), from.size(), to);
    }
    EXPECT_EQ(x, y) << f;
  }
  EXPECT_TRUE(fs::exists(root / "framed" / "mask.png"));
  EXPECT_TRUE(fs::exists(root / "framed" / "truth" / "depth.pfm"));
}

// A capture that fails or is cancelled leaves nothing; a set short of a
// frame is refused, naming why.
TEST(Store, AFrameByFrameSetNotCommittedOrShortOfAFrameLeavesNothing) {
  fs::path root = rigtest::temp_dir("writer-drop");
  auto store = veneerd::Store::open(root);
  ASSERT_TRUE(store) << store.message();
  veneer::io::ImageSet s = full_set("dropped");
  {
    auto writer = (*store)->begin("dropped");
    ASSERT_TRUE(writer) << writer.message();
    ASSERT_TRUE((*writer)->add_frame(0, s.ambient, s.ambient_raw, 4));
    ASSERT_TRUE((*writer)->add_frame(1, s.images[0], s.raw[0], 4));
  }
  {
    auto writer = (*store)->begin("short");
    ASSERT_TRUE(writer) << writer.message();
    ASSERT_TRUE((*writer)->add_frame(0, s.ambient, s.ambient_raw, 4));
    ASSERT_TRUE((*writer)->add_frame(1, s.images[0], s.raw[0], 4));
    EXPECT_FALSE((*writer)->add_frame(2, cv::Mat(3, 3, CV_32FC3, cv::Scalar::all(0)), {}, 4)) << "size changed";
    veneer::io::ImageSet meta = s;
    meta.id = "short";
    auto committed = (*writer)->commit(meta);
    ASSERT_FALSE(committed);
    EXPECT_NE(committed.message().find("not every frame"), std::string::npos) << committed.message();
  }
  EXPECT_TRUE((*store)->list().empty());
  std::vector<std::string> left;
  for (const auto& e : fs::directory_iterator(root)) left.push_back(e.path().filename().string());
  std::sort(left.begin(), left.end());
  EXPECT_EQ(left, (std::vector<std::string>{".lock"})) << "no temporary folder left";
}

// The store's write faults (the simulated rig's store.enospc, store.eio,
// store.slow): a write that fails half-way fails the set with the error named,
// and the half-written file goes with the temporary folder.
TEST(Store, AWriteFaultFailsTheSetByNameAndLeavesNothing) {
  fs::path root = rigtest::temp_dir("write-faults");
  auto store = veneerd::Store::open(root);
  ASSERT_TRUE(store) << store.message();
  int writes = 0;
  (*store)->set_write_faults([&](const fs::path&) {
    veneerd::WriteFault f;
    if (++writes == 3) f.error = EIO;
    if (writes == 5) f.error = ENOSPC;
    if (writes == 1) f.delay = std::chrono::milliseconds(30);
    return f;
  });
  veneer::io::ImageSet s = full_set("eio");
  for (const char* id : {"eio", "enospc"}) {
    auto writer = (*store)->begin(id);
    ASSERT_TRUE(writer) << writer.message();
    veneer::Status result;
    int k = 0;
    const auto t0 = std::chrono::steady_clock::now();
    for (; k < 4 && result; ++k) {
      result = k == 0 ? (*writer)->add_frame(0, s.ambient, s.ambient_raw, 4)
                      : (*writer)->add_frame(k, s.images[k - 1], s.raw[k - 1], 4);
    }
    if (std::string(id) == "eio") {
      EXPECT_GE(std::chrono::steady_clock::now() - t0, std::chrono::milliseconds(30)) << "the slow write";
    }
    ASSERT_FALSE(result) << id << ": a write failed";
    const std::string errno_text = std::string(id) == "eio" ? "Input/output error" : "No space left on device";
    EXPECT_NE(result.message().find(errno_text), std::string::npos) << result.message();
    EXPECT_NE(result.message().find("no set stored"), std::string::npos) << result.message();
    // The half-written file is there until the writer goes.
    bool partial = false;
    for (const auto& e : fs::recursive_directory_iterator(root))
      partial = partial || e.path().parent_path().filename().string().rfind("." + std::string(id) + ".capture-", 0) == 0;
    EXPECT_TRUE(partial) << "the failing write left part of its file in the temporary folder";
  }
  EXPECT_TRUE((*store)->list().empty());
  std::vector<std::string> left;
  for (const auto& e : fs::directory_iterator(root)) left.push_back(e.path().filename().string());
  EXPECT_EQ(left, (std::vector<std::string>{".lock"})) << "no temporary folder left";
}
