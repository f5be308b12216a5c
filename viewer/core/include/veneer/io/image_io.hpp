#pragma once
// Single-image files: PFM (float), 16-bit linear PNG, pictures for people.
#include <filesystem>

#include <opencv2/core.hpp>

#include "veneer/util/expected.hpp"

namespace veneer {

// PFM: little-endian, bottom row first. 1 or 3 channels, CV_32F.
// `xyz_order`: the Mat's channel 0 goes to the file's R slot (for normals and
// maps, whose channels are x,y,z); otherwise the Mat is taken as BGR (a photo)
// and written so that the file's R slot holds the red channel.
Status write_pfm(const std::filesystem::path& file, const cv::Mat& image, bool xyz_order);
Expected<cv::Mat> read_pfm(const std::filesystem::path& file, bool xyz_order);

// 16-bit linear PNG from/to CV_32FC3 BGR in [0,1] (values clamped).
Status write_png16(const std::filesystem::path& file, const cv::Mat& image);
// Reads an 8- or 16-bit PNG (or PPM/PGM) as CV_32FC3 BGR scaled to [0,1];
// grey images are expanded to 3 channels.
Expected<cv::Mat> read_linear_image(const std::filesystem::path& file);

// Pictures a person looks at (8-bit PNG):
cv::Mat normals_picture(const cv::Mat& normals);  // RGB = (n+1)/2, black outside
cv::Mat tonemap_picture(const cv::Mat& linear, double percentile = 99.5);  // sRGB gamma, auto exposure
Status write_picture(const std::filesystem::path& file, const cv::Mat& bgr8);

// Writes bytes to `file` via a temporary and rename (fsynced).
Status write_file_atomic(const std::filesystem::path& file, const std::string& bytes);

}  // namespace veneer
