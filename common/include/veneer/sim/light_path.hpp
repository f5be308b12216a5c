#pragma once
// A live sequence under one moving lamp (issue 40): the source object, still,
// lit by a single lamp travelling on a path that passes between and beyond
// the rig's captured lamps, as the live camera sees it (8-bit sRGB frames, a
// veneer-motion/1 motion.json so `veneer repaint --video` registers it as it
// registers a motion sequence); the light per frame in a sidecar
// (light_path.json); and, given the destination's scene, the truth per frame:
// the destination's shape in the source's material under the same lamp, what
// a perfect live look would show. The measure of the live look
// (eval/live_look.hpp) scores repainted frames against those.
#include <filesystem>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/sim/simulator.hpp"
#include "veneer/util/expected.hpp"
#include "veneer/util/progress.hpp"

namespace veneer::sim {

// The lamp's path in the rig frame: at height z = height_m, at distance
// radius (from the camera's axis, the z axis) going from inner_m at the first
// frame to radius_m at the last, at azimuth (clockwise from the top as seen in
// the picture, the rig's socket order: 0 top, 90 right) going from from_deg to
// to_deg. The rig's lamps sit at radius 0.47 m, height 1 m (25.2 degrees off
// the camera's axis), every 45 degrees from 0, the bottom (180) empty.
struct LightPathSpec {
  std::string name = "spiral";  // the named path the fields start from (spiral | circle | arc)
  double inner_m = 0.05;        // radius at the first frame [m]
  double radius_m = 0.9;        // radius at the last frame [m]
  double height_m = 0.8;        // the lamp's z [m] (> 0.05: in front of the object)
  double from_deg = 112.5;      // azimuth at the first frame [deg]
  double to_deg = 292.5;        // azimuth at the last frame [deg]
  bool closed = false;          // a closed loop: the last frame stops one step short of the first again
  cv::Vec3f colour{1, 1, 1};    // the lamp's colour [r, g, b] (1 = the rig's white)
  bool operator==(const LightPathSpec&) const = default;
  Status check() const;
};

// "spiral" (the default: from 3.6 to 48.4 degrees off the camera's axis over
// half a turn from the lower right to the left, inside the ring of lamps,
// across it at the empty bottom socket -- between the bottom-right and
// bottom-left lamps -- and beyond it; never nearer than 9.8 degrees to a lamp), "circle" (a closed turn 0.65 m out at 0.75 m:
// 40.9 degrees, beyond the ring, starting between the top and top-right
// sockets), "arc" (over the top from the left to the right, 0.3 m out at
// 1.1 m: 15.3 degrees, between the ring and the camera), each optionally
// followed by overrides: "circle,radius=0.5,height=0.9,from=0,to=360,inner=0.2,
// colour=1:0.9:0.8". The error names the bad part.
Expected<LightPathSpec> parse_light_path(const std::string& spec);
std::vector<std::string> light_path_names();

// The lamp of one frame.
struct PathLight {
  cv::Vec3d position_m;  // rig frame
  cv::Vec3d direction;   // unit, origin -> lamp
  cv::Vec3f intensity;   // irradiance at the origin [r, g, b] in image units (exposure folded in, as set.json's
                         // lights): the lamp is as bright at the object as a rig lamp, whatever its distance
  cv::Vec3f colour;      // the spec's colour
  Lamp lamp;             // what the renderer is given
};
// The lamps of `frames` frames (frames >= 1) under `exposure` (RenderOptions::exposure).
std::vector<PathLight> light_path_lights(const LightPathSpec& spec, int frames, double exposure = 1.0);

struct LightSequence {
  std::vector<cv::Mat> frames;  // the source as the live camera sees it: 8-bit BGR, sRGB-encoded
  std::vector<cv::Mat> truth;   // the destination in the source's material: linear CV_32FC3 BGR (clipped at
                                // 1, no noise); empty without a destination
  cv::Mat truth_mask;           // the destination's object mask (CV_8UC1), empty without a destination
  std::vector<PathLight> lights;
  cv::Point2d centre;           // the source's centre in the frame (mask centroid; the object stays still)
  cv::Mat mask;                 // the source's mask (CV_8UC1)
};

// Renders `frames` frames of `source_scene` (placement and size from
// `options`, noise stream per frame: shot = frame index) under the path's lamp
// (+ options.ambient) and, when `destination_scene` is not empty, the truth
// frames (make_scene_with_material(destination, source), no noise).
Expected<LightSequence> simulate_light_path(const std::string& source_scene, const std::string& destination_scene,
                                            const RenderOptions& options, const LightPathSpec& spec, int frames,
                                            const Progress& progress = {});

// light_path.json: {"format":"veneer-light-path/1","spec":"...","source":"...","destination":"...",
//  "size":[w,h],"units":"...","truth_mask":"truth/mask.png",
//  "frames":[{"file":"frame_0000.png","truth":"truth/frame_0000.png","position_m":[x,y,z],
//             "direction":[x,y,z],"intensity":[r,g,b],"colour":[r,g,b]}, ...]}
struct LightPathFile {
  std::string spec, source, destination;
  cv::Size size;
  std::vector<std::string> files, truth_files;  // truth_files empty (or entries "") without truth
  std::string truth_mask;                       // relative to the folder, "" without truth
  std::vector<PathLight> lights;                // lamp is filled from the position and intensity
};
Status write_light_path_json(const std::filesystem::path& file, const LightPathFile& contents);
Expected<LightPathFile> read_light_path_json(const std::filesystem::path& file);

}  // namespace veneer::sim
