#pragma once
// Internal: helpers shared by the fast engine's methods.
#include <cstdint>

#include "object.hpp"
#include "veneer/match/fast.hpp"
#include "veneer/match/features.hpp"

namespace veneer::match::fast {

Map new_map(cv::Size size);

// Writes destination row d -> source row s with squared feature distance v.
inline void put(Map& map, const Object& dst, const Object& src, int d, int s, float v) {
  const cv::Point p = dst.pixels[d], q = src.pixels[s];
  map.xy.at<cv::Vec2f>(p.y, p.x) = cv::Vec2f(static_cast<float>(q.x), static_cast<float>(q.y));
  map.distance.at<float>(p.y, p.x) = map_distance(v, dst.patch);
}

// splitmix64: random numbers as a pure function of their coordinates, so a
// result never depends on how work was split between threads.
inline uint64_t mix64(uint64_t z) {
  z += 0x9e3779b97f4a7c15ull;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  return z ^ (z >> 31);
}
inline uint64_t hash3(uint64_t a, uint64_t b, uint64_t c) { return mix64(mix64(mix64(a) ^ b) ^ c); }

Expected<Map> run_coherent(const Object& dst, const Object& src, const MatchOptions& options, const Progress& progress,
                           Stats* stats);

}  // namespace veneer::match::fast
