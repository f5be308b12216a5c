#pragma once
// Internal: the `combined` correspondence (Method::combined), the default.
//
// For every destination pixel, the source pixel whose surroundings look the
// same by everything the rig gives: the normals, the per-lamp shading pattern
// (each lamp's grey level over their norm: albedo-free, carrying cast shadows
// that normals miss), and the mean colour's chromaticity and (weakly)
// brightness, over a sparse 5x5 patch; plus a coherence term, the cost of
// each 4-neighbour whose match lies more than 1.5 px away. Minimised by
// PatchMatch (propagation, random search) over an image pyramid: the coarsest
// level searches the whole source, seeded by the nearest normal; each finer
// level starts from the coarser match scaled up and searches a few pixels
// around it. When the destination is the source moved, scaled or cropped, the
// patches only fit at the true motion, and the coherence term keeps chunks
// whole between different objects. Every destination object pixel is mapped.
#include "veneer/match/matcher.hpp"
#include "veneer/util/expected.hpp"
#include "veneer/util/progress.hpp"

namespace veneer::match::fast {

Expected<Map> run_combined(const ObjectView& destination, const ObjectView& source, const MatchOptions& options,
                           const Progress& progress);

}  // namespace veneer::match::fast
