// Names and option checks of the matcher.
#include <cmath>

#include "veneer/match/matcher.hpp"

namespace veneer::match {

namespace {
struct MethodName {
  Method method;
  const char* name;
};
constexpr MethodName kMethods[] = {
    {Method::linear, "linear"},         {Method::flann, "flann"},       {Method::candidates, "candidates"},
    {Method::patchmatch, "patchmatch"}, {Method::regiongrow, "regiongrow"}, {Method::baseline, "baseline"},
    {Method::coherent, "coherent"},     {Method::combined, "combined"},
};
}  // namespace

const char* method_name(Method m) {
  for (const auto& e : kMethods)
    if (e.method == m) return e.name;
  return "unknown";
}

const char* feature_name(Feature f) { return f == Feature::normals ? "normals" : "intensities"; }

Expected<Method> parse_method(const std::string& s) {
  for (const auto& e : kMethods)
    if (s == e.name) return e.method;
  return make_error("unknown method '" + s +
                    "' (combined, coherent, linear, flann, candidates, patchmatch, regiongrow, baseline)");
}

Expected<Feature> parse_feature(const std::string& s) {
  if (s == "normals") return Feature::normals;
  if (s == "intensities") return Feature::intensities;
  return make_error("unknown feature '" + s + "' (normals, intensities)");
}

Status MatchOptions::check() const {
  if (patch != 1 && patch != 3 && patch != 5 && patch != 7)
    return make_error("patch must be 1, 3, 5 or 7, got " + std::to_string(patch));
  if (candidates < 1 || candidates > 100)
    return make_error("candidates (K) must be in 1..100, got " + std::to_string(candidates));
  if (!std::isfinite(threshold) || threshold < 0)
    return make_error("threshold must be a finite number >= 0, got " + std::to_string(threshold));
  if (iterations < 1 || iterations > 1000)
    return make_error("iterations must be in 1..1000, got " + std::to_string(iterations));
  if (!std::isfinite(coherent_threshold) || coherent_threshold < 0)
    return make_error("coherent threshold must be a finite number >= 0, got " + std::to_string(coherent_threshold));
  if (!std::isfinite(coherent_smooth) || coherent_smooth < 0)
    return make_error("coherent smoothness must be a finite number >= 0, got " + std::to_string(coherent_smooth));
  if (!std::isfinite(coherent_guide) || coherent_guide < 0 || coherent_guide > 32)
    return make_error("coherent guide must be a smoothing radius in 0..32 px, got " + std::to_string(coherent_guide));
  if (coherent_sweeps < 0 || coherent_sweeps > 100)
    return make_error("coherent sweeps must be in 0..100, got " + std::to_string(coherent_sweeps));
  if (!std::isfinite(uniformity) || uniformity < 0)
    return make_error("uniformity must be a finite number >= 0, got " + std::to_string(uniformity));
  if (threads < 0) return make_error("threads must be >= 0 (0 = all cores), got " + std::to_string(threads));
  return {};
}

}  // namespace veneer::match
