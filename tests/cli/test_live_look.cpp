// Issue 40 through the real binary: `veneer simulate --light-path` writes a
// live sequence with its sidecar and truth, `veneer repaint --video` repaints
// it, `veneer eval --live --truth` scores it frame by frame, `veneer transfer
// --rti-format hsh` writes an HSH file; bad options exit 2 (usage) with one line.
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

namespace fs = std::filesystem;

namespace {

int run(const std::string& args) {
  const std::string cmd = VENEER_BIN_DIR "/veneer " + args + " >/dev/null 2>&1";
  const int status = std::system(cmd.c_str());
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

nlohmann::json read_json(const fs::path& file) {
  std::ifstream in(file);
  return nlohmann::json::parse(in, nullptr, false);
}

TEST(LiveLookCli, SimulateRepaintEvalAndHshExport) {
  const fs::path dir = fs::temp_directory_path() / ("veneer-cli-live-look-" + std::to_string(::getpid()));
  fs::remove_all(dir);
  const std::string common = " --size 256x170 --scale 2.5 --overwrite";
  ASSERT_EQ(run("simulate --scene bull --role destination --out " + (dir / "dst").string() + common), 0);
  ASSERT_EQ(run("simulate --scene orange --role source --out " + (dir / "src").string() + common), 0);
  const std::string seq = (dir / "seq").string();
  ASSERT_EQ(run("simulate --scene bull --material orange --light-path spiral --frames 5 --out " + seq + common), 0);
  for (const char* f : {"frame_0000.png", "frame_0004.png", "motion.json", "light_path.json", "truth/frame_0004.png",
                        "truth/mask.png"})
    EXPECT_TRUE(fs::exists(dir / "seq" / f)) << f;
  const auto sidecar = read_json(dir / "seq" / "light_path.json");
  ASSERT_TRUE(sidecar.is_object());
  EXPECT_EQ(sidecar["format"], "veneer-light-path/1");
  EXPECT_EQ(sidecar["source"], "orange");
  EXPECT_EQ(sidecar["destination"], "bull");
  ASSERT_EQ(sidecar["frames"].size(), 5u);
  for (const char* key : {"position_m", "direction", "intensity", "colour"}) EXPECT_EQ(sidecar["frames"][0][key].size(), 3u) << key;

  const std::string pair = " --dst " + (dir / "dst").string() + " --src " + (dir / "src").string();
  const fs::path rti = dir / "out.rti";
  ASSERT_EQ(run("transfer --no-cache --rti " + rti.string() + " --rti-format hsh --out " + (dir / "tr").string() + pair), 0);
  EXPECT_TRUE(fs::exists(rti));
  const auto metrics = read_json(dir / "tr" / "metrics.json");
  ASSERT_TRUE(metrics.contains("rti"));
  EXPECT_EQ(metrics["rti"]["format"], "HSH");
  EXPECT_EQ(metrics["rti"]["hsh_order"], 2);  // 7 lamps
  EXPECT_GT(metrics["rti"]["residual_rms_levels"].get<double>(), 0.0);

  ASSERT_EQ(run("repaint" + pair + " --map " + (dir / "tr").string() + " --video " + seq + " --out " + (dir / "rep").string()), 0);
  ASSERT_EQ(run("eval --live " + (dir / "rep").string() + " --truth " + seq), 0);
  // the video written through the video module (viewer/cli/video/) reads back through it: a video file as --video
  ASSERT_GT(fs::file_size(dir / "rep" / "repainted.mp4"), 0u);
  ASSERT_EQ(run("repaint" + pair + " --map " + (dir / "tr").string() + " --video " +
                (dir / "rep" / "repainted.mp4").string() + " --no-track --out " + (dir / "rep_mp4").string()),
            0);
  EXPECT_EQ(read_json(dir / "rep_mp4" / "report.json")["frames"], 5);
  const auto look = read_json(dir / "rep" / "live_look.json");
  ASSERT_TRUE(look.is_object());
  ASSERT_EQ(look["frames"].size(), 5u);
  EXPECT_GT(look["frames"][0]["samples"].get<long long>(), 100);
  EXPECT_TRUE(look["mean"].contains("shading_mean"));

  // usage errors: exit 2
  EXPECT_EQ(run("simulate --scene orange --light-path zigzag --out " + (dir / "bad").string()), 2);
  EXPECT_EQ(run("simulate --scene orange --light-path spiral --motion shift=1:0 --out " + (dir / "bad").string()), 2);
  EXPECT_EQ(run("eval --live " + (dir / "rep").string()), 2);  // no --truth
  EXPECT_EQ(run("transfer --no-cache --rti-format bogus --out " + (dir / "bad").string() + pair), 2);
  EXPECT_EQ(run("transfer --no-cache --rti " + (dir / "bad.rti").string() + " --rti-format hsh --hsh-order 3 --out " +
                (dir / "bad").string() + pair),
            2);  // 9 coefficients, 7 lamps
  EXPECT_FALSE(fs::exists(dir / "bad.rti"));
  fs::remove_all(dir);
}

// Issue 40's measure, small (tools/prototypes/live/simlive.sh runs it at 1024x680, 24 frames): the bull
// <- the orange, 6 frames of the spiral path, the live look (default map, shaded) against the pixel copy
// through the exact-nearest-normal map (linear, copy look), both scored by `veneer eval --live` against the
// truth frames, texture as look.py measures it (--map, --src), the light against light_path.json.
// Measured here (256x170, scale 2.5): live 0.153, copy 0.151 (ratio 1.01; 1.11 before the live look
// extrapolated off the rig's ring of lamps, LiveLookOptions::extrapolate; the goal of 0.7 is not met on the
// simulated pair, see simlive.sh), texture_corr min 0.24 (mean 0.43), light median 3.55 deg (1.6 before: the
// source's model extrapolated off the ring finds the light farther from the path's lamp at this size; at
// 1024x680 x 24, simlive.sh, 1.91 deg, within the goal of 3). The bounds guard what is, with room for the
// machine's noise.
TEST(LiveLookCli, SimulatedSequenceLiveAgainstCopy) {
  const fs::path dir = fs::temp_directory_path() / ("veneer-cli-simlive-" + std::to_string(::getpid()));
  fs::remove_all(dir);
  const std::string common = " --size 256x170 --scale 2.5 --overwrite";
  ASSERT_EQ(run("simulate --scene bull --role destination --out " + (dir / "dst").string() + common), 0);
  ASSERT_EQ(run("simulate --scene orange --role source --out " + (dir / "src").string() + common), 0);
  const std::string seq = (dir / "seq").string();
  ASSERT_EQ(run("simulate --scene bull --material orange --light-path spiral --frames 6 --out " + seq + common), 0);
  const std::string pair = " --dst " + (dir / "dst").string() + " --src " + (dir / "src").string();
  const std::string src = (dir / "src").string();
  ASSERT_EQ(run("transfer --no-cache --out " + (dir / "t_default").string() + pair), 0);
  ASSERT_EQ(run("repaint" + pair + " --map " + (dir / "t_default").string() + " --video " + seq + " --out " +
                (dir / "live").string()),
            0);
  ASSERT_EQ(run("transfer --no-cache --method linear --look copy --out " + (dir / "t_linear").string() + pair), 0);
  ASSERT_EQ(run("repaint --look copy" + pair + " --map " + (dir / "t_linear").string() + " --video " + seq +
                " --out " + (dir / "copy").string()),
            0);
  ASSERT_EQ(run("eval --live " + (dir / "live").string() + " --truth " + seq + " --map " +
                (dir / "t_default").string() + " --src " + src),
            0);
  ASSERT_EQ(run("eval --live " + (dir / "copy").string() + " --truth " + seq + " --map " +
                (dir / "t_linear").string() + " --src " + src),
            0);
  EXPECT_EQ(run("eval --live " + (dir / "live").string() + " --truth " + seq + " --map " +
                (dir / "t_default").string()),
            2);  // --map without --src
  const auto live = read_json(dir / "live" / "live_look.json");
  const auto copy = read_json(dir / "copy" / "live_look.json");
  ASSERT_TRUE(live.is_object() && copy.is_object());
  ASSERT_EQ(live["frames"].size(), 6u);
  EXPECT_TRUE(live["mean"]["texture_from_source"].get<bool>());
  const double live_mean = live["mean"]["shading_mean"].get<double>();
  const double copy_mean = copy["mean"]["shading_mean"].get<double>();
  const double ratio = live_mean / copy_mean;
  const double texture_min = live["mean"]["texture_corr_min"].get<double>();
  const double texture_mean = live["mean"]["texture_corr"].get<double>();
  const double light_median = live["mean"]["light_angle_median_deg"].get<double>();
  std::printf("simulated sequence: live %.4f, copy %.4f, ratio %.3f; texture_corr min %.3f mean %.3f; light median "
              "%.2f deg\n",
              live_mean, copy_mean, ratio, texture_min, texture_mean, light_median);
  EXPECT_LT(ratio, 0.97) << "measured 0.897 (1.008 before the unoccluded median and the wider dead zone; 1.11 "
                            "without extrapolating off the lamps' ring)";
  // the frame's own fine detail comes through only beyond the source model's error (change_dead_zone 1.0;
  // 0.25 before: min 0.24, mean 0.43); the still look's texture carries the rest
  EXPECT_GT(texture_min, 0.15) << "measured 0.196";
  EXPECT_GT(texture_mean, 0.24) << "measured 0.282";
  EXPECT_LT(light_median, 4.5) << "measured 3.55 deg at this size (1.91 at 1024x680, the goal of 3 met there)";
  for (const auto& f : live["frames"]) EXPECT_FALSE(f["light_angle_deg"].is_null()) << "every frame has its light";
  fs::remove_all(dir);
}

}  // namespace
