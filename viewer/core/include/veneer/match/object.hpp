#pragma once
// The object a matcher sees (ObjectView) made from an image set: its mask
// (segmentation, or the truth's), its normals (photometric stereo, or the
// truth's) and its photos with the ambient frame removed.
#include <opencv2/core.hpp>

#include "veneer/io/imageset.hpp"
#include "veneer/match/matcher.hpp"
#include "veneer/util/expected.hpp"
#include "veneer/util/progress.hpp"

namespace veneer::match {

// One object ready for matching, with the stage timings that produced it.
struct PreparedObject {
  ObjectView view;          // normals, mask, photos (ambient removed), lamp ids
  double segment_seconds = 0;
  double normals_seconds = 0;
};

// Resizes a set in place (photos by area, masks and truth nearest, normals
// renormalized, camera intrinsics scaled).
void scale_set(io::ImageSet& set, double scale);
// The size scale_set gives a set of `size`.
cv::Size scaled_size(cv::Size size, double scale);

Expected<PreparedObject> prepare_object(const io::ImageSet& set, bool truth_normals, const Progress& progress = {});
// Only the object's mask, as prepare_object finds it (the truth's with truth
// normals, else the segmentation's), without solving for normals.
Expected<cv::Mat> object_mask(const io::ImageSet& set, bool truth_normals);

}  // namespace veneer::match
