// Sets to the objects a matcher sees (object.hpp).
#include "veneer/match/object.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>

#include <opencv2/imgproc.hpp>

#include "veneer/ps/photometric_stereo.hpp"
#include "veneer/ps/segmentation.hpp"

namespace veneer::match {

namespace {
using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }
}  // namespace

cv::Size scaled_size(cv::Size size, double scale) {
  if (scale == 1.0) return size;
  return {std::max(1, static_cast<int>(std::lround(size.width * scale))),
          std::max(1, static_cast<int>(std::lround(size.height * scale)))};
}

void scale_set(io::ImageSet& set, double scale) {
  if (scale == 1.0) return;
  const cv::Size size = scaled_size(set.size, scale);
  auto area = [&](cv::Mat& m) {
    if (m.empty()) return;
    if (m.depth() != CV_16F) {
      cv::resize(m, m, size, 0, 0, cv::INTER_AREA);
      return;
    }
    cv::Mat wide;  // half floats (io::ReadOptions::half_floats): resized as float, one frame at a time
    m.convertTo(wide, CV_MAKETYPE(CV_32F, m.channels()));
    cv::resize(wide, wide, size, 0, 0, cv::INTER_AREA);
    wide.convertTo(m, m.type());
  };
  auto nearest = [&](cv::Mat& m) {
    if (!m.empty()) cv::resize(m, m, size, 0, 0, cv::INTER_NEAREST);
  };
  for (auto& im : set.images) area(im);
  area(set.ambient);
  nearest(set.mask);
  nearest(set.truth.mask);
  nearest(set.truth.normals);
  area(set.truth.albedo);
  nearest(set.truth.depth);
  const double sx = static_cast<double>(size.width) / set.size.width;
  set.camera.focal_px *= sx;
  set.camera.cx *= sx;
  set.camera.cy *= static_cast<double>(size.height) / set.size.height;
  set.size = size;
}

namespace {
std::string who_of(const io::ImageSet& set) { return set.id.empty() ? set.origin.string() : set.id; }
}  // namespace

Expected<cv::Mat> object_mask(const io::ImageSet& set, bool truth_normals) {
  if (truth_normals) {
    if (!set.truth.present())
      return make_error("set " + who_of(set) + " has no truth/normals.pfm (needed by truth normals)");
    if (!set.truth.mask.empty()) return set.truth.mask.clone();
    cv::Mat m;
    cv::transform(set.truth.normals, m, cv::Matx13f(1, 1, 1));
    return cv::Mat(m != 0);
  }
  auto seg = ps::segment(set);
  if (!seg) return make_error("set " + who_of(set) + ": segmentation: " + seg.message());
  return seg->mask;
}

Expected<PreparedObject> prepare_object(const io::ImageSet& set, bool truth_normals, const Progress& progress) {
  PreparedObject out;
  auto t0 = Clock::now();
  auto mask = object_mask(set, truth_normals);
  if (!mask) return mask.error();
  out.view.mask = std::move(*mask);
  if (truth_normals) {
    out.view.normals = set.truth.normals.clone();
  } else {
    out.segment_seconds = since(t0);
    t0 = Clock::now();
    auto solved = ps::photometric_stereo(set, out.view.mask, {}, progress);
    if (!solved) return make_error("set " + who_of(set) + ": photometric stereo: " + solved.message());
    if (set.mask.empty()) {  // a base the object stands on is not the object (a supplied mask is the user's word)
      ps::drop_supports(*solved);
      out.view.mask = solved->mask;
    }
    out.normals_seconds = since(t0);
    out.view.normals = solved->normals;
  }
  for (const auto& im : set.images) {
    cv::Mat photo = im.clone();
    if (!set.ambient.empty() && set.ambient.size() == im.size()) {
      photo -= set.ambient;
      photo = cv::max(photo, 0.0);
    }
    out.view.images.push_back(photo);
  }
  for (const auto& light : set.lights) out.view.lamps.push_back(light.lamp_id);
  if (out.view.lamps.size() != out.view.images.size()) out.view.lamps.clear();
  return out;
}

}  // namespace veneer::match
