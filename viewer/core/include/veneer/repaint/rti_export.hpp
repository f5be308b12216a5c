#pragma once
// The repainted destination as a relightable file the RTI viewers open
// (RTIViewer, Relight): a Polynomial Texture Map, PTM 1.2 (Malzbender, Gelb,
// Wolters: "Polynomial Texture Map (.ptm) File Format", HP Labs 2001).
//
// Per pixel and colour, the display value under a light of unit direction
// (lu, lv, lw) -- lu to the right, lv up, as the rig frame's x and y -- is
//   C = a0 lu^2 + a1 lv^2 + a2 lu lv + a3 lu + a4 lv + a5,
// fitted by least squares to the photos under the lamps' directions. The
// file holds the photos as people look at them: the linear photos times one
// exposure gain, through the sRGB curve, 0..255.
//
// PTM_FORMAT_RGB: six coefficients per pixel for each of R, G, B (three
// blocks). PTM_FORMAT_LRGB: six for the luminance and one 8-bit colour per
// pixel, C = L(lu, lv) * colour. Coefficients are bytes: value = (byte -
// bias) * scale with one scale (float) and bias (integer 0..255) per term;
// rows are stored bottom to top.
#include <filesystem>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/util/expected.hpp"
#include "veneer/util/progress.hpp"

namespace veneer::repaint {

enum class PtmFormat { lrgb, rgb };
const char* ptm_format_name(PtmFormat);  // "PTM_FORMAT_LRGB" | "PTM_FORMAT_RGB"

struct RtiExportOptions {
  PtmFormat format = PtmFormat::lrgb;  // LRGB: what RTIBuilder writes by default, a third the size of RGB
  double exposure = 0;                 // linear gain before the sRGB curve; 0 = automatic: the 99.5th
                                       // percentile of every photo's samples becomes 1 (as tonemap_picture)
  Status check() const;
};

// The HSH .rti export: the same photos, exposure and display encoding as the
// PTM's, fitted in hemispherical harmonics (repaint/hsh.hpp).
struct HshExportOptions {
  int order = 0;       // 1..3 (1, 4 or 9 coefficients per colour); 0 = automatic: the highest the lamps
                       // determine by count, hsh_order_for (7 lamps: order 2, 4 coefficients)
  double exposure = 0; // as RtiExportOptions::exposure
  Status check() const;
};

// How well the stored file reproduces the photos: the polynomial evaluated
// from the file's bytes (quantised coefficients and colours, clamped to
// 0..255) at each lamp's direction against the photo in the same display
// encoding, in 8-bit levels over every pixel and channel.
struct RtiFit {
  cv::Size size;
  PtmFormat format = PtmFormat::lrgb;
  double exposure = 1;                 // the gain used
  double rms = 0;                      // all lamps
  std::vector<double> rms_per_lamp;
  double p99 = 0;                      // 99th percentile of |error| over all lamps, pixels, channels
  double photo_spread = 0;             // RMS of the photos about their per-pixel mean over the lamps:
                                       // the residual of a fit that ignored the light
  int hsh_order = 0;                   // > 0: an HSH file of this order (`format` then unused)
  std::string format_label() const;    // "PTM_FORMAT_LRGB" | "PTM_FORMAT_RGB" | "HSH order 2 (4 terms)"
  std::string json() const;            // {"format", "width", "height", "exposure", "rms", "rms_per_lamp", ...}
};

// The automatic exposure gain: 1 / the 99.5th percentile of the photos'
// samples (linear BGR CV_32FC3), 1 when they are all black.
double rti_auto_exposure(const std::vector<cv::Mat>& photos);

// The photo as a PTM holds it: linear BGR times `exposure`, through the sRGB
// curve, scaled to 0..255 (CV_32FC3 BGR).
cv::Mat ptm_display(const cv::Mat& linear_bgr, double exposure);

// Fits and writes `file` (through a temporary, renamed into place) from
// photos (CV_32FC3 BGR, linear, one size) and the unit directions toward
// their lamps (rig frame). Needs at least 6 lamps; directions that do not
// determine all six terms (lamps on one cone around the camera, as a ring
// rig's) get the least-norm polynomial, which still fits the lamps' photos.
// `progress` hears ("fitting PTM", fraction); a cancel stops with "cancelled"
// and no file.
Expected<RtiFit> export_ptm(const std::vector<cv::Mat>& photos, const std::vector<cv::Vec3d>& directions,
                            const std::filesystem::path& file, const RtiExportOptions& options = {},
                            const Progress& progress = {});

// Fits and writes an HSH .rti file (RTIViewer's and Relight's "#HSH1.2"),
// through a temporary renamed into place:
//   "#HSH1.2\n", "3\n" (the file type: HSH), "<width> <height> 3\n" (3
//   colours), "<terms> 2 1\n" (terms per colour, the basis type, 1 byte per
//   coefficient); then terms float32 scales and terms float32 biases
//   (little-endian); then the bytes, rows top to bottom (file row j is the image's row j from the top, as
//   RTIViewer's Hsh::loadData and Relight's LRti::loadHSH read it; a PTM's go bottom to top), per pixel R, G, B
//   each with its terms in hsh_basis's order: coefficient = byte / 255 *
//   scale[k] + bias[k]. A viewer shows clamp(sum_k coefficient_k H_k(light),
//   0, 1) * 255. One scale and bias per term over every pixel and colour.
// The residual is of what the file stores (bytes decoded, clamped), in 8-bit
// levels, as the PTM's. Errors: those of fit_hsh (no lamps, fewer lamps than
// coefficients, ...), named after the file; no file is left behind.
Expected<RtiFit> export_hsh(const std::vector<cv::Mat>& photos, const std::vector<cv::Vec3d>& directions,
                            const std::filesystem::path& file, const HshExportOptions& options = {},
                            const Progress& progress = {});

}  // namespace veneer::repaint
