#pragma once
// The scene simulator: a ray caster that renders a named scene (after the
// thesis's objects) under any set of point lamps in the rig frame, as the
// rig's camera would see it. Used by `veneer simulate`, the simulated camera of
// veneerd, and every quality test (its ground truth is the oracle).
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/io/imageset.hpp"
#include "veneer/util/expected.hpp"
#include "veneer/util/progress.hpp"

namespace veneer::sim {

struct Lamp {
  cv::Vec3d position_m;        // rig frame
  cv::Vec3f color{1, 1, 1};    // [r, g, b] radiant intensity, 1 = a rig lamp at full white
  float brightness = 1.0f;     // 0..1 multiplier (Hue bri / 254)
};

// The thesis rig: 8 sockets on a 0.47 m circle around the camera at (0,0,1),
// the bottom socket empty, so 7 lamps. Index order is the order used in sets:
// starting at the top socket and going clockwise as seen in the picture (from
// the camera looking at the object): 0 top, 1 top-right, 2 right, 3 bottom-right,
// 4 bottom-left, 5 left, 6 top-left. A lamp at full white delivers irradiance 1
// at the origin (its radiant intensity is |position|^2 = 1 + 0.47^2).
std::vector<Lamp> thesis_rig();

struct RenderOptions {
  cv::Size size{1024, 680};     // image size [px]
  double focal_px = 0;          // pinhole focal length [px]; 0 = the rig default, 2 x width: an 8 cm
                                // object covers ~21 000 px at 1024x680 as in the thesis, and smaller
                                // renders show the same framing. Principal point: the image centre.
  double exposure = 1.0;        // linear gain on radiance (1 = a well-exposed rig shot)
  double noise_sigma = 0.0;     // sensor noise, std-dev as a fraction of full scale (Gaussian, added
                                // after exposure, before clipping; `veneer simulate` defaults to 0.005)
  double ambient = 0.0;         // uniform ambient light level (room light leaking in)
  uint64_t seed = 1;            // noise seed; same seed, same bytes
  uint32_t shot = 0;            // noise stream within a seed: shots with different `shot` get
                                // independent noise (simulate_set: light index; ambient frame 255)
  cv::Vec3d offset_m{0, 0, 0};  // moves the whole object (and its table) in the rig frame [m]
  double scale = 1.0;           // scales the object about its base (the point where it rests on
                                // the table behind it); 2.5 fills a 1024x680 frame (~150 000 px)
  int threads = 0;              // 0 = all cores
  bool cast_shadows = true;     // false: a lamp lights every point facing it, blocked or not (the
                                // relighting measure's way to find the cast shadows, match/metrics.hpp)
  // The camera's optics: a real sensor sees a band-limited image (lens and optical low-pass filter,
  // each pixel integrating its square), which is what demosaicing a Bayer mosaic relies on. Both the
  // photo and its RAW mosaic come from that image, and the truth is what the same footprint averages.
  // Off by default (point sampling, what the quality tests' thresholds were set on); the rig's camera
  // twin and the RAW tests turn them on with camera_optics().
  int edge_samples = 1;         // samples per side over each pixel whose neighbours see other geometry
                                // (outline, crease, fold): the pixel's box aperture where a point
                                // sample would alias; 1 = point sampling only
  double olpf_spread_px = 0.0;  // optical low-pass filter: a birefringent filter splitting each ray
                                // into 4 spots this far apart [px] in x and y, applied before noise
                                // and clipping; 1 (a camera's usual) = kernel [1/4 1/2 1/4] per axis,
                                // zero response at the Nyquist frequency; 0 = none; at most 2
  // A real camera's optics: 4x4 samples at outlines and creases, a 1 px low-pass filter.
  RenderOptions& camera_optics() {
    edge_samples = 4;
    olpf_spread_px = 1.0;
    return *this;
  }
  Status check() const;
};

class Scene;  // opaque: primitives + materials

// Names: orange apple banana cup-dots cup-white two-spheres blocks stone bull
// sphere-gray sphere-red-gloss.
std::vector<std::string> scene_names();
// One line saying what the scene is (empty for an unknown name).
std::string scene_description(const std::string& name);
Expected<std::shared_ptr<const Scene>> make_scene(const std::string& name, const RenderOptions& options);

// The shape (and placement) of `shape_scene` with the material of
// `material_scene`: e.g. the bull made of the red glossy sphere's stuff, the
// reference of the relighting measure (match/metrics.hpp).
Expected<std::shared_ptr<const Scene>> make_scene_with_material(const std::string& shape_scene,
                                                               const std::string& material_scene,
                                                               const RenderOptions& options);

// Renders linear BGR CV_32FC3 (clipped at 1.0 like a sensor) under `lamps`
// (all on at once; none = the ambient frame). The object's placement (offset_m,
// scale) is the one given to make_scene; here size, focal_px, exposure, noise,
// ambient, seed, shot, threads and the optics apply. Camera rays are cast once per image
// geometry and cached in the scene, so repeated renders only shade. Pixel
// value = exposure * (sum over lamps of albedo * E * max(0, n.l) + Blinn-Phong
// lobe * E, unless shadowed; + ambient * albedo) + noise, with E = the lamp's
// irradiance at the point (1/r^2), averaged over the pixel's samples and low-pass
// filtered before the noise. Thread-safe; empty when cancelled.
cv::Mat render(const Scene& scene, const std::vector<Lamp>& lamps, const RenderOptions& options,
               const Progress& progress = {});
// Truth for the scene as seen by the camera, over each pixel's footprint (its
// samples, then the optical low-pass filter): normals = the albedo-weighted
// mean normal of the object there, renormalised (what Lambertian photometric
// stereo recovers from a pixel that mixes several); mask = the object covers
// at least half the footprint; albedo and depth = their means over the object.
// Point-sampled when edge_samples = 1 and olpf_spread_px = 0.
io::Truth render_truth(const Scene& scene, const RenderOptions& options);

// A whole image set as the thesis rig would capture it: ambient frame + one shot
// per lamp, lights filled in with positions, directions (unit, origin -> lamp)
// and intensities (irradiance at the origin in image units, exposure folded in,
// so photometric stereo recovers the truth albedo), camera focal length and
// principal point, truth attached. Noise stream per shot: light index, 255 for
// the ambient frame. `created` honours SOURCE_DATE_EPOCH (byte-identical reruns).
Expected<io::ImageSet> simulate_set(const std::string& scene_name, const RenderOptions& options,
                                io::Role role = io::Role::unknown, const Progress& progress = {});

// The same for `shape_scene`'s shape in `material_scene`'s material
// (make_scene_with_material), under the same lamps and pose: the look a
// perfect transfer of material_scene onto shape_scene gives. The set's scene
// is the shape's; its object and id say "<shape>-in-<material>"; its truth
// albedo is the material's on the shape.
Expected<io::ImageSet> simulate_set_with_material(const std::string& shape_scene, const std::string& material_scene,
                                              const RenderOptions& options, io::Role role = io::Role::unknown,
                                              const Progress& progress = {});

}  // namespace veneer::sim
