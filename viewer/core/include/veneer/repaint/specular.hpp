#pragma once
// RTI's specular enhancement (Malzbender et al. 2006, as RTIViewer shows it):
// the normals shaded as a grey glossy surface -- Lambert plus a Blinn-Phong
// highlight seen from the camera (+z) -- under a light from `direction`, so
// relief and small dents show that the albedo hides. A view of the normals,
// beside the relighting (relight.hpp), not an estimate of the material.
#include <opencv2/core.hpp>

#include "veneer/util/expected.hpp"

namespace veneer::repaint {

struct SpecularOptions {
  double diffuse = 0.55;    // weight of the Lambert term n.l, [0, 2]; default 0.55
  double specular = 0.7;    // weight of the highlight (n.h)^exponent, [0, 2]; default 0.7
  double exponent = 60;     // Blinn-Phong exponent (larger = smaller, sharper highlight), [1, 1000]; default 60
  Status check() const;
};

// Per pixel: 255 * min(1, diffuse * max(0, n.l) + specular * max(0, n.h)^exponent)
// with l = direction normalised and h = normalise(l + (0, 0, 1)), as 8-bit
// grey BGR (CV_8UC3); pixels whose normal is (0, 0, 0) (outside the object)
// are black. `normals`: CV_32FC3, x, y, z in the rig frame (channel 0 = x).
// Fails, naming what is wrong, on another type, an empty image, a zero
// direction or options outside their ranges.
Expected<cv::Mat> specular_enhancement(const cv::Mat& normals, const cv::Vec3d& direction,
                                       const SpecularOptions& options = {});

}  // namespace veneer::repaint
