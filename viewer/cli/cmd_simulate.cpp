// veneer simulate — renders a scene under the thesis rig and writes a
// veneer-set/1 folder with its truth/ (normals, mask, albedo, depth).
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "command.hpp"
#include "output.hpp"
#include "veneer/io/camera_files.hpp"
#include "veneer/io/image_io.hpp"
#include "veneer/io/imageset.hpp"
#include "veneer/sim/light_path.hpp"
#include "veneer/sim/motion.hpp"
#include "veneer/sim/simulator.hpp"

namespace {

bool parse_size(const std::string& text, cv::Size* size) {
  int w = 0, h = 0;
  char x = 0, extra = 0;
  std::istringstream in(text);
  if (!(in >> w >> x >> h) || (x != 'x' && x != 'X') || (in >> extra)) return false;
  *size = {w, h};
  return true;
}

bool parse_vec3(const std::string& text, cv::Vec3d* v) {
  std::istringstream in(text);
  double a = 0, b = 0, c = 0;
  char s1 = 0, s2 = 0, extra = 0;
  if (!(in >> a >> s1 >> b >> s2 >> c) || s1 != ',' || s2 != ',' || (in >> extra)) return false;
  *v = {a, b, c};
  return true;
}

::veneer::cli::Output report{"simulate"};

struct SimulateArgs {
  std::string scene, material, out, size = "1024x680", offset = "0,0,0", role = "destination", preview, motion, light_path;
  int frames = 30;
  uint64_t seed = 1;
  double noise = 0.005, scale = 1.0, ambient = 0.0, exposure = 1.0, focal = 0.0;
  int threads = 0;
  bool list = false, overwrite = false, dng = false, optics = false;
};

// --motion: numbered frames of the scene moving (a live view with truth).
int run_motion(const SimulateArgs& a, const veneer::sim::RenderOptions& o) {
  auto spec = veneer::sim::parse_motion(a.motion);
  if (!spec) return report.usage("--motion: " + spec.message());
  if (a.frames < 1 || a.frames > 100000) return report.usage("--frames " + std::to_string(a.frames) + ": expected 1..100000");
  namespace fs = std::filesystem;
  if (fs::exists(a.out / fs::path("motion.json")) && !a.overwrite)
    return report.fail(a.out + ": already holds a sequence (use --overwrite)");
  if (auto st = report.folder(a.out); !st) return report.fail(st.message());
  veneer::cli::ProgressBar bar("simulate " + a.scene + " moving");
  veneer::Progress progress;
  progress.on_progress = [&bar](double f, const std::string& stage) { bar.update(f * 0.9, stage); };
  auto seq = veneer::sim::simulate_motion(a.scene, o, *spec, a.frames, progress);
  if (!seq) return seq.message().rfind("unknown scene", 0) == 0 ? report.usage(seq.message()) : report.fail(seq.message());
  std::vector<std::string> files;
  for (size_t i = 0; i < seq->frames.size(); ++i) {
    char name[32];
    std::snprintf(name, sizeof name, "frame_%04zu.png", i);
    files.emplace_back(name);
    if (auto st = report.picture(name, seq->frames[i]); !st) return report.fail(st.message());
  }
  if (auto st = veneer::sim::write_motion_json(report.path("motion.json"), *seq, a.motion, files); !st)
    return report.fail(st.message());
  bar.update(1.0, "done");
  bar.done();
  return report.wrote("scene " + a.scene + " moving (" + a.motion + "), " + std::to_string(files.size()) + " frames " +
                      std::to_string(o.size.width) + "x" + std::to_string(o.size.height) + " (8-bit sRGB PNG) + motion.json");
}

// --light-path: the source, still, under one lamp moving on a path (a live
// sequence to measure the live look against); with --material the truth frames.
int run_light_path(const SimulateArgs& a, const veneer::sim::RenderOptions& o) {
  namespace fs = std::filesystem;
  auto spec = veneer::sim::parse_light_path(a.light_path);
  if (!spec) return report.usage("--light-path: " + spec.message());
  if (a.frames < 1 || a.frames > 100000) return report.usage("--frames " + std::to_string(a.frames) + ": expected 1..100000");
  // --material names the source (the scene the live camera sees); --scene is then the destination
  const std::string source = a.material.empty() ? a.scene : a.material;
  const std::string destination = a.material.empty() ? "" : a.scene;
  if (fs::exists(a.out / fs::path("light_path.json")) && !a.overwrite)
    return report.fail(a.out + ": already holds a sequence (use --overwrite)");
  if (auto st = report.folder(a.out); !st) return report.fail(st.message());
  veneer::cli::ProgressBar bar("simulate " + source + " under a moving lamp");
  veneer::Progress progress;
  progress.on_progress = [&bar](double f, const std::string& stage) { bar.update(f * 0.9, stage); };
  auto seq = veneer::sim::simulate_light_path(source, destination, o, *spec, a.frames, progress);
  if (!seq) return seq.message().rfind("unknown scene", 0) == 0 ? report.usage(seq.message()) : report.fail(seq.message());
  veneer::sim::LightPathFile sidecar;
  sidecar.spec = a.light_path.empty() ? spec->name : a.light_path;
  sidecar.source = source;
  sidecar.destination = destination;
  sidecar.size = o.size;
  sidecar.lights = seq->lights;
  if (!seq->truth.empty()) {
    std::error_code ec;
    fs::create_directories(report.path("truth"), ec);
    if (ec) return report.fail(report.path("truth").string() + ": " + ec.message());
    sidecar.truth_mask = "truth/mask.png";
    if (auto st = report.picture(sidecar.truth_mask, seq->truth_mask); !st) return report.fail(st.message());
  }
  for (size_t i = 0; i < seq->frames.size(); ++i) {
    char name[48];
    std::snprintf(name, sizeof name, "frame_%04zu.png", i);
    sidecar.files.emplace_back(name);
    if (auto st = report.picture(name, seq->frames[i]); !st) return report.fail(st.message());
    if (!seq->truth.empty()) {
      std::snprintf(name, sizeof name, "truth/frame_%04zu.png", i);
      sidecar.truth_files.emplace_back(name);
      if (auto st = veneer::io::write_png16(report.path(name), seq->truth[i]); !st) return report.fail(st.message());
    }
  }
  // motion.json: the object stays at the stills' pose, so `veneer repaint --video` registers it as a motion sequence
  veneer::sim::MotionSequence still;
  still.frames = seq->frames;
  still.centre = seq->centre;
  still.mask = seq->mask;
  for (const auto& l : seq->lights) still.truth.push_back({cv::Matx23d(1, 0, 0, 0, 1, 0), l.position_m});
  if (auto st = veneer::sim::write_motion_json(report.path("motion.json"), still, "light-path=" + sidecar.spec, sidecar.files); !st)
    return report.fail(st.message());
  if (auto st = veneer::sim::write_light_path_json(report.path("light_path.json"), sidecar); !st)
    return report.fail(st.message());
  bar.update(1.0, "done");
  bar.done();
  return report.wrote("scene " + source + " under a lamp on the " + sidecar.spec + " path, " +
                      std::to_string(sidecar.files.size()) + " frames " + std::to_string(o.size.width) + "x" +
                      std::to_string(o.size.height) + " (8-bit sRGB PNG) + motion.json + light_path.json" +
                      (destination.empty() ? "" : " + truth/ (" + destination + " in " + source + "'s material, 16-bit linear)"));
}

int run_simulate(const SimulateArgs& a) {
  if (a.list) {
    for (const auto& name : veneer::sim::scene_names()) {
      std::string padded = name;
      padded.resize(std::max<size_t>(padded.size() + 2, 18), ' ');
      std::cout << padded << veneer::sim::scene_description(name) << "\n";
    }
    return 0;
  }
  if (a.scene.empty()) return report.usage("--scene is required (see --list)");
  if (a.out.empty()) return report.usage("--out is required");
  veneer::sim::RenderOptions o{.focal_px = a.focal, .exposure = a.exposure, .noise_sigma = a.noise,
                               .ambient = a.ambient, .seed = a.seed, .scale = a.scale, .threads = a.threads};
  if (!parse_size(a.size, &o.size)) return report.usage("--size '" + a.size + "': expected WIDTHxHEIGHT, e.g. 1024x680");
  if (!parse_vec3(a.offset, &o.offset_m)) return report.usage("--offset '" + a.offset + "': expected x,y,z in metres");
  auto role = veneer::io::parse_role(a.role);
  if (!role || *role == veneer::io::Role::unknown) return report.usage("--role '" + a.role + "': expected destination or source");
  if (a.optics) o.camera_optics();
  if (auto st = o.check(); !st) return report.usage(st.message());
  if (!a.light_path.empty()) {
    if (!a.motion.empty()) return report.usage("--light-path and --motion: one sequence at a time");
    return run_light_path(a, o);
  }
  if (!a.motion.empty()) {
    if (!a.material.empty()) return report.usage("--material renders a set, not a --motion sequence");
    return run_motion(a, o);
  }

  veneer::cli::ProgressBar bar("simulate " + a.scene);
  veneer::Progress progress;
  progress.on_progress = [&bar](double f, const std::string& stage) { bar.update(f * 0.8, stage); };
  auto set = a.material.empty() ? veneer::sim::simulate_set(a.scene, o, *role, progress)
                                : veneer::sim::simulate_set_with_material(a.scene, a.material, o, *role, progress);
  if (!set) return set.message().rfind("unknown scene", 0) == 0 ? report.usage(set.message()) : report.fail(set.message());
  if (a.dng) {
    // The rig's camera twin's files: the developed JPEG as the photo and the
    // lossless DNG (with its embedded preview) beside it.
    bar.update(0.82, "camera files (JPEG + DNG)");
    if (auto st = veneer::io::add_camera_files(*set); !st) return report.fail(st.message());
  }
  bar.update(0.85, "writing " + a.out);
  if (auto st = veneer::io::write_set(*set, a.out, a.overwrite); !st) return report.fail(st.message());
  if (!a.preview.empty()) {
    // what a person would want to see first: every lamp on at once
    cv::Mat sum = cv::Mat::zeros(set->size, CV_32FC3);
    for (const auto& im : set->images) sum += im;
    if (auto st = report.picture(a.preview, veneer::io::tonemap_picture(sum)); !st) return report.fail(st.message());
  }
  bar.update(1.0, "done");
  bar.done();
  int pixels = cv::countNonZero(set->truth.mask);
  report.line("wrote " + a.out + ": scene " + a.scene + (a.material.empty() ? "" : " in " + a.material + "'s material") + ", " + std::to_string(set->images.size()) + " lamps + ambient, " +
              std::to_string(o.size.width) + "x" + std::to_string(o.size.height) + ", " + std::to_string(pixels) +
              " object pixels");
  return 0;
}

}  // namespace

VENEER_ARGS_COMMAND(simulate, SimulateArgs,
                    "render a scene under the simulated thesis rig (7 lamps on a 0.47 m ring, object at 1 m) "
                    "and write a veneer-set/1 folder with truth/") {
  cmd->add_option("--scene", args->scene, "scene name (see --list)");
  cmd->add_option("--material", args->material,
                  "render the scene's shape in this scene's material (albedo texture and gloss), same lamps and "
                  "pose: the look a perfect transfer of that source onto this destination gives (e.g. --scene bull "
                  "--material orange)");
  cmd->add_option("--out", args->out, "output set folder (written atomically)");
  cmd->add_flag("--list", args->list, "list the scene names and exit");
  cmd->add_option("--size", args->size, "image size WIDTHxHEIGHT")->capture_default_str();
  cmd->add_option("--seed", args->seed, "noise seed (same seed, same bytes)")->capture_default_str();
  cmd->add_option("--noise", args->noise,
                  "sensor noise std-dev as a fraction of full scale (0.005 ~ a DSLR at ISO 100 in 16-bit linear)")
      ->capture_default_str();
  cmd->add_option("--offset", args->offset, "move the object by x,y,z metres in the rig frame")->capture_default_str();
  cmd->add_option("--scale", args->scale, "scale the object about its base (2.5 fills the frame, ~150 000 pixels at 1024x680)")
      ->capture_default_str();
  cmd->add_option("--focal", args->focal, "focal length in pixels (0 = 2 x width, the thesis framing)")
      ->capture_default_str();
  cmd->add_option("--ambient", args->ambient, "uniform ambient light level (room light leaking in)")
      ->capture_default_str();
  cmd->add_option("--exposure", args->exposure, "linear exposure gain (1 = a well-exposed rig shot)")
      ->capture_default_str();
  cmd->add_option("--role", args->role, "destination | source")->capture_default_str();
  cmd->add_option("--threads", args->threads, "worker threads (0 = all cores)")->capture_default_str();
  cmd->add_flag("--overwrite", args->overwrite, "replace an existing set folder");
  cmd->add_flag("--optics", args->optics,
                "render through a camera's optics, as the simulated rig does: 4x4 samples per pixel at outlines and "
                "creases, a 1 px optical low-pass filter, truth over the same footprint (what a RAW file's "
                "demosaicing needs; default: point-sampled)");
  cmd->add_flag("--dng", args->dng,
                "write each photo as a camera set to RAW+JPEG delivers it, as the simulated rig does: the developed "
                "photo light_NN.jpg (sRGB, 8-bit) and the RAW file light_NN.dng (RGGB mosaic, 14-bit, as-shot white "
                "balance, lossless JPEG compressed, a 1/4-size preview embedded), both named in set.json; the set "
                "is read through the RAW path");
  cmd->add_option("--motion", args->motion,
                  "render the source moving instead of a set: the total motion over the frames, comma-separated, "
                  "e.g. shift=30:0,rotate=5,scale=1.05,turn=3,lamp=sweep (shift in image pixels, rotate and turn "
                  "in degrees); writes frame_NNNN.png (8-bit sRGB) and motion.json (the true still->frame "
                  "affine per frame) into --out; frame 0 is the pose of a set rendered with the same options");
  cmd->add_option("--light-path", args->light_path,
                  "render a live sequence instead of a set: the source, still, under one lamp moving on a path "
                  "between and beyond the rig's lamps: spiral (3.6 to 48.4 degrees off the camera's axis over half "
                  "a turn, across the ring of lamps between two of them), circle (40.9 degrees, beyond the ring) or arc (15.3 degrees, "
                  "over the top), optionally with overrides, e.g. circle,radius=0.5,height=0.9,from=0,to=360,"
                  "colour=1:0.9:0.8; writes frame_NNNN.png (8-bit sRGB), motion.json (for veneer repaint --video) "
                  "and light_path.json (the lamp per frame); the source is --scene, or with --material that scene "
                  "and then --scene is the destination: truth/frame_NNNN.png (16-bit linear, no noise) are the "
                  "destination in the source's material under the same lamp, truth/mask.png its object");
  cmd->add_option("--frames", args->frames, "with --motion or --light-path: how many frames")->capture_default_str();
  cmd->add_option("--preview", args->preview, "also write an 8-bit picture of all lamps on (PNG)");
  return [args] { return run_simulate(*args); };
}
