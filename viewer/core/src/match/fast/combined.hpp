#pragma once
// Internal: the `combined` correspondence (Method::combined), the default.
//
// First, is the destination the source moved (scaled, turned, cropped)? A
// PatchMatch at the coarsest pyramid level compares everything the rig gives
// for a pixel: the normal, the per-lamp shading pattern (each lamp's grey
// level over their norm: albedo-free, carrying cast shadows that normals
// miss), the mean colour's chromaticity and (weakly) brightness, over a
// sparse 9x9 patch, plus a coherence term (each 4-neighbour whose match does
// not continue this one costs). If an affine motion found by RANSAC explains
// 60 % of its matches, the finer levels follow it; at full size the motion is
// refitted and taken, at sub-pixel positions, wherever its patch fits about
// as well as the pixel's own match -- provided it keeps the normals nearly as
// well as the nearest normal does (two similar blobs can follow one motion
// too). Otherwise the objects differ and `coherent` on the normals maps them:
// patches of normals compare badly between shapes of different curvature.
// Every destination object pixel is mapped.
#include "veneer/match/matcher.hpp"
#include "veneer/util/expected.hpp"
#include "veneer/util/progress.hpp"

namespace veneer::match::fast {

Expected<Map> run_combined(const ObjectView& destination, const ObjectView& source, const MatchOptions& options,
                           const Progress& progress);

}  // namespace veneer::match::fast
