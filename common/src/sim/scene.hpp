#pragma once
// The inside of a simulator scene: a union of primitives in object space, a
// material (albedo texture, bump, specular lobe) and the dark table behind it,
// plus the placement chosen by RenderOptions::offset_m and ::scale.
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

#include "geometry.hpp"
#include "veneer/sim/simulator.hpp"

namespace veneer::sim {

// What the material says about a surface point.
struct SurfaceSample {
  V3 albedo{0.5, 0.5, 0.5};  // linear RGB, Lambertian reflectance (1 = white)
  V3 normal;                 // shading normal (unit), object space; starts as the geometric normal
  double ks = 0;             // Blinn-Phong specular strength (white highlight)
  double shininess = 1;      // Blinn-Phong exponent
};

// p: point on the surface, n: geometric normal, both object space; prim: index
// into Shape::prims; part: that primitive's tag. Fills `out` (normal preset to n).
using MaterialFn = std::function<void(const V3& p, const V3& n, int prim, int part, SurfaceSample* out)>;

// One pixel of the G-buffer (what the camera ray hit), world frame.
struct GPixel {
  float p[3];       // hit point
  float ng[3];      // geometric normal (offsets shadow rays, attached shadows)
  float n[3];       // shading normal
  float albedo[3];  // RGB
  float ks, shininess;
  int32_t prim;     // primitive hit (-1 = none: table or nothing)
  uint8_t kind;     // 0 = nothing, 1 = table, 2 = object, 3 = its base (a plinth: lit and shaded, not the object)
};

// The camera rays of one image geometry. Every pixel has its centre sample;
// a pixel whose centre differs from a neighbour's (an outline, a crease, an
// albedo edge, a bump at pixel scale) also has edge_samples^2 stratified
// samples over its square, which it is shaded from instead (the pixel's box
// aperture, where point sampling would alias).
struct GBuffer {
  cv::Size size;
  double focal = 0, cx = 0, cy = 0;
  int edge_samples = 1;          // samples per side at flagged pixels (1 = point sampling only)
  std::vector<GPixel> px;        // centre samples, row-major
  std::vector<uint32_t> first;   // size area + 1: the samples of pixel i are sub[first[i] .. first[i + 1])
                                 // (an empty range: the centre sample alone); empty when edge_samples = 1
  std::vector<GPixel> sub;
  // The samples a pixel integrates: [begin, end).
  std::pair<const GPixel*, const GPixel*> samples(size_t i) const {
    if (!first.empty() && first[i + 1] > first[i]) return {sub.data() + first[i], sub.data() + first[i + 1]};
    return {&px[i], &px[i] + 1};
  }
};

class Scene {
 public:
  std::string name;
  Shape shape;             // object space: metres, centred near the origin, y up
  MaterialFn material;
  int support_part = -1;   // Shape part tag of the base the object stands on (a plinth), -1 = none;
                           // rendered as the object is, but not in the truth's mask
  V3 table_albedo{0.04, 0.04, 0.04};
  double table_z = 0;      // object-space z of the table plane (faces +z, touches the object's back)
  // Placement: world = offset + base + scale * (p - base), base = (0, 0, table_z).
  V3 offset;
  double scale = 1;

  V3 to_object(const V3& world) const {
    V3 base{0, 0, table_z};
    return base + (world - offset - base) / scale;
  }
  V3 to_world(const V3& object) const {
    V3 base{0, 0, table_z};
    return offset + base + (object - base) * scale;
  }
  double table_world_z() const { return offset.z + table_z; }

  // The G-buffer for this image geometry, built once and cached.
  std::shared_ptr<const GBuffer> gbuffer(cv::Size size, double focal, int edge_samples, int threads) const;

 private:
  mutable std::mutex mutex_;
  mutable std::shared_ptr<const GBuffer> cache_;
};

// Builds the object (shape, material, table albedo) of a named scene; nullptr if unknown.
std::unique_ptr<Scene> build_scene(const std::string& name);

// Focal length [px] of the rig's default framing for an image `width` pixels wide.
double default_focal(int width);

}  // namespace veneer::sim
