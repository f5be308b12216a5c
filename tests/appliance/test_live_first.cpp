// Live first over the wire (proto/README.md "Live first", issue 34): the real
// veneerd on loopback with the simulated rig, whose camera twin stores per
// frame a developed JPEG and a lossless DNG with an embedded preview; a
// client pulls the preview set first (a valid reduced set, in place before
// any full file arrives), then the full files, which replace it atomically.
#include <gtest/gtest.h>

#include <atomic>

#include <opencv2/imgproc.hpp>

#include "rig_test_util.hpp"
#include "veneer/io/dng.hpp"
#include "veneer/io/image_io.hpp"
#include "veneer/io/imageset.hpp"
#include "veneer/io/raw.hpp"
#include "veneer/rig/client.hpp"

namespace fs = std::filesystem;
using rigtest::DaemonProcess;

namespace {

std::unique_ptr<veneer::rig::Client> connect_to(const DaemonProcess& d, const fs::path& store) {
  auto token = veneer::rig::read_token_file(store / "token");
  if (!token) return nullptr;
  auto c = veneer::rig::Client::connect({"127.0.0.1", d.port()}, *token);
  return c ? std::move(*c) : nullptr;
}

// Presses the simulated button and waits for the set; its id.
std::string capture(veneer::rig::Client& c) {
  using Kind = veneer::rig::Event::Kind;
  if (!c.press_button()) return {};
  auto done = c.wait_event([](const veneer::rig::Event& e) { return e.kind == Kind::set_stored || e.kind == Kind::capture_failed; }, 120);
  return done && done->kind == Kind::set_stored ? done->set_id : std::string();
}

}  // namespace

TEST(LiveFirst, TheTwinStoresAJpegAndACompressedDngWithAPreviewPerFrame) {
  fs::path dir = rigtest::temp_dir("twinfiles");
  fs::path store = dir / "store";
  auto d = DaemonProcess::start(store, {"--size", "512x340"});
  ASSERT_TRUE(d && d->port() != 0) << (d ? d->log() : "no process");
  auto c = connect_to(*d, store);
  ASSERT_TRUE(c);
  const std::string id = capture(*c);
  ASSERT_FALSE(id.empty()) << d->log();
  const fs::path set = store / id;
  for (const std::string frame : {"light_00", "light_06", "ambient"}) {
    SCOPED_TRACE(frame);
    EXPECT_FALSE(fs::exists(set / (frame + ".png"))) << "a 16-bit PNG where the camera's JPEG belongs";
    auto jpeg = veneer::io::read_file_bytes(set / (frame + ".jpg"));
    auto dng = veneer::io::read_file_bytes(set / (frame + ".dng"));
    ASSERT_TRUE(jpeg && dng);
    EXPECT_EQ(veneer::io::image_file_kind(*jpeg), "jpeg");
    // Lossless compression: below the 2 bytes a sample of the uncompressed mosaic.
    EXPECT_LT(dng->size(), 512u * 340u * 2u * 8u / 10u);
    auto preview = veneer::io::raw_preview_jpeg(*dng, frame + ".dng");  // LibRaw finds it
    ASSERT_TRUE(preview) << preview.message();
    auto found = veneer::io::find_dng_preview(set / (frame + ".dng"));
    ASSERT_TRUE(found) << found.message();
    EXPECT_EQ(found->size, cv::Size(128, 85));
  }
  // The set reads from the RAW files by default, from the JPEGs when asked.
  auto raw = veneer::io::read_set(set);
  ASSERT_TRUE(raw) << raw.message();
  EXPECT_EQ(raw->photos_from, "raw");
  veneer::io::ReadOptions developed;
  developed.photos = veneer::io::PhotoSource::developed;
  auto jpeg = veneer::io::read_set(set, developed);
  ASSERT_TRUE(jpeg) << jpeg.message();
  EXPECT_EQ(jpeg->photos_from, "jpeg");
  for (size_t i = 0; i < raw->images.size(); ++i) {
    const cv::Mat& m = raw->truth.mask;
    // Two readings of one noisy frame: the JPEG's loss against the RAW's demosaicing (each ~1-2 %).
    EXPECT_LT(cv::norm(jpeg->images[i], raw->images[i], cv::NORM_L1, m) / cv::norm(raw->images[i], cv::NORM_L1, m), 0.05);
  }
}

TEST(LiveFirst, ThePreviewSetIsInPlaceAndReadableBeforeTheFullFilesWhichReplaceIt) {
  fs::path dir = rigtest::temp_dir("livefirst");
  fs::path store = dir / "store";
  auto d = DaemonProcess::start(store, {"--size", "512x340"});
  ASSERT_TRUE(d && d->port() != 0) << (d ? d->log() : "no process");
  auto c = connect_to(*d, store);
  ASSERT_TRUE(c);
  const std::string id = capture(*c);
  ASSERT_FALSE(id.empty()) << d->log();

  const fs::path out = dir / "pulled" / "dest";
  veneer::rig::PullOptions o;
  o.live_first = true;
  o.include_truth = true;  // the full set's truth is checked below
  int previews = 0;
  std::optional<veneer::io::ImageSet> preview;
  std::vector<std::string> in_folder;  // what the folder held when the preview was announced
  o.on_preview = [&](const fs::path& folder) {
    ++previews;
    for (const auto& e : fs::directory_iterator(folder)) in_folder.push_back(e.path().filename().string());
    auto s = veneer::io::read_set(folder);
    EXPECT_TRUE(s) << s.message();
    if (s) preview = std::move(*s);
  };
  std::vector<std::string> stages;
  veneer::Progress progress;
  progress.on_progress = [&](double, const std::string& stage) { stages.push_back(stage); };
  ASSERT_TRUE(c->pull_set(id, out, o, progress));
  ASSERT_EQ(previews, 1);
  ASSERT_TRUE(preview);
  // The preview: a whole set at a quarter of the size, marked, no RAW files yet.
  EXPECT_EQ(preview->size, cv::Size(128, 85));
  ASSERT_TRUE(preview->preview_of);
  EXPECT_EQ(preview->preview_of->id, id);
  EXPECT_EQ(preview->preview_of->size, cv::Size(512, 340));
  EXPECT_EQ(preview->photos_from, "jpeg");
  EXPECT_EQ(preview->images.size(), 7u);
  EXPECT_FALSE(preview->ambient.empty());
  for (const auto& f : in_folder) EXPECT_EQ(f.find(".dng"), std::string::npos) << f << " arrived before the preview was announced";

  // Then the full set in the same place: read from its RAW files, not a preview.
  auto full = veneer::io::read_set(out);
  ASSERT_TRUE(full) << full.message();
  EXPECT_FALSE(full->preview_of);
  EXPECT_EQ(full->size, cv::Size(512, 340));
  EXPECT_EQ(full->photos_from, "raw");
  EXPECT_TRUE(full->truth.present());
  EXPECT_NEAR(preview->camera.focal_px * 4, full->camera.focal_px, 1e-9);
  // Each preview frame is its full frame reduced (JPEG's loss of an area average).
  for (size_t i = 0; i < full->images.size(); ++i) {
    cv::Mat reduced;
    cv::resize(full->images[i], reduced, preview->size, 0, 0, cv::INTER_AREA);
    EXPECT_LT(cv::norm(preview->images[i], reduced, cv::NORM_L1) / cv::norm(reduced, cv::NORM_L1), 0.06) << "frame " << i;
  }
  // Nothing left beside it (no preview or staging folder).
  for (const auto& e : fs::directory_iterator(out.parent_path()))
    EXPECT_EQ(e.path().filename(), "dest") << e.path() << " left over";

  // A second pull of the same set into it has nothing to do; preview-only pulls too.
  EXPECT_TRUE(c->pull_set(id, out, o));
  EXPECT_TRUE(c->pull_preview(id, out));
  // A preview-only pull elsewhere, and a plain pull completing it in place.
  const fs::path only = dir / "pulled" / "only";
  ASSERT_TRUE(c->pull_preview(id, only));
  auto small = veneer::io::read_set(only);
  ASSERT_TRUE(small) << small.message();
  EXPECT_TRUE(small->preview_of);
  ASSERT_TRUE(c->pull(id, only, false));
  auto completed = veneer::io::read_set(only);
  ASSERT_TRUE(completed) << completed.message();
  EXPECT_FALSE(completed->preview_of);
  // Another set's folder is not replaced without asking.
  const fs::path other = dir / "pulled" / "other";
  fs::create_directories(other);
  EXPECT_FALSE(c->pull_set(id, other, o));
}
