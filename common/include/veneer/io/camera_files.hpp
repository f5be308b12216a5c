#pragma once
// The files a camera set to RAW+JPEG delivers per shot, made from a linear
// photo: the developed JPEG (what the camera's own processing would write:
// white balanced as shot, the sRGB transfer curve, 8-bit, quality 95, a "fine" JPEG) and
// the DNG (dng.hpp: a losslessly compressed mosaic with an embedded reduced
// JPEG preview). The rig's camera twin stores these per frame and `veneer
// simulate --dng` writes the same, so sets look like a real camera's: at
// 24 Mpx, a JPEG of a few MB and a DNG of ~20-30 MB (not a 16-bit PNG of
// 80 MB and an uncompressed DNG of 42 MB).
#include <string>

#include <opencv2/core.hpp>

#include "veneer/io/dng.hpp"
#include "veneer/io/imageset.hpp"
#include "veneer/util/expected.hpp"

namespace veneer::io {

// A linear photo (CV_32FC3 BGR, 1.0 = white; clipped to [0, 1]) through the
// sRGB transfer curve to 8 bits (CV_8UC3 BGR): what a camera's JPEG holds,
// and what decode_linear_image's inverse sRGB curve undoes. The photo is
// already white balanced (the set's convention), so no gains are applied.
cv::Mat develop_srgb8(const cv::Mat& linear_bgr);
// develop_srgb8 encoded as a baseline JPEG (libjpeg through OpenCV's
// imencode, 4:2:0), quality 1..100.
Expected<std::string> encode_developed_jpeg(const cv::Mat& linear_bgr, int quality = 95);

struct CameraFileOptions {
  int jpeg_quality = 95;  // the developed JPEG's quality, 1..100 (a camera's "fine")
  bool raw = true;        // also the DNG
  DngOptions dng;         // its levels, compression and preview
  Status check() const;
};

struct CameraFiles {
  ImageSet::RawFile developed;  // {"jpg", bytes}
  ImageSet::RawFile raw;        // {"dng", bytes}; empty when options.raw is off
};

// One shot's files (the JPEG and the DNG are encoded in parallel).
Expected<CameraFiles> encode_camera_files(const cv::Mat& linear_bgr, const CameraFileOptions& options = {});

// Gives every photo of `set` (and its ambient frame) its camera files in
// set.developed / set.raw (and the ambient's), encoded in parallel, so
// write_set stores the set as the rig's camera twin does: light_NN.jpg +
// light_NN.dng. The in-memory photos stay as they are.
Status add_camera_files(ImageSet& set, const CameraFileOptions& options = {});

}  // namespace veneer::io
