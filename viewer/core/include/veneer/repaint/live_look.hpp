#pragma once
// The live view's shaded look (issue 40): each live frame of the source
// painted as the still look (look.hpp) is, at the light the frame was taken
// under -- also at lamps the rig never captured.
//
//   1. The light in the frame: from the frame (registered to the source's
//      stills), the source's normals and albedo, one lamp's direction (and,
//      when the source's lamps are near, its position on the lamps' plane),
//      colour, intensity and the ambient, with a residual that says when one
//      lamp does not explain the frame (two lamps, a hand in the way).
//   2. The destination's shading at that light: a relightable model of the
//      destination's own photos (relightable.hpp; cast shadows and its gloss
//      in it, not only Lambert on normals), evaluated per pixel as one small
//      dot product with coefficients worked out once per map.
//   3. The frame painted: the source's texture T whole through the map
//      (ShadedLook::texture()), times the destination's shading at the light
//      over its median, plus the source's gloss placed by the destination's
//      normals for that light, times what the frame holds beyond the
//      source's own predicted shading at that light (the frame over the
//      source's model, carried through the map, dead-zoned and clipped), so
//      what changes on the source still comes through.
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/repaint/look.hpp"
#include "veneer/repaint/relightable.hpp"
#include "veneer/repaint/shadows.hpp"
#include "veneer/util/expected.hpp"
#include "veneer/util/progress.hpp"

namespace veneer::repaint {

// The light a live frame was taken under, as estimated from it.
struct LiveLight {
  cv::Vec3d direction{0, 0, 1};          // unit, rig frame, from the object toward the lamp
  std::optional<cv::Vec3d> position_m;   // near lamps: where the direction meets the source lamps' plane
                                         // (rig frame, m); none for distant lamps
  cv::Vec3d colour{1, 1, 1};             // r, g, b relative to the stills' lamps (mean 1)
  double intensity = 0;                  // the lamp's strength in the frame's linear units per unit of the
                                         // stills' (the camera's exposure included)
  double ambient = 0;                    // light from all around, in the same units (per unit albedo)
  double residual = 0;                   // relative RMS of what one lamp leaves of the frame on the
                                         // sampled object pixels (0 = explained exactly)
  bool explained = true;                 // false: one lamp does not explain the frame
  std::string fallback;                  // what the view did then ("held the last good light",
                                         // "pixel copy"), "" when explained
};

struct LightEstimateOptions {
  int samples = 3000;            // object pixels the light is estimated on, 100..100000; default 3000
  int iterations = 4;            // reweighted fits (cast shadows and highlights down-weighted), 1..20; default 4
  double max_residual = 0.25;    // above this residual one lamp does not explain the frame, (0, 10]; default
                                 // 0.25. Measured: real single lamps (cat, buddha, each lamp left out of the
                                 // model) 0.04-0.17; simulated 0.01-0.04; a hand over a third of the orange
                                 // 0.60; two lamps 140 deg apart on the orange 0.20 (both light most of what
                                 // the camera sees: for a matte object that is one lamp between them, and it
                                 // is shaded as one)
  int hold_frames = 30;          // an unexplained frame holds the last good light for at most this many
                                 // frames, then paints the pixel copy, 0..100000; default 30
  bool srgb = true;              // live frames are 8-bit sRGB (decoded to linear first); default on
  Status check() const;
};

struct LiveLookOptions {
  RelightableOptions model;      // the relightable model of each side's shading
  LightEstimateOptions light;    // the light estimate
  double change_dead_zone = 1.0;   // |log(frame / source's prediction)| below this is the model's own error and
                                   // is dropped; beyond it the change (a sticker, a finger's shadow) comes
                                   // through, [0, 5]. Default 1.0: the source model's per-pixel error reaches
                                   // well past 0.25 and came through as speckle. Live / copy, 0.25 -> 0.7 ->
                                   // 1.0 -> 5 (off): real pairs, lamps left out, 0.69 -> 0.66 -> 0.65 -> 0.63;
                                   // the demo pair's spiral, one exposure, 0.72 -> 0.71 -> 0.70 -> 0.69
  double change_clip = 2.0;      // what comes through clipped to [1/x, x], [1, 100]; default 2
  bool extrapolate = true;       // lamps on a ring (a ring rig's): a light farther off the camera's axis than
                                 // the ring is shaded as each side's model at the ring's angle l' (same azimuth)
                                 // times the Lambert ratio (n.l + e) / (n.l' + e) on that side's normals; inside
                                 // the ring the model alone. Default on. Measured on the simulated ring sequence
                                 // (simlive.sh, 1024x680 x 24): live/copy 1.33 -> 1.13 (see live_look.cpp)
  double extrapolate_floor = 0.02;  // e above, (0, 1]; default 0.02 (simlive.sh 512x340 x 12: 0.005 1.08,
                                    // 0.02 1.09, 0.05 1.13, 0.1 1.16, 0.2 1.19)
  double extrapolate_ring_deg = 5;  // the lamps are a ring when their angles off the axis are within this of each
                                    // other, [0, 90]; default 5 (lamps spread over the hemisphere, as DiLiGenT's,
                                    // are left to the model: extrapolated by elevation alone, livelook_all.sh
                                    // measured 0.70x the copy against 0.69x)
  bool shadows = true;           // the light's own cast shadows on the destination (issue 47, shadows.hpp): its
                                 // model fitted on its photos with their cast shadows taken out (each shadowed
                                 // sample replaced by its albedo x n.l), its shading times the visibility at the
                                 // light, from horizons of its normals' heights told the photos' shadows; off =
                                 // the captured lamps' shadows as the photos hold them. Default on
  ShadowOptions shadow;          // those horizons
  Status check() const;
};

// Everything a live frame's shaded look needs, worked out once per map.
class LiveLook {
 public:
  // `look`: the still look of this map; `destination`, `source`: the views
  // and lamp directions it was made from (the map's scale); `source_positions`:
  // the source's lamps' positions (rig frame, m), one per lamp, or empty for
  // distant lamps. Fails, naming it, on sizes that do not fit the look, lamps
  // that do not match the photos, or options out of range; "cancelled".
  static Expected<LiveLook> make(const ShadedLook& look, const LookSide& destination, const LookSide& source,
                                 const Map& map, const std::vector<cv::Vec3d>& source_positions = {},
                                 const LiveLookOptions& options = {}, const Progress& progress = {});

  // The light in `frame` (8-bit BGR, sRGB unless options().light.srgb is
  // off), whose pixel map_source_to_frame * (x, y, 1) shows the map's source
  // pixel (x, y) (registration and the live geometry). Never fails on a
  // frame: one that one lamp does not explain comes back with explained = false.
  LiveLight estimate_light(const cv::Mat& frame, const cv::Matx23d& map_source_to_frame) const;

  // The destination-sized 8-bit BGR picture of `frame` at `light`: mapped
  // pixels painted as above, times `exposure`, the others `backdrop` (or black).
  cv::Mat paint(const cv::Mat& frame, const cv::Matx23d& map_source_to_frame, const LiveLight& light,
                const cv::Mat& backdrop, double exposure = 1.0) const;

  // The look at a captured lamp (unit direction, intensity 1, no ambient,
  // no change from the frame): linear CV_32FC3 in the stills' units, for
  // comparing with ShadedLook::paint.
  cv::Mat paint_linear(const cv::Vec3d& direction) const;

  const LiveLookOptions& options() const { return options_; }
  cv::Size destination_size() const { return size_; }

 private:
  LiveLookOptions options_;
  cv::Size size_;
  std::shared_ptr<const struct LiveLookData> data_;
};

}  // namespace veneer::repaint
