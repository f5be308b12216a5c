// Feature vectors (thesis eq. 4.1a, 4.1c); see features.hpp.
#include "veneer/match/features.hpp"

#include <cmath>

#include <opencv2/imgproc.hpp>

namespace veneer::match {

Status check_view(const ObjectView& view, Feature feature, const std::string& role) {
  if (view.mask.empty()) return make_error(role + ": no mask");
  if (view.mask.type() != CV_8UC1) return make_error(role + ": mask must be 8-bit single channel");
  if (cv::countNonZero(view.mask) == 0) return make_error(role + ": the mask is empty (no object pixels)");
  const cv::Size size = view.mask.size();
  if (feature == Feature::normals) {
    if (view.normals.empty()) return make_error(role + ": no normals for the normals feature");
    if (view.normals.type() != CV_32FC3) return make_error(role + ": normals must be CV_32FC3");
    if (view.normals.size() != size)
      return make_error(role + ": normals are " + std::to_string(view.normals.cols) + "x" +
                        std::to_string(view.normals.rows) + " but the mask is " + std::to_string(size.width) +
                        "x" + std::to_string(size.height));
  } else {
    if (view.images.empty()) return make_error(role + ": no photos for the intensities feature");
    for (size_t i = 0; i < view.images.size(); ++i) {
      const cv::Mat& im = view.images[i];
      if (im.type() != CV_32FC3) return make_error(role + ": photo " + std::to_string(i) + " must be CV_32FC3");
      if (im.size() != size) return make_error(role + ": photo " + std::to_string(i) + " differs in size from the mask");
    }
    if (!view.lamps.empty() && view.lamps.size() != view.images.size())
      return make_error(role + ": " + std::to_string(view.lamps.size()) + " lamp ids for " +
                        std::to_string(view.images.size()) + " photos");
  }
  return {};
}

Status check_pair(const ObjectView& destination, const ObjectView& source, Feature feature) {
  if (auto s = check_view(destination, feature, "destination"); !s) return s;
  if (auto s = check_view(source, feature, "source"); !s) return s;
  if (feature == Feature::intensities) {
    if (destination.images.size() != source.images.size())
      return make_error("intensities need the same lamps in both sets: the destination has " +
                        std::to_string(destination.images.size()) + " photos, the source " +
                        std::to_string(source.images.size()));
    if (!destination.lamps.empty() && !source.lamps.empty()) {
      for (size_t i = 0; i < destination.lamps.size(); ++i) {
        if (destination.lamps[i] != source.lamps[i])
          return make_error("intensities need the same lamps in both sets: photo " + std::to_string(i) +
                            " is lamp '" + destination.lamps[i] + "' in the destination but '" +
                            source.lamps[i] + "' in the source");
      }
    }
  }
  return {};
}

Expected<cv::Mat> pixel_values(const ObjectView& view, Feature feature) {
  const cv::Size size = view.mask.size();
  if (feature == Feature::normals) {
    cv::Mat out(size, CV_32FC3, cv::Scalar::all(0));
    view.normals.copyTo(out, view.mask);
    return out;
  }
  const int lamps = static_cast<int>(view.images.size());
  if (lamps > CV_CN_MAX) return make_error("too many lamps for the intensities feature: " + std::to_string(lamps));
  cv::Mat out(size, CV_32FC(lamps), cv::Scalar::all(0));
  std::vector<float> grey(lamps);
  for (int y = 0; y < size.height; ++y) {
    const uchar* m = view.mask.ptr<uchar>(y);
    float* o = out.ptr<float>(y);
    for (int x = 0; x < size.width; ++x) {
      if (!m[x]) continue;
      double sum = 0;
      for (int l = 0; l < lamps; ++l) {
        const cv::Vec3f& c = view.images[l].at<cv::Vec3f>(y, x);
        grey[l] = std::max(0.0f, (c[0] + c[1] + c[2]) / 3.0f);
        sum += grey[l];
      }
      // eq. 4.1a: each lamp's grey intensity over the pixel's sum; a black
      // pixel has no direction information and stays 0.
      if (sum > 0)
        for (int l = 0; l < lamps; ++l) o[x * lamps + l] = static_cast<float>(grey[l] / sum);
    }
  }
  return out;
}

Expected<FeatureSet> make_features(const ObjectView& view, Feature feature, int patch) {
  if (patch != 1 && patch != 3 && patch != 5 && patch != 7)
    return make_error("patch must be 1, 3, 5 or 7, got " + std::to_string(patch));
  auto values = pixel_values(view, feature);
  if (!values) return values.error();
  const cv::Mat& v = *values;
  const int channels = v.channels();
  FeatureSet fs;
  fs.patch = patch;
  fs.dims = channels * patch * patch;
  fs.size = view.mask.size();
  fs.row_of = cv::Mat(fs.size, CV_32SC1, cv::Scalar(-1));
  for (int y = 0; y < fs.size.height; ++y) {
    const uchar* m = view.mask.ptr<uchar>(y);
    for (int x = 0; x < fs.size.width; ++x) {
      if (!m[x]) continue;
      fs.row_of.at<int>(y, x) = static_cast<int>(fs.pixels.size());
      fs.pixels.emplace_back(x, y);
    }
  }
  if (fs.pixels.empty()) return make_error("the mask is empty (no object pixels)");
  fs.bbox = cv::boundingRect(fs.pixels);
  fs.data.resize(fs.pixels.size() * static_cast<size_t>(fs.dims));
  const int r = patch / 2;
  auto on_object = [&](int x, int y) {
    return x >= 0 && y >= 0 && x < fs.size.width && y < fs.size.height && view.mask.at<uchar>(y, x) != 0;
  };
  for (size_t i = 0; i < fs.pixels.size(); ++i) {
    const cv::Point p = fs.pixels[i];
    float* out = fs.data.data() + i * fs.dims;
    for (int dy = -r; dy <= r; ++dy) {
      for (int dx = -r; dx <= r; ++dx) {
        int x = p.x + dx, y = p.y + dy;
        if (!on_object(x, y)) {
          x = p.x - dx;  // mirrored through the centre
          y = p.y - dy;
          if (!on_object(x, y)) x = p.x, y = p.y;
        }
        const float* src = v.ptr<float>(y) + static_cast<size_t>(x) * channels;
        for (int c = 0; c < channels; ++c) *out++ = src[c];
      }
    }
  }
  return fs;
}

}  // namespace veneer::match
