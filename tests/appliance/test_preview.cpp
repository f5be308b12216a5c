// The files a download serves (veneerd/preview.hpp) and the live-first
// requests' edge (api.cpp): a set of camera files serves each frame's
// embedded preview as a reduced set; an older set its photos at full size;
// a resumed fetch leaves out what the client holds.
#include <gtest/gtest.h>
#include <zlib.h>

#include <fstream>

#include "rig_test_util.hpp"
#include "veneer/io/camera_files.hpp"
#include "veneer/io/dng.hpp"
#include "veneer/io/image_io.hpp"
#include "veneer/io/imageset.hpp"
#include "veneer/v1/rig.pb.h"
#include "veneerd/api.hpp"
#include "veneerd/preview.hpp"
#include "veneerd/store.hpp"

namespace fs = std::filesystem;
namespace pb = veneer::v1;

namespace {

veneer::io::ImageSet noisy_set(const std::string& id, cv::Size size) {
  veneer::io::ImageSet s;
  s.id = id;
  s.role = veneer::io::Role::destination;
  s.object = "cube";
  s.created = "2026-11-27T03:00:00Z";
  s.size = size;
  s.camera.focal_px = 2.0 * size.width;
  s.camera.cx = (size.width - 1) / 2.0;
  s.camera.cy = (size.height - 1) / 2.0;
  cv::RNG rng(11);
  for (int i = 0; i < 3; ++i) {
    veneer::io::Light l;
    l.index = i;
    l.lamp_id = std::to_string(i + 1);
    l.direction = cv::Vec3d(0.1 * i, 0, 1) / cv::norm(cv::Vec3d(0.1 * i, 0, 1));
    s.lights.push_back(l);
    cv::Mat img(size, CV_32FC3);
    rng.fill(img, cv::RNG::UNIFORM, 0.1 * (i + 1), 0.2 * (i + 1));
    s.images.push_back(img);
  }
  s.ambient = cv::Mat(size, CV_32FC3, cv::Scalar(0.01, 0.01, 0.01));
  return s;
}

std::string bytes_of(const veneerd::ServedFile& f) {
  if (f.source.empty()) return f.bytes;
  std::ifstream in(f.source, std::ios::binary);
  in.seekg(static_cast<std::streamoff>(f.offset));
  std::string out(static_cast<size_t>(f.size), '\0');
  in.read(out.data(), static_cast<std::streamsize>(out.size()));
  return out;
}

// Writes what a download serves into `dir`, as a client would.
void receive(const std::vector<veneerd::ServedFile>& files, const fs::path& dir) {
  fs::create_directories(dir);
  for (const auto& f : files) ASSERT_TRUE(veneer::io::write_file_synced(dir / f.rel, bytes_of(f)));
}

}  // namespace

TEST(Preview, ASetOfCameraFilesServesEachFramesEmbeddedPreviewAsAReducedSet) {
  fs::path root = rigtest::temp_dir("preview");
  auto store = veneerd::Store::open(root / "store");
  ASSERT_TRUE(store) << store.message();
  veneer::io::ImageSet set = noisy_set("p1", {96, 64});
  ASSERT_TRUE(veneer::io::add_camera_files(set));
  ASSERT_TRUE((*store)->save(set));
  auto files = veneerd::preview_files(**store, "p1");
  ASSERT_TRUE(files) << files.message();
  std::vector<std::string> names;
  for (const auto& f : *files) names.push_back(f.rel);
  EXPECT_EQ(names, (std::vector<std::string>{"set.json", "light_00.jpg", "light_01.jpg", "light_02.jpg", "ambient.jpg"}));
  // Each frame's JPEG is the stored DNG's preview, byte for byte, read in place.
  auto embedded = veneer::io::read_dng_preview(root / "store" / "p1" / "light_01.dng");
  ASSERT_TRUE(embedded) << embedded.message();
  EXPECT_EQ(bytes_of((*files)[2]), *embedded);
  EXPECT_EQ((*files)[2].source, root / "store" / "p1" / "light_01.dng");

  receive(*files, root / "got");
  auto preview = veneer::io::read_set(root / "got");
  ASSERT_TRUE(preview) << preview.message();
  EXPECT_EQ(preview->size, cv::Size(24, 16));
  ASSERT_TRUE(preview->preview_of);
  EXPECT_EQ(preview->preview_of->id, "p1");
  EXPECT_EQ(preview->preview_of->size, cv::Size(96, 64));
  EXPECT_EQ(preview->photos_from, "jpeg");
  EXPECT_NEAR(preview->camera.focal_px, 48.0, 1e-9);
  EXPECT_EQ(preview->images.size(), 3u);
  EXPECT_FALSE(preview->ambient.empty());
  fs::remove_all(root);
}

TEST(Preview, AnOlderSetWithoutPreviewsServesItsPhotosAtFullSize) {
  fs::path root = rigtest::temp_dir("preview-old");
  auto store = veneerd::Store::open(root / "store");
  ASSERT_TRUE(store) << store.message();
  veneer::io::ImageSet set = noisy_set("old", {32, 24});  // 16-bit PNGs and no RAW files
  ASSERT_TRUE((*store)->save(set));
  auto files = veneerd::preview_files(**store, "old");
  ASSERT_TRUE(files) << files.message();
  ASSERT_EQ(files->size(), 5u);
  EXPECT_EQ((*files)[1].rel, "light_00.png");
  EXPECT_EQ((*files)[1].offset, 0u);
  EXPECT_EQ((*files)[1].size, fs::file_size(root / "store" / "old" / "light_00.png"));
  receive(*files, root / "got");
  auto preview = veneer::io::read_set(root / "got");
  ASSERT_TRUE(preview) << preview.message();
  EXPECT_EQ(preview->size, cv::Size(32, 24));
  ASSERT_TRUE(preview->preview_of);
  EXPECT_EQ(preview->photos_from, "png");
  fs::remove_all(root);
}

TEST(Preview, AResumedFetchLeavesOutWhatTheClientHoldsButNotSetJson) {
  fs::path root = rigtest::temp_dir("preview-skip");
  auto store = veneerd::Store::open(root / "store");
  ASSERT_TRUE(store) << store.message();
  ASSERT_TRUE((*store)->save(noisy_set("s", {16, 12})));
  std::vector<std::string> skipped;
  auto files = veneerd::set_files(**store, "s", false, {"set.json", "light_01.png", "not-in-the-set.png"}, &skipped);
  ASSERT_TRUE(files) << files.message();
  std::vector<std::string> names;
  for (const auto& f : *files) names.push_back(f.rel);
  EXPECT_EQ(names, (std::vector<std::string>{"set.json", "light_00.png", "light_02.png", "ambient.png"}));
  EXPECT_EQ(skipped, (std::vector<std::string>{"light_01.png"}));
  EXPECT_FALSE(veneerd::preview_files(**store, "nope"));
  fs::remove_all(root);
}

// A resumed file is sent from the client's offset only when the CRC-32 of the
// rig's own first bytes is the client's (computed here with zlib's CRC-32 of
// the bytes read back); otherwise, and for set.json and offsets past the end,
// whole.
TEST(Preview, AResumedFetchContinuesAFileOnlyWhenItsStartIsTheRigs) {
  fs::path root = rigtest::temp_dir("preview-resume");
  auto store = veneerd::Store::open(root / "store");
  ASSERT_TRUE(store) << store.message();
  ASSERT_TRUE((*store)->save(noisy_set("s", {64, 48})));
  auto files = veneerd::set_files(**store, "s", false, {});
  ASSERT_TRUE(files) << files.message();
  auto bytes_of = [&](const std::string& rel) {
    std::ifstream in(root / "store" / "s" / rel, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
  };
  const std::string l0 = bytes_of("light_00.png"), l1 = bytes_of("light_01.png"), js = bytes_of("set.json");
  ASSERT_GT(l0.size(), 100u);
  auto crc = [](const std::string& b, size_t n) {
    return static_cast<uint32_t>(::crc32(0, reinterpret_cast<const Bytef*>(b.data()), static_cast<uInt>(n)));
  };
  std::vector<veneerd::api::ResumeFrom> from = {
      {"light_00.png", 100, crc(l0, 100)},                    // the rig's start: resumed
      {"light_01.png", 50, crc(l1, 50) ^ 1u},                 // not the rig's bytes: whole
      {"light_02.png", l0.size() * 100, 0},                   // past the end: whole
      {"set.json", 10, crc(js, 10)},                          // set.json: always whole
      {"not-in-the-set.png", 10, 0}};
  auto honoured = veneerd::resume_files(*files, from);
  ASSERT_EQ(honoured.size(), 1u);
  EXPECT_EQ(honoured[0].file, "light_00.png");
  for (const auto& f : *files) EXPECT_EQ(f.start, f.rel == "light_00.png" ? 100u : 0u) << f.rel;
  fs::remove_all(root);
}

// The camera's JPEGs written frame by frame are the files save() writes.
TEST(Preview, ASetWrittenFrameByFrameKeepsTheCamerasJpegs) {
  fs::path root = rigtest::temp_dir("writer-jpeg");
  auto store = veneerd::Store::open(root / "store");
  ASSERT_TRUE(store) << store.message();
  veneer::io::ImageSet whole = noisy_set("whole", {64, 48});
  ASSERT_TRUE(veneer::io::add_camera_files(whole));
  ASSERT_TRUE((*store)->save(whole));
  auto writer = (*store)->begin("framed");
  ASSERT_TRUE(writer) << writer.message();
  ASSERT_TRUE((*writer)->add_frame(0, whole.ambient, whole.ambient_raw, 4, whole.ambient_developed));
  for (size_t i = 0; i < 3; ++i)
    ASSERT_TRUE((*writer)->add_frame(static_cast<int>(i) + 1, whole.images[i], whole.raw[i], 4, whole.developed[i]));
  veneer::io::ImageSet meta = whole;
  meta.id = "framed";
  ASSERT_TRUE((*writer)->commit(meta));
  auto a = (*store)->files("whole", false), b = (*store)->files("framed", false);
  ASSERT_TRUE(a && b);
  EXPECT_EQ(*a, *b);
  EXPECT_NE(std::find(a->begin(), a->end(), "light_02.jpg"), a->end());
  EXPECT_NE(std::find(a->begin(), a->end(), "ambient.jpg"), a->end());
  fs::remove_all(root);
}

TEST(Api, LiveFirstRequestsAreCheckedNamingTheirFields) {
  pb::ClientMessage m;
  m.set_id(4);
  m.mutable_fetch_preview()->set_set_id("a-set");
  auto r = veneerd::api::decode(m);
  ASSERT_TRUE(r) << r.message();
  auto* p = std::get_if<veneerd::api::FetchPreviewReq>(&r->body);
  ASSERT_NE(p, nullptr);
  EXPECT_EQ(p->set_id, "a-set");
  EXPECT_EQ(p->chunk_size, veneerd::api::kDefaultChunkBytes);
  EXPECT_FALSE(veneerd::api::needs_control(r->body));
  EXPECT_STREQ(veneerd::api::request_name(r->body), "fetch_preview");

  pb::ClientMessage bad_id;
  bad_id.mutable_fetch_preview()->set_set_id("../x");
  auto refused = veneerd::api::decode(bad_id);
  ASSERT_FALSE(refused);
  EXPECT_NE(refused.message().find("fetch_preview.set_id"), std::string::npos) << refused.message();

  pb::ClientMessage skip;
  skip.mutable_fetch_images()->set_set_id("a-set");
  skip.mutable_fetch_images()->add_skip_files("light_00.dng");
  auto ok = veneerd::api::decode(skip);
  ASSERT_TRUE(ok) << ok.message();
  EXPECT_EQ(std::get<veneerd::api::FetchImagesReq>(ok->body).skip_files, std::vector<std::string>{"light_00.dng"});
  for (int i = 0; i <= static_cast<int>(veneerd::api::kMaxSkipFiles); ++i) skip.mutable_fetch_images()->add_skip_files("f");
  auto too_many = veneerd::api::decode(skip);
  ASSERT_FALSE(too_many);
  EXPECT_NE(too_many.message().find("fetch_images.skip_files"), std::string::npos) << too_many.message();
  pb::ClientMessage long_name;
  long_name.mutable_fetch_images()->set_set_id("a-set");
  long_name.mutable_fetch_images()->add_skip_files(std::string(veneerd::api::kMaxSkipFileChars + 1, 'a'));
  EXPECT_FALSE(veneerd::api::decode(long_name));
}
