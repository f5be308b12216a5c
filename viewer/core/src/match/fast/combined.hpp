#pragma once
// Internal: the `combined` correspondence (Method::combined), the default.
//
// First, is the destination the source moved (scaled, turned, cropped)? A
// PatchMatch at the coarsest pyramid level compares everything the rig gives
// for a pixel: the normal, the per-lamp shading pattern (each lamp's grey
// level over their norm: albedo-free, carrying cast shadows that normals
// miss), the mean colour's chromaticity and (weakly) brightness, over a
// sparse 9x9 patch, plus a coherence term (each 4-neighbour whose match does
// not continue this one costs). The patch is sampled on the source through
// the motion's linear part, so a copy at 0.5x-2x or turned compares sample
// for sample: at the coarsest level the search runs under guesses of that
// part from the masks (the areas' ratio; the principal axes; unscaled; turns
// in eighths), likeliest first, until one is followed by half the matches.
// If an affine motion found by RANSAC explains 35 % of them there, the finer
// levels follow it; on each, and twice at full size, the motion is checked
// against the data (each sampled patch's best place within 2 px of it, the
// affine refitted to those by RANSAC: the search's own matches lean towards
// the motion that guided them). At full size it is taken, at sub-pixel
// positions, wherever its patch fits about as well as the pixel's own match
// -- provided it keeps the normals nearly as well as the nearest normal does,
// or to within their noise (two similar blobs can follow one motion too).
// Otherwise the objects differ and `coherent` on the normals maps them:
// patches of normals compare badly between shapes of different curvature.
// Every destination object pixel is mapped; when no motion is taken, the
// map's motion note says why. An object whose features hardly vary at the
// coarsest level (flat, one colour: no texture or relief) gets no search.
#include "veneer/match/matcher.hpp"
#include "veneer/util/expected.hpp"
#include "veneer/util/progress.hpp"

namespace veneer::match::fast {

Expected<Map> run_combined(const ObjectView& destination, const ObjectView& source, const MatchOptions& options,
                           const Progress& progress);

}  // namespace veneer::match::fast
