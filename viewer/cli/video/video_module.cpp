// libveneer_video.so: OpenCV videoio behind video_module.hpp's table.
#include "video_module.hpp"

#include <opencv2/videoio.hpp>
#include <opencv2/videoio/registry.hpp>

namespace {

using namespace veneer::cli::video;

class CaptureReader final : public Reader {
 public:
  cv::VideoCapture capture;
  bool read(cv::Mat* frame) override { return capture.isOpened() && capture.read(*frame) && !frame->empty(); }
};

class FileWriter final : public Writer {
 public:
  cv::VideoWriter writer;
  bool write(const cv::Mat& frame) override {
    if (!writer.isOpened()) return false;
    writer.write(frame);
    return true;
  }
  void close() override { writer.release(); }
};

// A file is tried with each backend that reads files, in OpenCV's order of
// preference (as cv::CAP_ANY tries them), but gPhoto2's: that one takes a
// name for a camera, and looking for it enumerates the USB bus through
// libgphoto2 and libusb, whose device list is never freed (issue 49: 5,007
// allocations leaked on every file no other backend could read).
Reader* open_reader(const char* path) {
  auto r = new CaptureReader;
  for (const cv::VideoCaptureAPIs api : cv::videoio_registry::getStreamBackends()) {
    if (api == cv::CAP_GPHOTO2) continue;
    if (r->capture.open(path, api)) return r;
  }
  delete r;
  return nullptr;
}

Writer* open_writer(const char* path, double fps, int width, int height) {
  auto w = new FileWriter;
  if (!w->writer.open(path, cv::VideoWriter::fourcc('m', 'p', '4', 'v'), fps, cv::Size(width, height))) {
    delete w;
    return nullptr;
  }
  return w;
}

const ModuleTable table{kModuleVersion, &open_reader, &open_writer};

}  // namespace

extern "C" __attribute__((visibility("default"))) const ModuleTable* veneer_video_module() { return &table; }
