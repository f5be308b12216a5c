#include "geometry.hpp"

#include <algorithm>
#include <limits>

namespace veneer::sim {

M3 M3::operator*(const M3& o) const {
  M3 m;
  for (int i = 0; i < 3; ++i) {
    // row i of (this * o) = sum_k this[i][k] * o.row(k)
    m.r[i] = o.r[0] * r[i].x + o.r[1] * r[i].y + o.r[2] * r[i].z;
  }
  return m;
}

namespace {

M3 rows(V3 r0, V3 r1, V3 r2) {
  M3 m;
  m.r[0] = r0;
  m.r[1] = r1;
  m.r[2] = r2;
  return m;
}

Primitive finished(Primitive p, PrimKind kind, int part) {
  p.kind = kind;
  p.part = part;
  p.finish();
  return p;
}

// A primitive placed by its centre, half extents (radii) and rotation.
Primitive centred(PrimKind kind, V3 centre, V3 half, M3 rotation, int part) {
  Primitive p;
  p.c = centre;
  p.h = half;
  p.R = rotation;
  return finished(p, kind, part);
}

// A primitive along the segment a..b, radius ra at a and rb at b.
Primitive along(PrimKind kind, V3 a, V3 b, double ra, double rb, int part) {
  Primitive p;
  p.a = a;
  p.b = b;
  p.ra = ra;
  p.rb = rb;
  return finished(p, kind, part);
}

}  // namespace

M3 M3::rot_x(double a) {
  const double c = std::cos(a), s = std::sin(a);
  return rows({1, 0, 0}, {0, c, -s}, {0, s, c});
}
M3 M3::rot_y(double a) {
  const double c = std::cos(a), s = std::sin(a);
  return rows({c, 0, s}, {0, 1, 0}, {-s, 0, c});
}
M3 M3::rot_z(double a) {
  const double c = std::cos(a), s = std::sin(a);
  return rows({c, -s, 0}, {s, c, 0}, {0, 0, 1});
}

Primitive Primitive::sphere(V3 centre, double radius, int part) {
  return ellipsoid(centre, {radius, radius, radius}, {}, part);
}

Primitive Primitive::ellipsoid(V3 centre, V3 radii, M3 rotation, int part) {
  return centred(PrimKind::ellipsoid, centre, radii, rotation, part);
}

Primitive Primitive::box(V3 centre, V3 half, M3 rotation, int part) {
  return centred(PrimKind::box, centre, half, rotation, part);
}

Primitive Primitive::round_cone(V3 a, V3 b, double ra, double rb, int part) {
  // The intersection routine wants the larger sphere at a.
  if (rb > ra) {
    std::swap(a, b);
    std::swap(ra, rb);
  }
  return along(PrimKind::round_cone, a, b, ra, rb, part);
}

Primitive Primitive::cylinder(V3 a, V3 b, double r, int part) { return along(PrimKind::cylinder, a, b, r, r, part); }

Primitive Primitive::cup(V3 bottom, V3 top, double outer, double inner, double floor, int part) {
  Primitive p = cylinder(bottom, top, outer, part);
  p.kind = PrimKind::cup;
  p.rb = inner;
  p.h = {floor, 0, 0};
  p.finish();
  return p;
}

void Primitive::finish() {
  switch (kind) {
    case PrimKind::ellipsoid:
      bc = c;
      br = std::max({h.x, h.y, h.z});
      break;
    case PrimKind::box:
      bc = c;
      br = length(h);
      break;
    case PrimKind::round_cone:
      bc = (a + b) * 0.5;
      br = length(b - a) * 0.5 + std::max(ra, rb);
      break;
    case PrimKind::cylinder:
    case PrimKind::cup:
      bc = (a + b) * 0.5;
      br = std::sqrt(dot(b - a, b - a) * 0.25 + ra * ra);
      break;
  }
}

double Primitive::min_z() const {
  switch (kind) {
    case PrimKind::ellipsoid: {
      // world z = c.z + row2(R) . (h * u), |u| = 1  ->  support = |row2(R) * h|
      V3 w = mul(R.r[2], h);
      return c.z - length(w);
    }
    case PrimKind::box:
      return c.z - (std::abs(R.r[2].x) * h.x + std::abs(R.r[2].y) * h.y + std::abs(R.r[2].z) * h.z);
    case PrimKind::round_cone:
      return std::min(a.z - ra, b.z - rb);
    case PrimKind::cylinder:
    case PrimKind::cup: {
      V3 w = normalize(b - a);
      double radial = ra * std::sqrt(std::max(0.0, 1.0 - w.z * w.z));
      return std::min(a.z, b.z) - radial;
    }
  }
  return c.z;
}

namespace {

constexpr double kMiss = -1.0;

bool sphere_hit_possible(const V3& o, const V3& d, const V3& c, double r) {
  V3 oc = o - c;
  double b = dot(oc, d);
  double cc = dot(oc, oc) - r * r;
  if (cc > 0 && b > 0) return false;  // outside and moving away
  return b * b - cc >= 0;             // d is unit
}

double hit_ellipsoid(const Primitive& p, const V3& o, const V3& d, double t_min, double t_max, V3* n) {
  V3 ol = p.R.tmul(o - p.c), dl = p.R.tmul(d);
  ol = {ol.x / p.h.x, ol.y / p.h.y, ol.z / p.h.z};
  dl = {dl.x / p.h.x, dl.y / p.h.y, dl.z / p.h.z};
  double a = dot(dl, dl), b = dot(ol, dl), c = dot(ol, ol) - 1.0;
  double disc = b * b - a * c;
  if (disc < 0) return kMiss;
  double t = (-b - std::sqrt(disc)) / a;
  if (t <= t_min || t >= t_max) return kMiss;
  V3 u = ol + dl * t;
  *n = normalize(p.R * V3{u.x / p.h.x, u.y / p.h.y, u.z / p.h.z});
  return t;
}

double hit_box(const Primitive& p, const V3& o, const V3& d, double t_min, double t_max, V3* n) {
  V3 ol = p.R.tmul(o - p.c), dl = p.R.tmul(d);
  double t_near = -std::numeric_limits<double>::infinity(), t_far = std::numeric_limits<double>::infinity();
  int axis = 0;
  double sign = 1;
  for (int i = 0; i < 3; ++i) {
    double oi = ol[i], di = dl[i], hi = p.h[i];
    if (std::abs(di) < 1e-15) {
      if (std::abs(oi) > hi) return kMiss;
      continue;
    }
    double t1 = (-hi - oi) / di, t2 = (hi - oi) / di;
    double s = -1;  // entering through the -h face
    if (t1 > t2) {
      std::swap(t1, t2);
      s = 1;
    }
    if (t1 > t_near) {
      t_near = t1;
      axis = i;
      sign = s;
    }
    t_far = std::min(t_far, t2);
  }
  if (t_near > t_far || t_near <= t_min || t_near >= t_max) return kMiss;
  V3 nl{0, 0, 0};
  if (axis == 0) nl.x = sign;
  if (axis == 1) nl.y = sign;
  if (axis == 2) nl.z = sign;
  *n = p.R * nl;
  return t_near;
}

// Round cone (convex hull of two spheres), after Inigo Quilez's closed form.
double hit_round_cone(const Primitive& p, const V3& o, const V3& d, double t_min, double t_max, V3* n) {
  V3 ba = p.b - p.a, oa = o - p.a, ob = o - p.b;
  double ra = p.ra, rb = p.rb;
  double rr = ra - rb;
  double m0 = dot(ba, ba), m1 = dot(ba, oa), m2 = dot(ba, d), m3 = dot(d, oa), m5 = dot(oa, oa);
  double m6 = dot(ob, d), m7 = dot(ob, ob);
  double d2 = m0 - rr * rr;
  double k2 = d2 - m2 * m2;
  double k1 = d2 * m3 - m1 * m2 + m2 * rr * ra;
  double k0 = d2 * m5 - m1 * m1 + m1 * rr * ra * 2.0 - m0 * ra * ra;
  double h = k1 * k1 - k0 * k2;
  if (h < 0) return kMiss;
  if (std::abs(k2) > 1e-18) {
    double t = (-std::sqrt(h) - k1) / k2;
    double y = m1 - ra * rr + t * m2;
    if (y > 0 && y < d2) {
      if (t <= t_min || t >= t_max) return kMiss;
      *n = normalize((oa + d * t) * d2 - ba * y);
      return t;
    }
  }
  // the caps: whichever sphere is hit first
  double h1 = m3 * m3 - m5 + ra * ra;
  double h2 = m6 * m6 - m7 + rb * rb;
  double best = std::numeric_limits<double>::infinity();
  V3 nb;
  if (h1 > 0) {
    double t = -m3 - std::sqrt(h1);
    if (t > t_min && t < best) {
      best = t;
      nb = (oa + d * t) / ra;
    }
  }
  if (h2 > 0) {
    double t = -m6 - std::sqrt(h2);
    if (t > t_min && t < best) {
      best = t;
      nb = (ob + d * t) / rb;
    }
  }
  if (best >= t_max) return kMiss;
  *n = normalize(nb);
  return best;
}

// The ray o + t d in the frame of the axis a..b: the axis's length L and unit
// direction w, the ray's origin and direction along it (oy, dy) and across it
// (op, dp).
struct AxisFrame {
  double L;
  V3 w;
  double oy, dy;
  V3 op, dp;
};
AxisFrame axis_frame(const Primitive& p, const V3& o, const V3& d) {
  const V3 ba = p.b - p.a;
  const double L = length(ba);
  const V3 w = ba / L;
  const V3 oc = o - p.a;
  const double oy = dot(oc, w), dy = dot(d, w);
  return {L, w, oy, dy, oc - w * oy, d - w * dy};
}

double hit_cylinder(const Primitive& p, const V3& o, const V3& d, double t_min, double t_max, V3* n) {
  const auto [L, w, oy, dy, op, dp] = axis_frame(p, o, d);
  double r2 = p.ra * p.ra;
  double best = std::numeric_limits<double>::infinity();
  V3 nb;
  double A = dot(dp, dp);
  if (A > 1e-18) {
    double B = dot(op, dp), C = dot(op, op) - r2;
    double disc = B * B - A * C;
    if (disc < 0) return kMiss;  // misses the infinite cylinder, so the caps too
    double t = (-B - std::sqrt(disc)) / A;
    double y = oy + t * dy;
    if (y >= 0 && y <= L && t > t_min) {
      best = t;
      nb = (op + dp * t) / p.ra;
    }
  } else if (dot(op, op) > r2) {
    return kMiss;  // parallel to the axis, outside
  }
  if (std::abs(dy) > 1e-18) {
    // entering cap: the y = 0 cap when moving along +w, the y = L cap when moving along -w
    double plane = dy > 0 ? 0.0 : L;
    double t = (plane - oy) / dy;
    V3 q = op + dp * t;
    if (t > t_min && t < best && dot(q, q) <= r2) {
      best = t;
      nb = dy > 0 ? -w : w;
    }
  }
  if (best >= t_max) return kMiss;
  *n = normalize(nb);
  return best;
}

// The open cup: the nearest of outer wall, rim, inner wall (seen from the
// hollow), inner floor and outer bottom.
double hit_cup(const Primitive& p, const V3& o, const V3& d, double t_min, double t_max, V3* n) {
  const auto [L, w, oy, dy, op, dp] = axis_frame(p, o, d);
  const double ro = p.ra, ri = p.rb, floor = p.h.x;
  double best = t_max;
  V3 nb;
  auto take = [&](double t, const V3& normal) {
    if (t > t_min && t < best) {
      best = t;
      nb = normal;
    }
  };
  double A = dot(dp, dp), B = dot(op, dp);
  if (A > 1e-18) {
    double disc_o = B * B - A * (dot(op, op) - ro * ro);
    if (disc_o < 0) return kMiss;  // misses the outer cylinder: misses the cup
    double t = (-B - std::sqrt(disc_o)) / A;  // entering the outer wall
    double y = oy + t * dy;
    if (y >= 0 && y <= L) take(t, (op + dp * t) / ro);
    double disc_i = B * B - A * (dot(op, op) - ri * ri);
    if (disc_i >= 0) {
      t = (-B + std::sqrt(disc_i)) / A;  // leaving the hollow through the inner wall
      y = oy + t * dy;
      if (y >= floor && y <= L) take(t, -(op + dp * t) / ri);
    }
  } else if (dot(op, op) > ro * ro) {
    return kMiss;
  }
  if (std::abs(dy) > 1e-18) {
    auto radial2 = [op = op, dp = dp](double t) { V3 q = op + dp * t; return dot(q, q); };  // copies: clang 14 (make fuzz) captures no structured bindings
    if (dy < 0) {
      double t = (L - oy) / dy;  // rim, from above
      double r2 = radial2(t);
      if (r2 <= ro * ro && r2 >= ri * ri) take(t, w);
      t = (floor - oy) / dy;  // inner floor, from above
      if (radial2(t) < ri * ri) take(t, w);
    } else {
      double t = -oy / dy;  // outer bottom, from below
      if (radial2(t) <= ro * ro) take(t, -w);
    }
  }
  if (best >= t_max) return kMiss;
  *n = normalize(nb);
  return best;
}

}  // namespace

double Primitive::intersect(const V3& o, const V3& d, double t_min, double t_max, V3* normal) const {
  if (!sphere_hit_possible(o, d, bc, br)) return kMiss;
  switch (kind) {
    case PrimKind::ellipsoid: return hit_ellipsoid(*this, o, d, t_min, t_max, normal);
    case PrimKind::box: return hit_box(*this, o, d, t_min, t_max, normal);
    case PrimKind::round_cone: return hit_round_cone(*this, o, d, t_min, t_max, normal);
    case PrimKind::cylinder: return hit_cylinder(*this, o, d, t_min, t_max, normal);
    case PrimKind::cup: return hit_cup(*this, o, d, t_min, t_max, normal);
  }
  return kMiss;
}

bool Primitive::inside(const V3& q) const {
  switch (kind) {
    case PrimKind::ellipsoid: {
      V3 u = R.tmul(q - c);
      u = {u.x / h.x, u.y / h.y, u.z / h.z};
      return dot(u, u) < 1.0;
    }
    case PrimKind::box: {
      V3 u = R.tmul(q - c);
      return std::abs(u.x) < h.x && std::abs(u.y) < h.y && std::abs(u.z) < h.z;
    }
    case PrimKind::round_cone: {
      // union of spheres c(s) = a + s (b - a), r(s) = ra + s (rb - ra): the
      // signed distance to sphere s is convex in s, so a ternary search finds its minimum.
      auto f = [&](double s) { return length(q - lerp(a, b, s)) - (ra + s * (rb - ra)); };
      double lo = 0, hi = 1;
      for (int i = 0; i < 60; ++i) {
        double m1 = lo + (hi - lo) / 3, m2 = hi - (hi - lo) / 3;
        if (f(m1) < f(m2)) hi = m2; else lo = m1;
      }
      return f(0.5 * (lo + hi)) < 0;
    }
    case PrimKind::cylinder: {
      const AxisFrame f = axis_frame(*this, q, {0, 0, 0});
      const double y = f.oy, L = f.L;
      return y > 0 && y < L && dot(f.op, f.op) < ra * ra;
    }
    case PrimKind::cup: {
      const AxisFrame f = axis_frame(*this, q, {0, 0, 0});
      const double y = f.oy, L = f.L;
      double r2 = dot(f.op, f.op);
      bool solid = y > 0 && y < L && r2 < ra * ra;
      bool hollow = y > h.x && r2 < rb * rb;
      return solid && !hollow;
    }
  }
  return false;
}

void Shape::finish() {
  if (prims.empty()) {
    br = 0;
    return;
  }
  // centre: middle of the primitives' bounding box; radius: covers every bounding sphere
  V3 lo{1e9, 1e9, 1e9}, hi{-1e9, -1e9, -1e9};
  for (const auto& p : prims) {
    lo = {std::min(lo.x, p.bc.x - p.br), std::min(lo.y, p.bc.y - p.br), std::min(lo.z, p.bc.z - p.br)};
    hi = {std::max(hi.x, p.bc.x + p.br), std::max(hi.y, p.bc.y + p.br), std::max(hi.z, p.bc.z + p.br)};
  }
  bc = (lo + hi) * 0.5;
  br = 0;
  for (const auto& p : prims) br = std::max(br, length(p.bc - bc) + p.br);
}

double Shape::min_z() const {
  double z = std::numeric_limits<double>::infinity();
  for (const auto& p : prims) z = std::min(z, p.min_z());
  return z;
}

double Shape::intersect(const V3& o, const V3& d, double t_min, double t_max, V3* normal, int* prim) const {
  if (prims.empty() || !sphere_hit_possible(o, d, bc, br)) return kMiss;
  double best = t_max;
  int best_i = -1;
  V3 n;
  for (size_t i = 0; i < prims.size(); ++i) {
    double t = prims[i].intersect(o, d, t_min, best, &n);
    if (t > 0 && t < best) {
      best = t;
      best_i = static_cast<int>(i);
      *normal = n;
    }
  }
  if (best_i < 0) return kMiss;
  *prim = best_i;
  return best;
}

bool Shape::occluded(const V3& o, const V3& d, double t_min, double t_max) const {
  if (prims.empty() || !sphere_hit_possible(o, d, bc, br)) return false;
  V3 n;
  for (const auto& p : prims) {
    if (p.intersect(o, d, t_min, t_max, &n) > 0) return true;
  }
  return false;
}

}  // namespace veneer::sim
