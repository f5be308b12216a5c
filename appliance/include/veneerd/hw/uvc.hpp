#pragma once
// The "uvc" camera: a USB webcam through V4L2 (OpenCV's video capture), for
// cheap rigs. Manual exposure where the driver offers it; stills are frames
// of the stream, linearised from sRGB; live view is the same stream as JPEG.
#include <memory>
#include <mutex>
#include <string>

#include <nlohmann/json.hpp>

#include "veneer/util/expected.hpp"
#include "veneerd/devices/camera.hpp"

namespace veneerd::hw {

struct UvcOptions {
  std::string device = "/dev/video0";  // a path, or an index as text ("0")
  int width = 1280, height = 720;      // requested stream size; the driver may pick another
  int flush_frames = 4;                // frames dropped after an exposure change (driver queue)
};

veneer::Expected<UvcOptions> parse_uvc_options(const nlohmann::json& section, const std::string& where);

class UvcCamera : public Camera {
 public:
  explicit UvcCamera(UvcOptions options);
  ~UvcCamera() override;
  std::string name() const override { return "uvc"; }
  veneer::Status open() override;
  bool connected() const override;
  veneer::Expected<CameraDescription> describe() override;
  veneer::Status set_exposure(const Exposure& exposure) override;
  veneer::Expected<Still> capture() override;
  veneer::Expected<std::vector<unsigned char>> preview() override;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  mutable std::mutex mu_;
};

}  // namespace veneerd::hw
