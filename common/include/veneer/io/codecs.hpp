#pragma once
// OpenCV's image codecs (libopencv_imgcodecs), opened the first time one is
// called (issue 48). Linking them made every `veneer` command map ~110
// libraries at start (GDAL, GDCM, HDF5, Poppler ...) for the few files that
// are neither the sets' PNGs (png_codec.hpp) nor PFMs: JPEG photos, TIFFs,
// pictures. The same calls as cv::imdecode, cv::imencode, cv::imread and
// cv::imwrite; when the library cannot be opened they throw cv::Exception
// naming it (as OpenCV's own errors do), so callers handle both alike.
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>  // the IMREAD_* / IMWRITE_* flags (no symbol of the library)

namespace veneer::io::codecs {

cv::Mat imdecode(cv::InputArray bytes, int flags);
bool imencode(const std::string& ext, cv::InputArray image, std::vector<uchar>& bytes,
              const std::vector<int>& params = std::vector<int>());
cv::Mat imread(const std::string& file, int flags = cv::IMREAD_COLOR);
bool imwrite(const std::string& file, cv::InputArray image, const std::vector<int>& params = std::vector<int>());
// Whether the library is open in this process (loaded by a call, or linked).
bool loaded();

}  // namespace veneer::io::codecs
