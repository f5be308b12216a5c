#pragma once
// The fast correspondence engine (issue 4): the default wherever it applies.
//
//  - Nearest normal through a lookup over the sphere of normals: an
//    octahedral grid filled from the source's object pixels. `linear` gets
//    the exact nearest ("grid": the query's cell, then every cell within
//    reach of the best found, read 8 points at a time; exact by a bound on
//    the grid's stretch); `flann` -- approximate in the thesis too -- the
//    lookup ("lookup": the best among the query's own cell's few entries and
//    the previous pixel's match, about twice as fast, +0.07 degrees mean).
//    An exact low-dimensional kd-tree ("kdtree", nanoflann) serves long lists.
//  - Patch and intensity features: a 3-D projection that is a lower bound of
//    the full distance (patch mean, then the 3 principal directions) yields
//    candidates from the same index; they are re-ranked by the exact full
//    distance, and the answer is certified exact when the next unvisited
//    candidate's lower bound exceeds it (else the candidate list grows once,
//    then the best found is kept; the share certified is reported in Stats).
//  - Fast patchmatch, regiongrow and candidates with the semantics of the
//    faithful methods, and the `coherent` method (StyleBlit-style chunks).
// Every per-pixel stage runs on all cores (TBB).
#include <memory>

#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "veneer/match/index.hpp"
#include "veneer/match/matcher.hpp"
#include "veneer/util/expected.hpp"
#include "veneer/util/progress.hpp"

namespace veneer::match::fast {

// True when the fast engine serves `options` (method x feature x patch).
// `coherent` is served only here, whatever options.fast says.
bool supports(const MatchOptions& options);

// What the last run did, for benches and diagnostics.
struct Stats {
  std::string index;             // "grid" or "kdtree"
  int projected_dims = 0;        // dims of the candidate search (3), 0 = searched at full dimension
  double explained_variance = 1;  // share of the feature variance kept by the projection
  double certified = 1;          // share of destination pixels whose nearest is proven exact
  double candidates = 0;         // mean exact distances computed per destination pixel (projected search)
  double seconds = 0;            // wall time of compute_map
  double refine_seconds = 0;     // of which `coherent`'s refinement (wall)
};

Expected<Map> compute_map(const ObjectView& destination, const ObjectView& source, const MatchOptions& options,
                          const Progress& progress = {});
Expected<Map> compute_map(const ObjectView& destination, const ObjectView& source, const MatchOptions& options,
                          const Progress& progress, Stats* stats);

// "grid" (octahedral lookup, exact for any 3-D points, fastest on normals),
// "lookup" (the same grid, k = 1 answered from the query's own cell: not
// exact) or "kdtree" (nanoflann, exact, any dimension); nullptr for other names.
std::unique_ptr<NearestIndex> make_index(const std::string& kind);

// Repaint with the overlapping chunks blended (StyleBlit's optional blending,
// done as voting): each destination pixel averages, Gaussian-weighted, the
// source colours that its neighbours within `radius` propose for it -- their
// match shifted back by their offset. Inside a coherent chunk every proposal
// is the same pixel, so texture stays sharp; across a seam the chunks fade
// into each other. radius 0 = plain lookup. Returns CV_32FC3, zero where the
// destination is not mapped.
// With a guide, a proposal also weighs exp(-|n_d - n_s|^2 / (2 sigma^2)): the
// destination pixel's normal against the proposed source pixel's. A chunk
// continued across the destination's own edges (a leg in front of the body,
// an ear against the head) proposes normals that do not fit there and drops
// out, so outlines stay sharp while seams and speckle soften. A destination
// pixel without a normal (zero or not finite) is blended unguided; a proposal
// without one is left out; when nothing is left the pixel keeps its own match.
struct BlendGuide {
  cv::Mat destination;  // CV_32FC3 normals, the map's size
  cv::Mat source;       // CV_32FC3 normals, the source photo's size
  double sigma = 0.1;   // |dn| of the fall-off (0.1 ~ 6 degrees), > 0
};
Expected<cv::Mat> blend_repaint(const Map& map, const cv::Mat& destination_mask, const cv::Mat& source_photo,
                                const cv::Mat& source_mask, int radius = 2, int threads = 0,
                                const BlendGuide* guide = nullptr);
// The same in two steps, for several photos through one map: the weights
// depend on the map, the masks and the guide only, so they are worked out
// once (blend_plan; an empty destination_mask = every mapped pixel) and each
// photo is then a weighted sum per pixel (apply_blend).
struct BlendPlan {
  struct Term {
    int source;    // y * source width + x
    float weight;  // the pixel's weights sum to 1 (no terms: black)
  };
  cv::Size destination_size, source_size;
  std::vector<int> pixels;  // the mapped pixels (y * width + x), row order
  std::vector<int> first;   // per pixel its first term (one more entry: the end)
  std::vector<Term> terms;
};
Expected<BlendPlan> blend_plan(const Map& map, const cv::Mat& destination_mask, const cv::Mat& source_mask,
                               int radius, int threads = 0, const BlendGuide* guide = nullptr);
// Writes the plan's pixels of `out` (the plan's destination size, the photo's
// type) from `source_photo` (CV_8UC3 or CV_32FC3, the plan's source size);
// the other pixels of `out` are left as they are.
Status apply_blend(const BlendPlan& plan, const cv::Mat& source_photo, cv::Mat& out, int threads = 0);

// The index kind compute_map uses for nearest normals (the faster one as measured).
const char* default_index();

}  // namespace veneer::match::fast
