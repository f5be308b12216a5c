#pragma once
// Counter-based randomness for the simulator: every random number is a pure
// function of its coordinates (seed, shot, pixel, ...), so renders are the same
// whatever the thread count or the order of work. Plus small procedural
// textures (value noise, fBm, cellular dots) evaluated in object space.
#include <algorithm>
#include <cmath>
#include <cstdint>

#include "geometry.hpp"

namespace veneer::sim {

// splitmix64 finaliser: a good 64-bit mix.
inline uint64_t mix64(uint64_t z) {
  z += 0x9e3779b97f4a7c15ULL;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}
inline uint64_t hash_combine(uint64_t a, uint64_t b) { return mix64(a ^ mix64(b)); }
// Uniform in [0, 1) from 53 bits.
inline double to_unit(uint64_t h) { return static_cast<double>(h >> 11) * (1.0 / 9007199254740992.0); }

inline uint64_t hash_cell(int x, int y, int z, uint64_t salt) {
  uint64_t h = mix64(salt);
  h = hash_combine(h, static_cast<uint64_t>(static_cast<uint32_t>(x)));
  h = hash_combine(h, static_cast<uint64_t>(static_cast<uint32_t>(y)));
  h = hash_combine(h, static_cast<uint64_t>(static_cast<uint32_t>(z)));
  return h;
}
inline double cell_rand(int x, int y, int z, uint64_t salt) { return to_unit(hash_cell(x, y, z, salt)); }

// Value noise in [0, 1], smooth (quintic fade), period-free.
inline double value_noise(const V3& p, uint64_t salt) {
  double fx = std::floor(p.x), fy = std::floor(p.y), fz = std::floor(p.z);
  int ix = static_cast<int>(fx), iy = static_cast<int>(fy), iz = static_cast<int>(fz);
  double tx = p.x - fx, ty = p.y - fy, tz = p.z - fz;
  auto fade = [](double t) { return t * t * t * (t * (t * 6 - 15) + 10); };
  double ux = fade(tx), uy = fade(ty), uz = fade(tz);
  double v[8];
  for (int k = 0; k < 8; ++k) v[k] = cell_rand(ix + (k & 1), iy + ((k >> 1) & 1), iz + ((k >> 2) & 1), salt);
  double x00 = v[0] + (v[1] - v[0]) * ux, x10 = v[2] + (v[3] - v[2]) * ux;
  double x01 = v[4] + (v[5] - v[4]) * ux, x11 = v[6] + (v[7] - v[6]) * ux;
  double y0 = x00 + (x10 - x00) * uy, y1 = x01 + (x11 - x01) * uy;
  return y0 + (y1 - y0) * uz;
}

// Fractal sum of value noise, in about [0, 1].
inline double fbm(const V3& p, int octaves, uint64_t salt, double lacunarity = 2.0, double gain = 0.5) {
  double sum = 0, amp = 0.5, norm = 0;
  V3 q = p;
  for (int i = 0; i < octaves; ++i) {
    sum += amp * value_noise(q, salt + static_cast<uint64_t>(i) * 7919);
    norm += amp;
    amp *= gain;
    q = q * lacunarity + V3{17.3, -9.1, 5.7};
  }
  return sum / norm;
}

// Cellular noise: distance to the nearest jittered feature point of a unit
// grid (one point per cell), and that cell's random id.
struct Cell {
  double dist = 1e9;
  uint64_t id = 0;
  V3 offset;  // feature point - p
};
inline Cell cellular(const V3& p, uint64_t salt) {
  int ix = static_cast<int>(std::floor(p.x)), iy = static_cast<int>(std::floor(p.y)),
      iz = static_cast<int>(std::floor(p.z));
  Cell best;
  for (int dz = -1; dz <= 1; ++dz)
    for (int dy = -1; dy <= 1; ++dy)
      for (int dx = -1; dx <= 1; ++dx) {
        uint64_t h = hash_cell(ix + dx, iy + dy, iz + dz, salt);
        V3 f{ix + dx + to_unit(mix64(h ^ 1)), iy + dy + to_unit(mix64(h ^ 2)), iz + dz + to_unit(mix64(h ^ 3))};
        V3 off = f - p;
        double d = length(off);
        if (d < best.dist) {
          best.dist = d;
          best.id = h;
          best.offset = off;
        }
      }
  return best;
}

inline double smoothstep(double e0, double e1, double x) {
  double t = std::clamp((x - e0) / (e1 - e0), 0.0, 1.0);
  return t * t * (3 - 2 * t);
}

}  // namespace veneer::sim
