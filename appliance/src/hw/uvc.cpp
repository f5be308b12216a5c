// UVC webcams through OpenCV's V4L2 capture.
#include "veneerd/hw/uvc.hpp"

#include <filesystem>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

#include "veneer/util/log.hpp"
#include "veneerd/hw/gphoto2.hpp"

namespace veneerd::hw {

struct UvcCamera::Impl {
  UvcOptions opt;
  cv::VideoCapture cap;
  bool warned_aperture = false, warned_iso = false;
  bool open = false;
};

veneer::Expected<UvcOptions> parse_uvc_options(const nlohmann::json& s, const std::string& where) {
  UvcOptions o;
  if (!s.is_object()) return veneer::make_error(where + ": expected an object");
  for (const auto& [key, value] : s.items()) {
    if (key != "backend" && key != "device" && key != "width" && key != "height" && key != "flush_frames")
      return veneer::make_error(where + ": unknown field '" + key + "' for the uvc camera");
  }
  if (s.contains("device")) {
    const auto& d = s["device"];
    if (d.is_string()) o.device = d.get<std::string>();
    else if (d.is_number_integer() && d.get<int>() >= 0) o.device = std::to_string(d.get<int>());
    else return veneer::make_error(where + ".device: expected a path like \"/dev/video0\" or an index");
  }
  for (auto [key, field, lo, hi] : {std::tuple{"width", &o.width, 16, 8192}, std::tuple{"height", &o.height, 16, 8192},
                                    std::tuple{"flush_frames", &o.flush_frames, 0, 30}}) {
    if (!s.contains(key)) continue;
    if (!s[key].is_number_integer() || s[key].get<int>() < lo || s[key].get<int>() > hi)
      return veneer::make_error(where + "." + key + ": expected an integer " + std::to_string(lo) + ".." + std::to_string(hi));
    *field = s[key].get<int>();
  }
  return o;
}

UvcCamera::UvcCamera(UvcOptions options) : impl_(std::make_unique<Impl>()) { impl_->opt = std::move(options); }
UvcCamera::~UvcCamera() = default;

bool UvcCamera::connected() const {
  std::lock_guard<std::mutex> l(mu_);
  return impl_->open && impl_->cap.isOpened();
}

veneer::Status UvcCamera::open() {
  std::lock_guard<std::mutex> l(mu_);
  if (impl_->open && impl_->cap.isOpened()) return {};
  const std::string& dev = impl_->opt.device;
  bool is_index = !dev.empty() && dev.find_first_not_of("0123456789") == std::string::npos;
  if (!is_index && !std::filesystem::exists(dev))
    return veneer::make_error("uvc camera: " + dev + " does not exist: is the webcam plugged in? (`ls /dev/video*`)");
  bool ok = is_index ? impl_->cap.open(std::stoi(dev), cv::CAP_V4L2) : impl_->cap.open(dev, cv::CAP_V4L2);
  if (!ok || !impl_->cap.isOpened())
    return veneer::make_error("uvc camera: cannot open " + dev +
                              " through V4L2 (busy with another program, no permission — group video —, or not a capture device)");
  impl_->cap.set(cv::CAP_PROP_FRAME_WIDTH, impl_->opt.width);
  impl_->cap.set(cv::CAP_PROP_FRAME_HEIGHT, impl_->opt.height);
  impl_->open = true;
  VLOG_INFO("Camera", "uvc camera {} open at {}x{}", dev, impl_->cap.get(cv::CAP_PROP_FRAME_WIDTH),
            impl_->cap.get(cv::CAP_PROP_FRAME_HEIGHT));
  if (on_connection_change) on_connection_change(true);
  return {};
}

veneer::Expected<CameraDescription> UvcCamera::describe() {
  if (auto s = open(); !s) return s.error();
  std::lock_guard<std::mutex> l(mu_);
  CameraDescription d;
  d.model = "UVC webcam " + impl_->opt.device + " (" + impl_->cap.getBackendName() + ")";
  double e = impl_->cap.get(cv::CAP_PROP_EXPOSURE);
  // V4L2's exposure_absolute counts 100 µs steps; the driver decides which it accepts.
  d.shutter_values.push_back("any in 100 µs steps (now " + std::to_string(e * 1e-4) + " s)");
  d.aperture_values.push_back("fixed");
  d.iso_values.push_back("fixed (gain " + std::to_string(impl_->cap.get(cv::CAP_PROP_GAIN)) + ")");
  return d;
}

veneer::Status UvcCamera::set_exposure(const Exposure& e) {
  if (auto s = open(); !s) return s;
  std::lock_guard<std::mutex> l(mu_);
  if (e.aperture > 0 && !impl_->warned_aperture) {
    VLOG_WARN("Camera", "uvc camera: webcams have a fixed aperture; f/{} ignored", e.aperture);
    impl_->warned_aperture = true;
  }
  if (e.iso > 0 && !impl_->warned_iso) {
    VLOG_WARN("Camera", "uvc camera: no ISO setting over V4L2; ISO {} ignored", e.iso);
    impl_->warned_iso = true;
  }
  if (e.shutter_s > 0) {
    // 1 = V4L2_EXPOSURE_MANUAL for the V4L2 back-end.
    if (!impl_->cap.set(cv::CAP_PROP_AUTO_EXPOSURE, 1))
      return veneer::make_error("uvc camera " + impl_->opt.device + ": the driver does not allow manual exposure");
    double units = e.shutter_s * 1e4;
    if (!impl_->cap.set(cv::CAP_PROP_EXPOSURE, units))
      return veneer::make_error("uvc camera " + impl_->opt.device + ": the driver refused an exposure of " +
                                std::to_string(e.shutter_s) + " s");
    cv::Mat drop;
    for (int i = 0; i < impl_->opt.flush_frames; ++i) impl_->cap.read(drop);
  }
  return {};
}

veneer::Expected<Still> UvcCamera::capture() {
  if (auto s = open(); !s) return s.error();
  std::lock_guard<std::mutex> l(mu_);
  cv::Mat frame;
  // The driver queues a few frames: take a fresh one.
  for (int i = 0; i <= impl_->opt.flush_frames; ++i) {
    if (!impl_->cap.read(frame)) {
      impl_->open = false;
      impl_->cap.release();
      if (on_connection_change) on_connection_change(false);
      return veneer::make_error("uvc camera " + impl_->opt.device + ": no frame (unplugged?)");
    }
  }
  if (frame.type() != CV_8UC3) return veneer::make_error("uvc camera: unexpected frame format");
  Still s;
  s.linear = linearize_srgb8(frame);
  cv::imencode(".png", frame, s.original);
  s.original_name = "frame.png";
  return s;
}

veneer::Expected<std::vector<unsigned char>> UvcCamera::preview() {
  if (auto s = open(); !s) return s.error();
  std::lock_guard<std::mutex> l(mu_);
  cv::Mat frame;
  if (!impl_->cap.read(frame)) return veneer::make_error("uvc camera " + impl_->opt.device + ": no frame (unplugged?)");
  std::vector<unsigned char> jpeg;
  cv::imencode(".jpg", frame, jpeg, {cv::IMWRITE_JPEG_QUALITY, 85});
  return jpeg;
}

}  // namespace veneerd::hw
