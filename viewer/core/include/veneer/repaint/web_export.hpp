#pragma once
// The repainted destination as a web page anyone can open (issue 50): a
// folder that opens by double click in a browser, with no network and nothing
// fetched at run time, where dragging on the picture moves the light.
//
// The look is the HSH fit of the repainted photos (repaint/hsh.hpp, as the
// HSH .rti export: the photos through one exposure gain and the sRGB curve,
// values 0..1), made at most `max_side` px on its longer side. The folder:
//   info.json, plane_K.jpg   Relight's web layout, the one OpenLIME's RTI layer
//                            and Relight (Rti::load) read: {"width", "height",
//                            "format": "jpg", "type": "hsh", "colorspace": "rgb",
//                            "nplanes": 3 x terms, "quality", "materials": [{"scale",
//                            "bias"}], "lights"}; plane_K.jpg holds term K's
//                            coefficient of R, G, B in its R, G, B (plane p = 3 K +
//                            colour), rows top to bottom, quantised per plane:
//                            coefficient = (byte / 255 - bias[p]) * scale[p] (display
//                            units 0..1; Relight's Material::Plane::dequantize
//                            times 255)
//   index.html               our viewer: WebGL (one pass, a sampler per term),
//                            else a 2D canvas, else still.jpg; the object's and the
//                            source material's names; the light from its URL,
//                            index.html#light=x,y (x right, y up, the unit disc:
//                            z = sqrt(1 - x^2 - y^2)), `&bare` shows the picture
//                            alone at 1:1 in the window's corner (for a screenshot)
//   look.js                  what the page needs, loaded by a script tag (a page
//                            opened from file:// may not fetch() its folder, and
//                            images from file:// taint a canvas): the fit's numbers
//                            and the plane JPEGs again, as data: URLs
//   still.jpg                the look at the page's first light, for browsers
//                            without WebGL or canvas
// A light is drawn as clamp(sum_K coefficient_K H_K(light), 0, 1) * 255.
#include <filesystem>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/repaint/hsh.hpp"
#include "veneer/util/expected.hpp"
#include "veneer/util/progress.hpp"

namespace veneer::repaint {

struct WebExportOptions {
  int max_side = 2048;     // px: the look's longer side at most this (reduced by area averaging); 0 =
                           // full size. 2048: a phone's screen shows ~1100-1400 px across, every WebGL
                           // device takes a 2048 texture, and 4 planes stay a few MB
  int order = 0;           // HSH order 1..3; 0 = the highest the lamps determine (hsh_order_for: 7 lamps 2)
  double exposure = 0;     // linear gain before the sRGB curve; 0 = automatic, as the .rti export's
  int jpeg_quality = 93;   // the planes' and the still's JPEG quality, 50..100 (the demo pair: 95 draws
                           // 1.55 levels from the fit on average, a 6.1 MB folder; 90 2.55, 3.9 MB)
  std::string object;      // the destination object's name, shown on the page
  std::string material;    // the source's name: the material it is shown in
  Status check() const;
};

// The fit the page shows.
struct WebFit {
  HshFit hsh;                       // coefficients per channel (B, G, R Mats), display units 0..1
  cv::Size size;                    // the look's size (the photos' reduced to max_side)
  cv::Size full_size;               // the photos'
  double exposure = 1;              // the gain used
  std::vector<cv::Vec3d> lamps;     // unit directions toward the lamps (rig frame)
};

// The look's size for photos of `full`: the longer side at most max_side (0 = full).
cv::Size web_size(cv::Size full, int max_side);

// Fits the look from the repainted photos (linear BGR CV_32FC3, one size;
// photos already reduced to web_size() are taken as they are) and the unit
// directions toward their lamps. Errors: no photos, a count mismatch, photos of
// different sizes or types, an order the lamps cannot determine (fit_hsh's).
Expected<WebFit> fit_web(const std::vector<cv::Mat>& photos, const std::vector<cv::Vec3d>& directions,
                         const WebExportOptions& options, const Progress& progress = {});

// The page's light (x right, y up; outside the unit disc taken to its rim) as a unit direction.
cv::Vec3d web_light(double x, double y);

// The look under `direction` as the page draws it from unquantised
// coefficients: 8-bit BGR, clamp(value, 0, 1) * 255 rounded.
cv::Mat render_web(const WebFit& fit, const cv::Vec3d& direction);

struct WebExport {
  cv::Size size;                 // the look's
  int terms = 0;                 // per colour
  double exposure = 1;
  cv::Vec2d first_light;         // the page's light when it opens (x, y)
  uintmax_t folder_bytes = 0;    // everything written
  std::string json() const;      // {"width", "height", "terms", "exposure", "first_light", "folder_bytes"}
};

// Whether export_web may write `folder`: it does not exist, is empty, or is
// a page this wrote; else one error naming it.
Status check_web_folder(const std::filesystem::path& folder);

// Fits and writes the page's folder `folder`: written into a temporary
// sibling, then renamed into place; an existing `folder` is replaced only when
// it is a page this wrote (it holds index.html and look.js) or empty, else
// refused. `progress` hears ("web page", fraction); a cancel leaves nothing.
Expected<WebExport> export_web(const std::vector<cv::Mat>& photos, const std::vector<cv::Vec3d>& directions,
                               const std::filesystem::path& folder, const WebExportOptions& options,
                               const Progress& progress = {});

}  // namespace veneer::repaint
