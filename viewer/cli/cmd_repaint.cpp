// veneer repaint — a recorded video (or numbered frames) of the source,
// each frame registered to the source's stills (match/track.hpp) and carried
// through the map onto the destination (issue 27's recorded-video path).
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include "veneer/io/codecs.hpp"
#include <opencv2/imgproc.hpp>

#include "command.hpp"
#include "inputs.hpp"
#include "output.hpp"
#include "video/video.hpp"
#include "veneer/io/image_io.hpp"
#include "veneer/io/imageset.hpp"
#include "veneer/pipeline/transfer.hpp"
#include "veneer/repaint/live.hpp"
#include "veneer/repaint/live_look.hpp"
#include "veneer/repaint/live_session.hpp"
#include "veneer/repaint/track.hpp"
#include "veneer/sim/motion.hpp"

namespace {

namespace fs = std::filesystem;
using namespace veneer;

struct RepaintArgs {
  std::string src, dst, map, video, out;
  std::string look = "shaded";
  bool no_track = false, overlay = false, no_shadows = false;
  int blend = -1;
  double min_correlation = repaint::TrackOptions{}.min_correlation;
};

::veneer::cli::Output report{"repaint"};

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const double pos = p * (v.size() - 1);
  const size_t i = static_cast<size_t>(pos);
  return i + 1 < v.size() ? v[i] + (pos - i) * (v[i + 1] - v[i]) : v[i];
}

// The frames of a folder (its motion.json's order when present, else the
// images sorted by name) or of a video file (through the video module,
// loaded only here), read lazily through `next`.
struct FrameSource {
  std::vector<fs::path> files;
  std::unique_ptr<cli::video::Reader> capture;
  size_t index = 0;
  bool next(cv::Mat* frame) {
    if (!files.empty()) {
      if (index >= files.size()) return false;
      *frame = veneer::io::codecs::imread(files[index++].string(), cv::IMREAD_COLOR);
      return !frame->empty();
    }
    return capture && capture->read(frame);
  }
};

nlohmann::json light_json(const repaint::LiveLight& l) {
  nlohmann::json j = {{"direction", {l.direction[0], l.direction[1], l.direction[2]}},
                      {"colour", {l.colour[0], l.colour[1], l.colour[2]}},
                      {"intensity", l.intensity},
                      {"ambient", l.ambient},
                      {"residual", l.residual},
                      {"explained", l.explained},
                      {"fallback", l.fallback}};
  if (l.position_m) j["position_m"] = {(*l.position_m)[0], (*l.position_m)[1], (*l.position_m)[2]};
  return j;
}

int run_repaint(const RepaintArgs& a) {
  auto look = repaint::parse_look(a.look);
  if (!look) return report.usage("--look: " + look.message());
  // the video first: a missing input is the most likely mistake
  FrameSource frames;
  std::optional<sim::MotionTruth> truth;
  const fs::path video(a.video);
  if (!fs::exists(video)) return report.usage("--video " + a.video + ": no such file or folder");
  if (fs::is_directory(video)) {
    if (fs::exists(video / "motion.json")) {
      auto t = sim::read_motion_json(video / "motion.json");
      if (!t) return report.fail(t.message());
      for (const auto& f : t->files) frames.files.push_back(video / f);
      truth = std::move(*t);
    } else {
      for (const auto& e : fs::directory_iterator(video)) {
        const auto ext = e.path().extension().string();
        if (ext == ".png" || ext == ".jpg" || ext == ".jpeg" || ext == ".PNG" || ext == ".JPG")
          frames.files.push_back(e.path());
      }
      std::sort(frames.files.begin(), frames.files.end());
    }
    if (frames.files.empty()) return report.usage("--video " + a.video + ": the folder holds no frames (PNG or JPEG)");
  } else {
    auto reader = cli::video::open_reader(a.video);
    if (!reader) return report.usage("--video " + reader.message());
    frames.capture = std::move(*reader);
  }

  const fs::path map_file = cli::map_file(a.map);
  auto map = match::read_map(map_file);
  if (!map) return report.fail(map.message());
  pipeline::TransferOptions options;
  if (fs::exists(map_file.parent_path() / "metrics.json")) {
    auto read = pipeline::read_transfer_options(map_file.parent_path() / "metrics.json");
    if (!read) return report.fail(read.message());
    options = *read;
  }
  auto src = io::read_set(a.src);
  if (!src) return report.fail(src.message());
  auto dst = io::read_set(a.dst);
  if (!dst) return report.fail(dst.message());
  if (!fs::exists(map_file.parent_path() / "metrics.json")) options.scale = pipeline::map_scale(*map, *dst);
  const cv::Mat backdrop = io::tonemap_picture(repaint::lit_photo(dst->images));
  auto mask = match::object_mask(*src, false);
  if (!mask) return report.fail("source: " + mask.message());
  cv::Mat still_mask = *mask;
  if (still_mask.size() != src->size) cv::resize(still_mask, still_mask, src->size, 0, 0, cv::INTER_NEAREST);

  const cv::Size source_size = match::scaled_size(src->size, options.scale);
  // Frames are blended as the transfer's pictures were (its metrics.json), as `veneer rig live` does.
  if (a.blend >= 0) options.blend = a.blend;
  std::shared_ptr<const match::fast::BlendPlan> plan;
  std::optional<pipeline::PreparedPair> pair;
  if (options.blend > 0 || *look == repaint::Look::shaded) {
    auto prepared = pipeline::prepare_pair(*dst, *src, options);
    if (!prepared) return report.fail(prepared.message());
    pair = std::move(*prepared);
  }
  if (options.blend > 0) {
    auto made = pipeline::blend_plan_for(*pair, options, *map);
    if (!made) return report.fail(made.message());
    plan = *made;
  }
  // the shaded look: the still look of this map, and what the live frames are painted with at their light
  std::shared_ptr<const repaint::LiveLook> live_look;
  double look_s = 0;
  if (*look == repaint::Look::shaded) {
    const auto t0 = std::chrono::steady_clock::now();
    repaint::LiveLookOptions live_options;
    live_options.shadows = !a.no_shadows;
    auto made = pipeline::live_look(*pair, options, *map, nullptr, live_options);
    if (!made) return report.fail("the shaded look: " + made.message());
    live_look = *made;
    look_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }
  repaint::TrackOptions track_options;
  track_options.min_correlation = a.min_correlation;
  if (auto st = track_options.check(); !st) return report.usage("--min-correlation: " + st.message());
  // tracking, repaint, outline and the live view's framing: what the viewer's Live tab runs
  repaint::LiveSession session(src->images, still_mask, *map, source_size, live_look, backdrop, plan, track_options);
  session.set_look(*look);
  session.set_smooth(true);  // offline: bilinear, no frame budget

  std::unique_ptr<cli::video::Writer> writer;
  fs::path mp4;  // in the output folder, once it is made (the first frame)
  nlohmann::json per_frame = nlohmann::json::array();
  std::vector<double> ms, errors;
  int lost = 0, count = 0, fallbacks = 0;
  cv::Mat frame;
  while (frames.next(&frame)) {
    const auto t0 = std::chrono::steady_clock::now();
    auto live = a.no_track ? session.process_untracked(frame) : session.process(frame);
    // the first frame decides whether the live view relates to the stills: refused before anything is written
    if (!live) return report.fail("frame " + std::to_string(count) + ": " + live.message());
    if (count == 0) {
      if (auto st = report.folder(a.out); !st) return report.fail(st.message());
      mp4 = report.path("repainted.mp4");
      if (!session.geometry()->same) std::cout << "live view: " << session.geometry()->describe() << "\n";
    }
    repaint::TrackResult r;
    r.lost = live->lost;
    r.correlation = live->quality;
    r.still_to_frame = live->still_to_frame;
    const cv::Mat& out = live->repainted;
    const double elapsed = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    ms.push_back(elapsed);
    char name[32];
    std::snprintf(name, sizeof name, "frame_%04d.png", count);
    if (auto st = report.picture(name, out); !st) return report.fail(st.message());
    if (a.overlay) {
      std::snprintf(name, sizeof name, "align_%04d.png", count);
      if (auto st = report.picture(name, repaint::alignment_picture(frame, still_mask, r)); !st)
        return report.fail(st.message());
      std::snprintf(name, sizeof name, "frame_%04d.png", count);
    }
    if (count == 0) {
      // the frames (PNG) are the result; the video beside them is a convenience, left out when it cannot be made
      auto opened = cli::video::open_writer(mp4.string(), 30.0, out.cols, out.rows);
      if (opened) writer = std::move(*opened);
      else std::cerr << "veneer repaint: no repainted.mp4: " << opened.message() << "\n";
    }
    if (writer) writer->write(out);
    nlohmann::json f = {{"file", name}, {"ms", elapsed}, {"lost", r.lost}, {"correlation", r.correlation},
                        {"look", repaint::look_name(live->look)}};
    if (live->light) {
      f["light"] = light_json(*live->light);
      f["light_ms"] = live->light_ms;
      f["shade_ms"] = live->shade_ms;
      fallbacks += !live->light->explained;
    }
    const auto& e = r.still_to_frame;
    f["still_to_frame"] = {{e(0, 0), e(0, 1), e(0, 2)}, {e(1, 0), e(1, 1), e(1, 2)}};
    if (truth && static_cast<size_t>(count) < truth->truth.size() && !r.lost) {
      const double e = repaint::motion_error_px(r.still_to_frame, truth->truth[count].still_to_frame, still_mask);
      errors.push_back(e);
      f["align_error_px"] = e;
    }
    per_frame.push_back(f);
    lost += r.lost;
    ++count;
  }
  if (count == 0) return report.fail("--video " + a.video + ": no frame could be read");
  if (writer) writer->close();
  nlohmann::json doc = {{"frames", count},
                           {"lost", lost},
                           {"tracking", !a.no_track},
                           {"look", a.look},
                           {"look_setup_s", look_s},
                           {"light_not_explained", fallbacks},
                           {"blend_px", plan ? options.blend : 0},
                           {"method", a.no_track ? "none (the stills' pose)" : "ECC affine, coarse to fine, seeded from the previous frame"},
                           {"ms_per_frame", {{"median", percentile(ms, 0.5)}, {"p95", percentile(ms, 0.95)}}},
                           {"video", fs::exists(mp4) ? "repainted.mp4" : ""},
                           {"per_frame", per_frame}};
  if (const auto& g = session.geometry()) {
    doc["live_view"] = {{"size", {g->live.width, g->live.height}},
                           {"stills", {g->still.width, g->still.height}},
                           {"scale", g->scale},
                           {"offset_px", {g->offset[0], g->offset[1]}},
                           {"framed_as_stills", g->same},
                           {"note", g->describe()}};
  }
  if (truth)
    doc["align_error_px"] = {{"median", percentile(errors, 0.5)}, {"p95", percentile(errors, 0.95)},
                                {"frames_measured", errors.size()}};
  if (auto st = report.json("report.json", doc, 1); !st) return report.fail(st.message());
  std::ostringstream line;
  line << "repainted " << count << " frames into " << a.out << " (" << lost << " lost), " << percentile(ms, 0.5)
       << " ms per frame median";
  if (truth) line << ", alignment error median " << percentile(errors, 0.5) << " px, p95 " << percentile(errors, 0.95) << " px";
  report.line(line.str());
  return 0;
}

}  // namespace

VENEER_ARGS_COMMAND(repaint, RepaintArgs,
                    "repaint a recorded video of the source onto the destination through a map, each "
                    "frame registered to the source's stills") {
  cmd->add_option("--src", args->src, "the source set the map was computed against")->required();
  cmd->add_option("--dst", args->dst, "the destination set (its picture shows where nothing is mapped)")->required();
  cmd->add_option("--map", args->map, "a transfer folder or its map.pfm")->required();
  cmd->add_option("--video", args->video,
                  "a video file, or a folder of numbered frames (with `veneer simulate --motion`'s motion.json, the "
                  "alignment error is measured)")
      ->required();
  cmd->add_option("--out", args->out, "output folder: frame_NNNN.png, repainted.mp4, report.json")->required();
  cmd->add_flag("--overlay", args->overlay,
                "also write align_NNNN.png: each frame with the source's outline where it was found (green; red "
                "when lost) and the ECC correlation");
  cmd->add_option("--blend", args->blend,
                  "blend the chunks' seams over this radius, 0..16 px (default: as the transfer did, its metrics.json)");
  cmd->add_flag("--no-track", args->no_track, "look frames up at the stills' pose (the old live view)");
  cmd->add_flag("--no-shadows", args->no_shadows,
                "shaded look: the destination's cast shadows only as its photos hold them, not the light's own");
  cmd->add_option("--look", args->look,
                  "shaded: each frame painted as the still look at the light estimated in it (the default); copy: "
                  "the frame's pixels copied through the map")
      ->capture_default_str();
  cmd->add_option("--min-correlation", args->min_correlation, "ECC correlation below this marks a frame lost (0..1)")
      ->capture_default_str();
  return [args] { return run_repaint(*args); };
}
