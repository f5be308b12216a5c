#pragma once
// A full-resolution correspondence map refined from a coarser one (the live
// view's map, or one computed at a working resolution) instead of computed
// from scratch: compute_map at full resolution is seconds; this is a local
// search of a few source pixels per destination pixel.
#include <opencv2/core.hpp>

#include "veneer/match/matcher.hpp"
#include "veneer/util/expected.hpp"
#include "veneer/util/progress.hpp"

namespace veneer::match {

struct RefineOptions {
  int radius = 1;    // search window around each continued match, in full-resolution source pixels
                     // (0..8, default 1: 3x3); a coarse map's error is about one of its own pixels
  int threads = 0;   // worker threads, 0 = all cores
  Status check() const;
};

// For every destination pixel of `destination.mask`: the coarse map's
// matches of its coarse pixel and of that pixel's 4 neighbours are each
// continued to it (the coarse source position scaled to the full size, plus
// the pixel's offset from its coarse pixel's centre: inside a chunk of the
// coarse map, the continuations are a chunk again), then the source pixel
// within `radius` of each continuation whose normal is nearest the
// destination's is taken (on the source's mask). `coarse` may be of any
// size (both axes scaled alike or not); the source's full-resolution size is
// `source.mask`'s, the coarse source's is assumed to scale as the
// destination's does. The result has the destination's size; pixels whose
// continuations all fall off the source's mask stay unmapped.
Expected<Map> refine_map(const Map& coarse, const ObjectView& destination, const ObjectView& source,
                         const RefineOptions& options = {}, const Progress& progress = {});

}  // namespace veneer::match
