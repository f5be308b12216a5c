// The simulator's scenes, after the thesis's objects. Each is a union of
// convex primitives in object space (metres, centred near the origin, y up,
// the camera toward +z) with a procedural material. Every scene is built in a
// local frame and then turned toward the camera so that its interesting sides
// show; textures and bumps are evaluated in that local frame, so they stick
// to the object whatever its placement.
#include <array>
#include <utility>
#include <cmath>
#include <numbers>

#include "noise.hpp"
#include "scene.hpp"

namespace veneer::sim {

namespace {

constexpr double kPi = std::numbers::pi;
constexpr double deg(double d) { return d * kPi / 180.0; }

// A rigid placement of a local frame in object space: object = R * local + t.
struct Frame {
  M3 R;
  V3 t;
  Primitive place(Primitive p) const {
    switch (p.kind) {
      case PrimKind::ellipsoid:
      case PrimKind::box:
        p.c = R * p.c + t;
        p.R = R * p.R;
        break;
      case PrimKind::round_cone:
      case PrimKind::cylinder:
      case PrimKind::cup:
        p.a = R * p.a + t;
        p.b = R * p.b + t;
        break;
    }
    p.finish();
    return p;
  }
  V3 to_local(const V3& p) const { return R.tmul(p - t); }
  V3 dir_to_local(const V3& d) const { return R.tmul(d); }
  V3 dir_to_object(const V3& d) const { return R * d; }
};

// Normal of a surface displaced by the height field h (metres) along n, to
// first order: n - (the tangential part of grad h).
template <class H>
V3 bump(const V3& p, const V3& n, H&& h, double eps) {
  double h0 = h(p);
  V3 g{(h(p + V3{eps, 0, 0}) - h0) / eps, (h(p + V3{0, eps, 0}) - h0) / eps, (h(p + V3{0, 0, eps}) - h0) / eps};
  V3 gt = g - n * dot(g, n);
  return normalize(n - gt);
}

V3 rgb(double r, double g, double b) { return {r, g, b}; }

// A chain of round cones through `pts` with radii `radii` (same count).
void add_chain(Shape& shape, const Frame& f, const std::vector<V3>& pts, const std::vector<double>& radii, int part) {
  for (size_t i = 0; i + 1 < pts.size(); ++i)
    shape.prims.push_back(f.place(Primitive::round_cone(pts[i], pts[i + 1], radii[i], radii[i + 1], part)));
}

// ---------------------------------------------------------------- spheres

std::unique_ptr<Scene> sphere_scene(V3 albedo, double ks, double shininess) {
  auto s = std::make_unique<Scene>();
  s->shape.prims.push_back(Primitive::sphere({0, 0, 0}, 0.04));
  s->material = [albedo, ks, shininess](const V3&, const V3&, int, int, SurfaceSample* out) {
    out->albedo = albedo;
    out->ks = ks;
    out->shininess = shininess;
  };
  return s;
}

std::unique_ptr<Scene> two_spheres() {
  auto s = std::make_unique<Scene>();
  s->shape.prims.push_back(Primitive::sphere({-0.033, 0, 0}, 0.03, 0));
  s->shape.prims.push_back(Primitive::sphere({0.033, 0.004, -0.004}, 0.028, 1));
  s->material = [](const V3&, const V3&, int, int part, SurfaceSample* out) {
    out->albedo = part == 0 ? rgb(0.10, 0.28, 0.68) : rgb(0.80, 0.52, 0.07);
    out->ks = 0.12;
    out->shininess = 40;
  };
  return s;
}

// ---------------------------------------------------------------- orange

std::unique_ptr<Scene> orange() {
  auto s = std::make_unique<Scene>();
  s->shape.prims.push_back(Primitive::sphere({0, 0, 0}, 0.04));
  const V3 stem = normalize({0.1, 0.62, 0.78});
  s->material = [stem](const V3& p, const V3& n, int, int, SurfaceSample* out) {
    // peel: pits of oil glands (cells of ~1.8 mm) on a gently lumpy surface.
    // Pit depth h = -A (1 - smoothstep(0, R, d))^2 of the distance d to the
    // cell's gland: its gradient is analytic, h'(d) (p - gland) / d.
    const double freq = 560.0, A = 0.00022, R = 0.55;
    Cell cell = cellular(p * freq, 11);
    V3 grad{0, 0, 0};
    if (cell.dist < R && cell.dist > 1e-9) {
      double t = cell.dist / R;
      double s = t * t * (3 - 2 * t), ds = 6 * t * (1 - t) / R;  // smoothstep and its derivative in d
      double dh_dd = -A * 2 * (1 - s) * (-ds);                    // per unit of d (cell units)
      grad = (-cell.offset / cell.dist) * (dh_dd * freq);         // d(d)/dp = -offset / d, in cell units per metre
    }
    auto lumps = [](const V3& q) { return 0.0005 * fbm(q * 60.0, 3, 12); };
    const double eps = 4e-5;
    double l0 = lumps(p);
    grad += V3{lumps(p + V3{eps, 0, 0}) - l0, lumps(p + V3{0, eps, 0}) - l0, lumps(p + V3{0, 0, eps}) - l0} / eps;
    out->normal = normalize(n - (grad - n * dot(grad, n)));
    double cells = cell.dist;
    double mottle = fbm(p * 110.0, 4, 13);
    V3 peel = rgb(0.93, 0.37, 0.03) * (0.82 + 0.3 * mottle) * (0.92 + 0.08 * smoothstep(0.1, 0.6, cells));
    // stem scar: a small olive-brown star facing up and toward the camera
    double a = std::acos(std::clamp(dot(normalize(p), stem), -1.0, 1.0));
    double scar = 1.0 - smoothstep(0.06, 0.11, a + 0.03 * std::sin(5 * std::atan2(p.x, p.z) * 3));
    out->albedo = lerp(peel, rgb(0.30, 0.27, 0.08), scar);
    out->ks = 0.16;
    out->shininess = 28;
  };
  return s;
}

// ---------------------------------------------------------------- apple

std::unique_ptr<Scene> apple() {
  auto s = std::make_unique<Scene>();
  const Frame f{M3::rot_x(deg(28)), {0, 0, 0}};
  const double ry = 0.036;
  s->shape.prims.push_back(f.place(Primitive::ellipsoid({0, 0, 0}, {0.043, ry, 0.043})));
  add_chain(s->shape, f, {{0, ry - 0.008, 0}, {0.001, ry + 0.004, 0}, {0.004, ry + 0.013, 0.001}}, {0.0021, 0.0017, 0.0014},
            1);
  s->material = [f, ry](const V3& p, const V3& n, int, int part, SurfaceSample* out) {
    V3 q = f.to_local(p), nl = f.dir_to_local(n);
    if (part == 1) {
      out->albedo = rgb(0.22, 0.14, 0.06) * (0.8 + 0.4 * fbm(q * 3000.0, 2, 21));
      out->ks = 0.05;
      out->shininess = 10;
      return;
    }
    // stem and calyx dimples: depressions around both poles
    auto height = [ry](const V3& x) {
      V3 d = normalize(V3{x.x, x.y * 0.043 / ry, x.z});
      double top = std::acos(std::clamp(d.y, -1.0, 1.0)), bottom = kPi - top;
      return -0.006 * std::exp(-(top / 0.33) * (top / 0.33)) - 0.004 * std::exp(-(bottom / 0.3) * (bottom / 0.3)) +
             0.0003 * fbm(x * 90.0, 3, 22);
    };
    V3 nb = bump(q, nl, height, 5e-5);
    out->normal = f.dir_to_object(nb);
    // streaks along the meridians: noise fast in longitude, slow in latitude
    double lon = std::atan2(q.x, q.z);
    V3 sq{std::cos(lon) * 13.0, std::sin(lon) * 13.0, q.y * 45.0};
    double streak = fbm(sq, 4, 23);
    double blush = fbm(q * 35.0, 3, 24);
    V3 red = rgb(0.58, 0.04, 0.035), yellow = rgb(0.78, 0.60, 0.13), green = rgb(0.42, 0.52, 0.10);
    V3 c = lerp(red, yellow, smoothstep(0.53, 0.72, streak) * 0.6 + smoothstep(0.62, 0.85, blush) * 0.3);
    double polar = std::abs(q.y) / ry;
    c = lerp(c, green, smoothstep(0.78, 0.97, polar) * 0.8);
    // lenticels: tiny pale dots
    Cell cell = cellular(q * 900.0, 25);
    double dot_mask = 1.0 - smoothstep(0.10, 0.18, cell.dist);
    out->albedo = lerp(c, rgb(0.85, 0.78, 0.45), dot_mask * 0.35);
    out->ks = 0.32;
    out->shininess = 45;
  };
  return s;
}

// ---------------------------------------------------------------- banana

std::unique_ptr<Scene> banana() {
  auto s = std::make_unique<Scene>();
  const Frame f{M3::rot_y(deg(-22)) * M3::rot_z(deg(-6)), {0, 0.01, 0}};
  const V3 centre{0, 0.075, 0};
  const double R = 0.10, a0 = deg(-145), a1 = deg(-38);
  const int n = 14;
  std::vector<V3> pts;
  std::vector<double> radii;
  for (int i = 0; i <= n; ++i) {
    double u = static_cast<double>(i) / n;
    double a = a0 + (a1 - a0) * u;
    pts.push_back(centre + V3{R * std::cos(a), R * std::sin(a), 0});
    radii.push_back(0.0035 + 0.0135 * std::pow(std::sin(kPi * std::clamp(0.04 + u * 0.96, 0.0, 1.0)), 0.55));
  }
  add_chain(s->shape, f, pts, radii, 0);
  // the stalk at the a1 end, continuing along the tangent
  V3 end = pts.back();
  V3 tangent{-std::sin(a1), std::cos(a1), 0};
  add_chain(s->shape, f, {end - tangent * 0.002, end + tangent * 0.012, end + tangent * 0.022 + V3{0, -0.002, 0}},
            {0.0048, 0.0042, 0.0038}, 1);
  s->material = [f, centre, a0, a1](const V3& p, const V3& nrm, int, int part, SurfaceSample* out) {
    V3 q = f.to_local(p), nl = f.dir_to_local(nrm);
    V3 rel = q - centre;
    double a = std::atan2(rel.y, rel.x);
    double u = std::clamp((a - a0) / (a1 - a0), 0.0, 1.0);  // 0 = blossom tip, 1 = stalk
    // five faint ridges along the fruit
    auto height = [centre, a](const V3& x) {
      V3 r = x - centre;
      V3 rad{std::cos(a), std::sin(a), 0};
      double psi = std::atan2(r.z, dot(r, rad) - 0.10);
      return 0.0007 * std::cos(5 * psi) + 0.00015 * fbm(x * 400.0, 2, 31);
    };
    out->normal = f.dir_to_object(bump(q, nl, height, 5e-5));
    V3 yellow = rgb(0.86, 0.68, 0.10) * (0.88 + 0.2 * fbm(q * 80.0, 3, 32));
    V3 c = lerp(yellow, rgb(0.55, 0.60, 0.12), smoothstep(0.80, 1.0, u) * 0.7);
    // sugar spots: brown speckles of varying size
    Cell cell = cellular(q * 380.0, 33);
    double size = 0.10 + 0.22 * to_unit(cell.id);
    double spot = 1.0 - smoothstep(size * 0.7, size, cell.dist);
    if (to_unit(mix64(cell.id)) < 0.55) spot = 0;
    c = lerp(c, rgb(0.30, 0.17, 0.05), spot * 0.85);
    if (part == 1) c = rgb(0.40, 0.38, 0.14) * (0.85 + 0.3 * fbm(q * 600.0, 2, 34));
    double tip = part == 1 ? smoothstep(0.018, 0.024, length(q - (centre + V3{0.10 * std::cos(a1), 0.10 * std::sin(a1), 0})))
                           : 1.0 - smoothstep(0.0, 0.035, u);
    out->albedo = lerp(c, rgb(0.16, 0.11, 0.05), tip);
    out->ks = 0.14;
    out->shininess = 22;
  };
  return s;
}

// ---------------------------------------------------------------- cups

std::unique_ptr<Scene> cup(bool dots) {
  auto s = std::make_unique<Scene>();
  // tipped toward the camera so the rim and the inside show, handle to the right
  const Frame f{M3::rot_x(deg(16)) * M3::rot_y(deg(-28)), {-0.008, 0.002, 0}};
  const double r = 0.038, inner = 0.0345, half = 0.045;
  s->shape.prims.push_back(f.place(Primitive::cup({0, -half, 0}, {0, half, 0}, r, inner, 0.006, 0)));
  // a D-shaped handle whose ends sink into the wall (not through it)
  std::vector<V3> pts;
  std::vector<double> radii;
  for (int i = 0; i <= 24; ++i) {
    double a = deg(-90) + deg(180) * i / 24.0;
    pts.push_back({0.0405 + 0.024 * std::cos(a), 0.003 + 0.026 * std::sin(a), 0});
    radii.push_back(0.0052);
  }
  add_chain(s->shape, f, pts, radii, 1);
  s->material = [f, r, dots](const V3& p, const V3& n, int, int part, SurfaceSample* out) {
    V3 white = rgb(0.82, 0.81, 0.78);
    out->albedo = white;
    out->ks = 0.30;
    out->shininess = 90;
    if (!dots || part != 0) return;
    V3 q = f.to_local(p), nl = f.dir_to_local(n);
    if (std::abs(nl.y) > 0.9) return;                 // rim, floor, bottom
    if (nl.x * q.x + nl.z * q.z < 0) return;          // the inner wall is plain
    double u = std::atan2(q.x, q.z) * r, v = q.y;
    const double cell = 0.0155;
    double row = std::floor(v / cell);
    double uu = u / cell + 0.5 * (static_cast<int>(row) & 1);
    double col = std::floor(uu);
    uint64_t h = hash_cell(static_cast<int>(col), static_cast<int>(row), 0, 41);
    double cu = col + 0.5 + 0.3 * (to_unit(mix64(h ^ 1)) - 0.5), cv = row + 0.5 + 0.3 * (to_unit(mix64(h ^ 2)) - 0.5);
    double d = std::hypot(uu - cu, v / cell - cv) * cell;
    double radius = 0.0034 + 0.0012 * to_unit(mix64(h ^ 3));
    double inside = 1.0 - smoothstep(radius - 0.0003, radius + 0.0003, d);
    static const std::array<V3, 4> palette{rgb(0.75, 0.08, 0.07), rgb(0.08, 0.22, 0.70), rgb(0.10, 0.52, 0.18),
                                           rgb(0.90, 0.70, 0.08)};
    out->albedo = lerp(white, palette[h % 4], inside);
  };
  return s;
}

// ---------------------------------------------------------------- blocks

std::unique_ptr<Scene> blocks() {
  auto s = std::make_unique<Scene>();
  const Frame f{M3::rot_x(deg(22)) * M3::rot_y(deg(-34)), {0, 0.002, 0}};
  const V3 half{0.016, 0.0095, 0.008};
  const double gap = 0.0008;
  const double w = 2 * half.x + gap, hgt = 2 * half.y + gap;
  // colour index per brick: 0 red, 1 green, 2 blue, 3 yellow
  struct Brick { double x, y, z; int colour; };
  const Brick bricks[] = {
      {-w, -hgt, 0, 0}, {0, -hgt, 0, 2}, {w, -hgt, 0, 3},            // bottom row
      {-w, -hgt, -2 * half.z - gap, 1}, {w, -hgt, -2 * half.z - gap, 0},  // behind it
      {-w * 0.5, 0, -0.004, 1}, {w * 0.5, 0, -0.004, 0},             // middle row, set back
      {0, hgt, -0.006, 3},                                              // top
  };
  for (const auto& b : bricks) s->shape.prims.push_back(f.place(Primitive::box({b.x, b.y, b.z}, half, {}, b.colour)));
  s->material = [](const V3& p, const V3&, int, int part, SurfaceSample* out) {
    static const std::array<V3, 4> colours{rgb(0.72, 0.07, 0.05), rgb(0.09, 0.48, 0.16), rgb(0.07, 0.20, 0.66),
                                           rgb(0.88, 0.68, 0.06)};
    out->albedo = colours[static_cast<size_t>(part) % 4] * (0.97 + 0.06 * fbm(p * 200.0, 2, 51));
    out->ks = 0.22;
    out->shininess = 60;
  };
  return s;
}

// ---------------------------------------------------------------- stone

std::unique_ptr<Scene> stone() {
  auto s = std::make_unique<Scene>();
  const Frame f{M3::rot_z(deg(14)) * M3::rot_y(deg(30)) * M3::rot_x(deg(18)), {-0.004, 0, 0}};
  s->shape.prims.push_back(f.place(Primitive::ellipsoid({0, 0, 0}, {0.05, 0.032, 0.038})));
  s->material = [f](const V3& p, const V3& n, int, int, SurfaceSample* out) {
    V3 q = f.to_local(p), nl = f.dir_to_local(n);
    auto height = [](const V3& x) {
      // broad lumps, pitted grain
      return 0.004 * fbm(x * 16.0, 3, 60) + 0.0014 * fbm(x * 55.0, 5, 61) + 0.0001 * fbm(x * 420.0, 3, 62);
    };
    out->normal = f.dir_to_object(bump(q, nl, height, 4e-5));
    double tone = fbm(q * 90.0, 4, 63);
    V3 c = rgb(0.36, 0.35, 0.34) * (0.75 + 0.5 * tone);
    // veins: thin bands along warped level sets, as in marble
    double warp = fbm(q * 22.0, 4, 64);
    double v1 = std::sin(dot(q, V3{120, 50, -40}) + 8.0 * warp);
    double vein = 1.0 - smoothstep(0.02, 0.10, std::abs(v1));
    double v2 = std::sin(dot(q, V3{-40, 150, 70}) + 6.0 * fbm(q * 30.0, 3, 65));
    double dark = 1.0 - smoothstep(0.015, 0.06, std::abs(v2));
    double grain = value_noise(q * 1500.0, 69);
    c = c * (0.85 + 0.3 * grain);
    c = lerp(c, rgb(0.84, 0.82, 0.78), vein * 0.85);
    c = lerp(c, rgb(0.12, 0.11, 0.11), dark * 0.6);
    out->albedo = c;
    out->ks = 0.05;
    out->shininess = 12;
  };
  return s;
}

// ---------------------------------------------------------------- bull

std::unique_ptr<Scene> bull() {
  auto s = std::make_unique<Scene>();
  const Frame f{M3::rot_x(deg(12)) * M3::rot_y(deg(-32)), {-0.006, 0.006, 0}};
  auto& P = s->shape.prims;
  enum { kHide = 0, kHorn = 2, kHoof = 3, kPlinth = 4 };
  P.push_back(f.place(Primitive::ellipsoid({-0.006, 0.004, 0}, {0.050, 0.023, 0.020}, {}, kHide)));      // barrel
  P.push_back(f.place(Primitive::ellipsoid({0.028, 0.012, 0}, {0.024, 0.025, 0.021}, {}, kHide)));       // shoulders
  P.push_back(f.place(Primitive::ellipsoid({-0.038, 0.008, 0}, {0.018, 0.02, 0.019}, {}, kHide)));       // haunches
  P.push_back(f.place(Primitive::round_cone({0.040, 0.018, 0}, {0.060, 0.014, 0}, 0.016, 0.012, kHide)));  // neck
  P.push_back(f.place(Primitive::ellipsoid({0.066, 0.010, 0}, {0.015, 0.017, 0.0135}, M3::rot_z(deg(-25)), kHide)));
  P.push_back(f.place(Primitive::round_cone({0.068, 0.006, 0}, {0.080, -0.006, 0}, 0.010, 0.0075, kHide)));  // muzzle
  for (double side : {-1.0, 1.0}) {
    add_chain(s->shape, f,
              {{0.063, 0.021, side * 0.007}, {0.064, 0.026, side * 0.017}, {0.068, 0.032, side * 0.023},
               {0.075, 0.036, side * 0.024}},
              {0.0032, 0.0026, 0.0018, 0.0009}, kHorn);
    // legs: front and hind, slightly splayed, hooves below
    for (double x : {0.030, -0.040}) {
      V3 top{x, -0.004, side * 0.011}, knee{x + 0.002, -0.026, side * 0.0125}, foot{x, -0.044, side * 0.0125};
      add_chain(s->shape, f, {top, knee, foot}, {0.0085, 0.0058, 0.0050}, kHide);
      P.push_back(f.place(Primitive::round_cone(foot, foot + V3{0.001, -0.0035, 0}, 0.0056, 0.0058, kHoof)));
    }
  }
  add_chain(s->shape, f, {{-0.054, 0.014, 0}, {-0.063, -0.004, 0.002}, {-0.061, -0.026, 0.004}}, {0.0030, 0.0022, 0.0020},
            kHide);
  P.push_back(f.place(Primitive::ellipsoid({-0.061, -0.030, 0.004}, {0.0035, 0.006, 0.0035}, {}, kHoof)));  // tuft
  P.push_back(f.place(Primitive::box({-0.004, -0.0515, 0}, {0.072, 0.004, 0.024}, {}, kPlinth)));
  s->support_part = kPlinth;
  s->material = [f](const V3& p, const V3& n, int, int part, SurfaceSample* out) {
    V3 q = f.to_local(p);
    switch (part) {
      case kHorn:
        out->albedo = rgb(0.78, 0.72, 0.58);
        out->ks = 0.3;
        out->shininess = 50;
        return;
      case kHoof:
        out->albedo = rgb(0.12, 0.10, 0.08);
        out->ks = 0.2;
        out->shininess = 40;
        return;
      case kPlinth:
        out->albedo = rgb(0.30, 0.34, 0.30) * (0.9 + 0.2 * fbm(q * 150.0, 3, 71));
        out->ks = 0.05;
        out->shininess = 10;
        return;
      default: {
        // glazed terracotta with a darker wash pooled in the creases
        auto height = [](const V3& x) { return 0.00015 * fbm(x * 350.0, 3, 72); };
        out->normal = f.dir_to_object(bump(q, f.dir_to_local(n), height, 4e-5));
        out->albedo = rgb(0.46, 0.27, 0.15) * (0.8 + 0.35 * fbm(q * 70.0, 4, 73));
        out->ks = 0.22;
        out->shininess = 35;
      }
    }
  };
  return s;
}

}  // namespace

std::vector<std::string> scene_names() {
  return {"orange", "apple",  "banana", "cup-dots",    "cup-white",       "two-spheres",
          "blocks", "stone",  "bull",   "sphere-gray", "sphere-red-gloss"};
}

std::string scene_description(const std::string& name) {
  static const std::pair<const char*, const char*> descriptions[] = {
      {"orange", "an orange, 8 cm: dimpled peel, mottled colour, stem scar"},
      {"apple", "an apple, slightly flattened: red with yellow streaks, green shoulders, stem in a dimple"},
      {"banana", "a curved banana, 18 cm: yellow with brown sugar spots, faint ridges, stalk"},
      {"cup-dots", "a white glazed cup with coloured dots and a handle, tipped to show its inside"},
      {"cup-white", "the same cup, plain white"},
      {"two-spheres", "two spheres side by side, blue and yellow"},
      {"blocks", "a stack of bricks in four colours: few normal orientations"},
      {"stone", "a rough grey stone with light and dark veins"},
      {"bull", "a statue of a bull on a plinth: concave, casts shadows on itself"},
      {"sphere-gray", "a uniform matte grey sphere (albedo 0.6), for measuring"},
      {"sphere-red-gloss", "a uniform red sphere with a strong specular lobe, for measuring"},
  };
  for (const auto& [n, d] : descriptions)
    if (name == n) return d;
  return {};
}

std::unique_ptr<Scene> build_scene(const std::string& name) {
  std::unique_ptr<Scene> s;
  if (name == "orange") s = orange();
  else if (name == "apple") s = apple();
  else if (name == "banana") s = banana();
  else if (name == "cup-dots") s = cup(true);
  else if (name == "cup-white") s = cup(false);
  else if (name == "two-spheres") s = two_spheres();
  else if (name == "blocks") s = blocks();
  else if (name == "stone") s = stone();
  else if (name == "bull") s = bull();
  else if (name == "sphere-gray") s = sphere_scene(rgb(0.6, 0.6, 0.6), 0.0, 1.0);
  else if (name == "sphere-red-gloss") s = sphere_scene(rgb(0.70, 0.07, 0.05), 0.6, 80.0);
  if (!s) return nullptr;
  s->name = name;
  s->shape.finish();
  // the table touches the object's back (a hair behind it, so they never coincide)
  s->table_z = s->shape.min_z() - 0.0003;
  return s;
}

}  // namespace veneer::sim
