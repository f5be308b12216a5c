#pragma once
// The camera. Implementations: "simulated" (renders the scene under the lamps
// the bridge reports on), "gphoto2" (DSLR over USB/PTP), "uvc" (V4L2 webcam).
#include <functional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/util/expected.hpp"

namespace veneerd {

struct Exposure {
  double shutter_s = 0;   // 0 = leave as configured
  double aperture = 0;    // f-number, 0 = leave
  int iso = 0;            // 0 = leave
};

struct CameraDescription {
  std::string model;
  std::vector<std::string> shutter_values;   // as the camera offers them
  std::vector<std::string> aperture_values;
  std::vector<std::string> iso_values;
};

struct Still {
  cv::Mat linear;              // CV_32FC3 BGR, linear, [0,1] — what goes into the set
  std::string original_name;   // e.g. "IMG_0001.CR2"; empty for simulated
  std::vector<unsigned char> original;  // full-resolution file as delivered (may be empty)
  // The camera's own developed JPEG of the shot when it delivered one at the
  // size of `linear` (a RAW+JPEG body; the simulated camera): the set stores
  // it as the photo instead of a 16-bit PNG of `linear`. May be empty.
  std::vector<unsigned char> developed_jpeg;
};

class Camera {
 public:
  virtual ~Camera() = default;
  virtual std::string name() const = 0;
  virtual veneer::Status open() = 0;   // idempotent; keeps the session open
  virtual bool connected() const = 0;
  virtual veneer::Expected<CameraDescription> describe() = 0;
  virtual veneer::Status set_exposure(const Exposure& exposure) = 0;
  virtual veneer::Expected<Still> capture() = 0;
  // One live-view frame as JPEG bytes.
  virtual veneer::Expected<std::vector<unsigned char>> preview() = 0;
  // Called from any thread when the camera goes away or comes back.
  std::function<void(bool connected)> on_connection_change;
};

}  // namespace veneerd
