#pragma once
// Analytic convex primitives for the scene simulator. Every primitive is
// convex, so a ray that starts outside it enters it at most once; a scene is a
// union of primitives, and a visible surface point of a union lies outside all
// of them. That lets one routine serve camera rays and shadow rays alike: the
// first entering hit with t in (t_min, t_max).
#include <cmath>
#include <cstdint>
#include <vector>

namespace veneer::sim {

struct V3 {
  double x = 0, y = 0, z = 0;
  V3() = default;
  constexpr V3(double x_, double y_, double z_) : x(x_), y(y_), z(z_) {}
  V3 operator+(const V3& o) const { return {x + o.x, y + o.y, z + o.z}; }
  V3 operator-(const V3& o) const { return {x - o.x, y - o.y, z - o.z}; }
  V3 operator-() const { return {-x, -y, -z}; }
  V3 operator*(double s) const { return {x * s, y * s, z * s}; }
  V3 operator/(double s) const { return {x / s, y / s, z / s}; }
  V3& operator+=(const V3& o) { x += o.x; y += o.y; z += o.z; return *this; }
  double operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }
};
inline V3 operator*(double s, const V3& v) { return v * s; }
inline double dot(const V3& a, const V3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline V3 cross(const V3& a, const V3& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline double length(const V3& v) { return std::sqrt(dot(v, v)); }
inline V3 normalize(const V3& v) {
  double l = length(v);
  return l > 0 ? v / l : V3{0, 0, 0};
}
inline V3 mul(const V3& a, const V3& b) { return {a.x * b.x, a.y * b.y, a.z * b.z}; }
inline V3 lerp(const V3& a, const V3& b, double t) { return a + (b - a) * t; }

// Rotation matrix, rows r[0..2]; apply: R * v; transpose: R^T * v.
struct M3 {
  V3 r[3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  V3 operator*(const V3& v) const { return {dot(r[0], v), dot(r[1], v), dot(r[2], v)}; }
  V3 tmul(const V3& v) const { return r[0] * v.x + r[1] * v.y + r[2] * v.z; }
  M3 operator*(const M3& o) const;
  static M3 rot_x(double rad);
  static M3 rot_y(double rad);
  static M3 rot_z(double rad);
};

enum class PrimKind : uint8_t { ellipsoid, box, round_cone, cylinder, cup };

// One convex primitive.
//  ellipsoid:  centre c, rotation R (local->world), radii h.
//  box:        centre c, rotation R, half extents h.
//  round_cone: segment a..b, radius ra at a and rb at b (a capsule when equal):
//              the union of the spheres along the segment with linearly varying radius.
//  cylinder:   capped, axis a..b, radius ra.
//  cup:        an open vessel: cylinder a..b of radius ra, hollowed from the top
//              down to a floor h.x thick, leaving walls ra - rb thick. The one
//              non-convex primitive: its routine also serves rays starting in the hollow.
struct Primitive {
  PrimKind kind = PrimKind::ellipsoid;
  V3 c, h{1, 1, 1};
  M3 R;
  V3 a, b;
  double ra = 0, rb = 0;
  int part = 0;  // scene-specific tag, handed to the material (e.g. 0 = body, 1 = handle)
  // bounding sphere (filled by finish())
  V3 bc;
  double br = 0;

  static Primitive sphere(V3 centre, double radius, int part = 0);
  static Primitive ellipsoid(V3 centre, V3 radii, M3 rotation = {}, int part = 0);
  static Primitive box(V3 centre, V3 half, M3 rotation = {}, int part = 0);
  static Primitive round_cone(V3 a, V3 b, double ra, double rb, int part = 0);
  static Primitive capsule(V3 a, V3 b, double r, int part = 0) { return round_cone(a, b, r, r, part); }
  static Primitive cylinder(V3 a, V3 b, double r, int part = 0);
  static Primitive cup(V3 bottom, V3 top, double outer, double inner, double floor, int part = 0);

  void finish();                   // computes the bounding sphere
  double min_z() const;            // the lowest z of the primitive (its support toward -z)
  // First entering hit of the ray o + t d (d need not be unit) with t in (t_min, t_max):
  // returns t (or -1) and the outward unit normal.
  double intersect(const V3& o, const V3& d, double t_min, double t_max, V3* normal) const;
  // Inside test (the oracle the tests compare intersect() against).
  bool inside(const V3& p) const;
};

// Union of primitives with a bounding sphere around all of them.
struct Shape {
  std::vector<Primitive> prims;
  V3 bc;
  double br = 0;
  void finish();
  double min_z() const;
  // Nearest hit; returns t or -1 and fills normal / index of the primitive.
  double intersect(const V3& o, const V3& d, double t_min, double t_max, V3* normal, int* prim) const;
  // Any hit in (t_min, t_max) (shadow rays).
  bool occluded(const V3& o, const V3& d, double t_min, double t_max) const;
};

}  // namespace veneer::sim
