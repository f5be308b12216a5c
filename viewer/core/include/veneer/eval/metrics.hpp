#pragma once
// Quality of a correspondence map, measured against ground truth (simulated
// sets carry truth/): what a researcher comparing matching methods reads.
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/io/imageset.hpp"
#include "veneer/match/fast.hpp"
#include "veneer/match/matcher.hpp"
#include "veneer/util/expected.hpp"
#include "veneer/util/progress.hpp"

namespace veneer::eval {

using match::Map;
namespace fast = match::fast;

struct Quality {
  int destination_pixels = 0;   // destination object pixels (the mask given)
  int mapped_pixels = 0;        // of those, mapped onto a source object pixel
  double coverage = 0;          // mapped / destination object pixels
  int background_hits = 0;      // mapped onto source background (must be 0)
  // normal agreement: angle between the destination's true normal and the
  // source's true normal at the match [degrees]; only with both truths
  std::optional<double> normal_mean_deg, normal_p95_deg;
  double coherence = 0;         // share of 4-neighbour destination pairs (both mapped) whose
                                // matches lie within 1.5 px of each other in the source
  int reuse_max = 0;            // most destination pixels sharing one source pixel
  double source_used = 0;       // share of source object pixels used at all
  std::optional<double> psnr_db;      // relighting under an extra lamp (see relight)
  std::optional<double> psnr_lit_db;  // the same over the pixels that lamp reaches (its cast shadows left out)
};

// `destination_mask` / `source_mask`: the object pixels (CV_8UC1); the truth
// normals (CV_32FC3) may be empty, then normal agreement is not measured.
Quality evaluate(const Map& map, const cv::Mat& destination_mask, const cv::Mat& source_mask,
                 const cv::Mat& destination_normals = {}, const cv::Mat& source_normals = {});

// How many destination pixels use each source pixel (CV_32SC1 of `source_size`).
cv::Mat reuse_counts(const Map& map, cv::Size source_size);

// PSNR [dB] of `transferred` against `reference` (linear BGR in [0,1], values
// clipped) over the pixels of `mask`; peak = 1 (full scale).
double psnr(const cv::Mat& transferred, const cv::Mat& reference, const cv::Mat& mask);

// The extra lamp of the relighting measure: a position off the rig's ring
// (upper left, closer to the object than the ring), so it took no part in matching.
cv::Vec3d relight_lamp_position();

// Relighting error: the source scene rendered under the extra lamp, carried
// through `map` onto the destination, against the destination's shape
// rendered in the source's material under the same lamp. Needs both sets to be
// simulated (ImageSet::scene set) and a source whose material is uniform
// (sphere-red-gloss, sphere-gray); fails otherwise with the reason.
//
// The destination's cast shadows under that lamp (the bull's on its plinth
// and on its own legs) are in the reference, and no map can carry them: the
// source has none where its normals face the lamp. They are ~5 % of the bull's
// pixels but most of the error of a good map (bull <- sphere-red-gloss at
// 512x340: truth-normal nearest 18.7 dB over all pixels, 28.9 dB without
// them), so differences between maps drown in them. `psnr_lit_db` leaves them
// out: `lit` = the pixels of `destination_mask` that the reference rendered
// with cast shadows and without agree on.
struct Relit {
  cv::Mat transferred;  // linear BGR: the source under the extra lamp, carried through the map (black unmapped)
  cv::Mat reference;    // linear BGR: the destination's shape in the source's material under the extra lamp
  cv::Mat lit;          // CV_8UC1: destination_mask's pixels outside the lamp's cast shadows
  double psnr_db = 0;      // over destination_mask
  double psnr_lit_db = 0;  // over lit
};
// blend > 0: the source carried through the map with repaint::repaint_blended (repaint.hpp),
// weighed by `guide` when given (fast::BlendGuide; normals of the map's size and the source's).
Expected<Relit> relight(const Map& map, const io::ImageSet& destination, const io::ImageSet& source,
                        const cv::Mat& destination_mask, int blend = 0, const fast::BlendGuide* guide = nullptr);
// What the measure renders for a pair whatever the map (relight() renders it
// on every call; the quality table once per pair and then uses the overload).
struct RelightScenes {
  cv::Mat lit_source;  // linear BGR: the source under the extra lamp
  cv::Mat reference;   // as Relit::reference
  cv::Mat shadowed;    // CV_8UC1: 255 where the lamp's cast shadows fall on the destination
};
Expected<RelightScenes> relight_scenes(const io::ImageSet& destination, const io::ImageSet& source);
Expected<Relit> relight(const Map& map, const RelightScenes& scenes, const cv::Mat& source_mask,
                        const cv::Mat& destination_mask, int blend = 0, const fast::BlendGuide* guide = nullptr);
bool relight_measurable(const std::string& source_scene);

}  // namespace veneer::eval
