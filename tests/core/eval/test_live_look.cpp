// The live look's measure (eval/live_look.hpp, issue 40) on a known
// sequence: the truth scored against itself gives shading error 0 and
// texture_corr 1 in every frame; a wrong sequence (the lamp's frames out of
// order, or the texture flattened) scores worse; through files (8-bit sRGB
// repainted frames, 16-bit linear truth) as `veneer eval --live` reads them.
#include <unistd.h>

#include <cstdio>
#include <filesystem>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "veneer/eval/live_look.hpp"
#include "veneer/io/image_io.hpp"
#include "veneer/sim/light_path.hpp"

namespace veneer::eval {
namespace {
namespace fs = std::filesystem;

const sim::LightSequence& sequence() {
  static const sim::LightSequence seq = [] {
    sim::RenderOptions o;
    o.size = {192, 128};
    o.scale = 2.5;
    auto s = sim::simulate_light_path("orange", "bull", o, *sim::parse_light_path("spiral"), 6);
    EXPECT_TRUE(s) << s.message();
    return s ? std::move(s).value() : sim::LightSequence{};
  }();
  return seq;
}

TEST(LiveLook, TruthAgainstItselfScoresZeroAndOne) {
  const auto& seq = sequence();
  ASSERT_EQ(seq.truth.size(), 6u);
  auto look = live_look(seq.truth, seq.truth, seq.truth_mask);
  ASSERT_TRUE(look) << look.message();
  ASSERT_EQ(look->frames.size(), 6u);
  for (const FrameLook& f : look->frames) {
    EXPECT_GT(f.shading.samples, 1000);
    EXPECT_EQ(f.shading.mean, 0.0);
    EXPECT_EQ(f.shading.p90, 0.0);
    ASSERT_TRUE(f.texture_corr);
    EXPECT_NEAR(*f.texture_corr, 1.0, 1e-9);
  }
  EXPECT_EQ(look->shading_mean, 0.0);
  EXPECT_NEAR(*look->texture_corr_mean, 1.0, 1e-9);
  std::fputs(look->table().c_str(), stdout);
}

TEST(LiveLook, AWrongSequenceScoresWorse) {
  const auto& seq = sequence();
  // the lamp's frames reversed: each frame shaded by another lamp
  std::vector<cv::Mat> reversed(seq.truth.rbegin(), seq.truth.rend());
  auto wrong_light = live_look(reversed, seq.truth, seq.truth_mask);
  ASSERT_TRUE(wrong_light) << wrong_light.message();
  // the texture flattened: each frame blurred
  std::vector<cv::Mat> flat;
  for (const cv::Mat& t : seq.truth) {
    cv::Mat b;
    cv::GaussianBlur(t, b, cv::Size(0, 0), 4);
    flat.push_back(b);
  }
  auto no_texture = live_look(flat, seq.truth, seq.truth_mask);
  ASSERT_TRUE(no_texture) << no_texture.message();
  std::printf("frames reversed: shading %.4f, texture_corr %.3f; texture blurred: shading %.4f, texture_corr %.3f\n",
              wrong_light->shading_mean, *wrong_light->texture_corr_mean, no_texture->shading_mean,
              *no_texture->texture_corr_mean);
  EXPECT_GT(wrong_light->shading_mean, 0.1);
  for (size_t i = 0; i < 6; ++i)
    if (i != 2 && i != 3) {  // 2 and 3 swap lamps close to each other
      EXPECT_GT(wrong_light->frames[i].shading.mean, 0.05) << "frame " << i;
    }
  EXPECT_LT(*no_texture->texture_corr_mean, 0.6);
  // a count mismatch, named
  auto short_run = live_look({seq.truth.begin(), seq.truth.begin() + 5}, seq.truth, seq.truth_mask);
  ASSERT_FALSE(short_run);
  EXPECT_NE(short_run.message().find("5 repainted frames for 6 truth frames"), std::string::npos) << short_run.message();
}

// The files as `veneer simulate --light-path --material` and `veneer repaint
// --video` write them: the truth as 8-bit sRGB "repainted" frames scores
// nearly perfectly (quantisation only), a reversed sequence does not.
TEST(LiveLook, FoldersAsTheCommandsWriteThem) {
  const auto& seq = sequence();
  const fs::path dir = fs::temp_directory_path() / ("veneer-live-look-" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir / "seq" / "truth");
  fs::create_directories(dir / "rep");
  fs::create_directories(dir / "bad");
  sim::LightPathFile c;
  c.spec = "spiral";
  c.size = seq.truth[0].size();
  c.lights = seq.lights;
  c.truth_mask = "truth/mask.png";
  ASSERT_TRUE(cv::imwrite((dir / "seq" / c.truth_mask).string(), seq.truth_mask));
  for (size_t i = 0; i < seq.truth.size(); ++i) {
    char name[48];
    std::snprintf(name, sizeof name, "truth/frame_%04zu.png", i);
    c.truth_files.push_back(name);
    ASSERT_TRUE(io::write_png16(dir / "seq" / name, seq.truth[i]));
    std::snprintf(name, sizeof name, "frame_%04zu.png", i);
    c.files.push_back(name);
    cv::Mat srgb(seq.truth[i].size(), CV_8UC3);
    for (int y = 0; y < srgb.rows; ++y)
      for (int x = 0; x < srgb.cols; ++x)
        for (int k = 0; k < 3; ++k) {
          const float v = std::clamp(seq.truth[i].at<cv::Vec3f>(y, x)[k], 0.0f, 1.0f);
          const float s = v <= 0.0031308f ? 12.92f * v : 1.055f * std::pow(v, 1 / 2.4f) - 0.055f;
          srgb.at<cv::Vec3b>(y, x)[k] = cv::saturate_cast<uchar>(s * 255);
        }
    ASSERT_TRUE(cv::imwrite((dir / "rep" / name).string(), srgb));
    std::snprintf(name, sizeof name, "frame_%04zu.png", seq.truth.size() - 1 - i);  // the frames in reverse
    ASSERT_TRUE(cv::imwrite((dir / "bad" / name).string(), srgb));
  }
  ASSERT_TRUE(sim::write_light_path_json(dir / "seq" / "light_path.json", c));
  auto good = live_look_folders(dir / "rep", dir / "seq");
  ASSERT_TRUE(good) << good.message();
  auto bad = live_look_folders(dir / "bad", dir / "seq");
  ASSERT_TRUE(bad) << bad.message();
  std::printf("8-bit truth: shading %.4f, texture_corr %.4f; reversed: shading %.4f, texture_corr %.4f\n",
              good->shading_mean, *good->texture_corr_mean, bad->shading_mean, *bad->texture_corr_mean);
  EXPECT_LT(good->shading_mean, 0.03);
  EXPECT_GT(*good->texture_corr_mean, 0.95);
  EXPECT_GT(bad->shading_mean, 3 * good->shading_mean);
  EXPECT_EQ(good->frames[0].file, "frame_0000.png");
  EXPECT_NE(good->json().find("\"shading_mean\""), std::string::npos);
  // a sequence without truth is refused with the way to make one
  c.truth_files.clear();
  c.truth_mask.clear();
  ASSERT_TRUE(sim::write_light_path_json(dir / "seq" / "light_path.json", c));
  auto none = live_look_folders(dir / "rep", dir / "seq");
  ASSERT_FALSE(none);
  EXPECT_NE(none.message().find("--material"), std::string::npos) << none.message();
  fs::remove_all(dir);
}

}  // namespace
}  // namespace veneer::eval
