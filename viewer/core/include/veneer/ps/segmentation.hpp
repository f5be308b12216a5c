#pragma once
// Segmentation of the object from the background of an image set.
//
// By default (`contrast`) the object is what some lamp lights clearly above
// the background: per pixel the brightest of the set's photos (ambient
// removed), against the level the frame's border shows (the backdrop, a wall
// or cloth the lamps also reach), with hysteresis so that a dim tail or a leg
// shadowed under most lamps stays with the body it touches. The thesis
// threshold (the summed intensity, a given threshold or Otsu's) remains. An optional rectangle limits
// the object; then the mask is cleaned: specks (small components) removed,
// small holes filled, and (`contrast`) the dim outline beside the object kept
// where it stands clear of the backdrop around it (`outline_sigmas`). A set
// that supplies its own mask (DiLiGenT mask.png) uses it by default.
#include <optional>
#include <string>

#include <opencv2/core.hpp>

#include "veneer/io/imageset.hpp"
#include "veneer/ps/photometric_stereo.hpp"
#include "veneer/util/expected.hpp"

namespace veneer::ps {

enum class SegmentMethod {
  automatic,  // set.mask when present, else contrast
  supplied,   // set.mask (fails when the set has none)
  threshold,  // fixed threshold on the mean grey intensity over lamps
  otsu,       // Otsu's threshold on the log of the mean grey intensity over lamps
  none,       // every pixel (then the rectangle and cleaning still apply)
  contrast,   // brightest lamp's photo against the border's backdrop level, with hysteresis
};
const char* segment_method_name(SegmentMethod);
Expected<SegmentMethod> parse_segment_method(const std::string&);

struct SegmentOptions {
  SegmentMethod method = SegmentMethod::automatic;  // see SegmentMethod
  double threshold = 0.02;      // `threshold`: mean grey intensity over lamps (1 = full scale) [0, 1)
  std::optional<cv::Rect> rect; // pixels outside are background (clipped to the image; must overlap it)
  bool clean = true;            // remove specks and fill holes
  int open_radius = 1;          // clean: morphological opening radius [px] before components (0 = off)
  double min_component_fraction = 0.002;  // clean: components smaller than this fraction of the
                                          // image area are removed [0, 1)
  double max_hole_fraction = 0.002;       // clean: background holes (not touching the border)
                                          // smaller than this fraction of the image are filled [0, 1)
  bool subtract_ambient = true; // subtract set.ambient when present
  // `contrast`: the backdrop level is a high percentile of the brightest-lamp
  // image over a band along the top, left and right of the frame (the bottom
  // is often the table the object stands on); object pixels are above
  // `contrast_low` times it and connected to pixels above `contrast_high` times it.
  double border_fraction = 0.03;  // band width as a fraction of the frame's smaller side (0, 0.25]
  double contrast_low = 1.5;      // > 1
  double contrast_high = 4.0;     // >= contrast_low
  // `contrast`, after cleaning: a pixel beside the object joins it when its
  // brightest-lamp value stands this many robust standard deviations above
  // the backdrop around it and at least halfway from that backdrop to the
  // object beside it (a dark part's dim outline, a thin tip) [0, 100]; 0 = off.
  double outline_sigmas = 3.0;
  Status check() const;
};

struct Segmentation {
  cv::Mat mask;           // CV_8UC1, 255 = object
  cv::Mat summed;         // CV_32FC1 mean grey intensity over lamps (contrast: the brightest lamp's;
                          // empty for `supplied`)
  double threshold = 0;   // threshold used (threshold/otsu; contrast: the low one)
  double backdrop = 0;    // contrast: the border's backdrop level (brightest lamp, 1 = full scale)
  SegmentMethod method_used = SegmentMethod::supplied;
  int object_pixels = 0;
};

// Fails for: a set with no images, `supplied` without set.mask, a rectangle
// outside the image, an empty result mask (nothing is object), bad options.
Expected<Segmentation> segment(const io::ImageSet& set, const SegmentOptions& options = {});

// The cleaning step on its own (CV_8UC1 in, CV_8UC1 out).
cv::Mat clean_mask(const cv::Mat& mask, const SegmentOptions& options);

}  // namespace veneer::ps

namespace veneer::ps {

// A plinth, stand or table top that the object stands on is in the lit mask
// too, but it is not the object: a designer wants the bull, not its base.
// Supports are found on the solved normals: flat regions (every pixel within
// `plane_deg` of its neighbour and of the region's mean normal, at least
// `min_plane_fraction` of the mask) that reach the bottom of the object, with
// the flat regions touching them; they are dropped when together they are
// less than `max_support_fraction` of the mask and what stands on them touches
// them along a small part of their outline (legs, a stem, what a shadow hides: at most
// `max_contact_fraction`), so an object made of flat faces (a stack of
// bricks, a box) is left whole.
// Pixels swept up with a support (the seams between its faces, its rim
// against the backdrop) go back to what stands on it when they are nearer to
// it, or as near and closer to its normals (a hoof's outline on the plinth).
struct SupportOptions {
  double plane_deg = 3.0;
  double region_deg = 6.0;
  double min_plane_fraction = 0.01;
  double max_support_fraction = 0.5;
  double max_contact_fraction = 0.45;
  double absorb_deg = 12.0;  // pixels next to a dropped support within this of its normal (its cast shadows) go with it
  // Flat regions this close to the support join it across a thin seam of
  // pixels that belong to no flat region: a crease blurred by the lens, the
  // penumbra of a leg's cast shadow (mixed pixels photometric stereo can't
  // solve). Seams up to twice this wide are dropped with the support.
  int seam_px = 3;
};
struct SupportRemoval {
  int removed_pixels = 0;  // pixels dropped from the mask
  int planes = 0;          // flat regions dropped
};
// `mask` CV_8UC1 and `normals` CV_32FC3 of one size; normals outside the
// remaining mask are left as they were (the caller may clear them).
SupportRemoval drop_supports(cv::Mat& mask, const cv::Mat& normals, const SupportOptions& options = {});
// The same on a solved result: its mask shrinks, and its normals, albedo,
// reliability, residual and depth are cleared outside it; the pixel counts follow.
SupportRemoval drop_supports(PsResult& result, const SupportOptions& options = {});

}  // namespace veneer::ps
