#pragma once
// Video files for `veneer repaint --video`, behind a small shared module
// (libveneer_video.so) that `veneer` opens only when a command reads or
// writes a video: OpenCV's videoio pulls in ffmpeg and GStreamer (a hundred
// and more shared libraries), which every other command would otherwise map
// and initialise at start (issue 42). The module is built beside `veneer`
// and installed in <libdir>/veneer; video.hpp finds and opens it.
//
// The table below is the whole interface: frames cross as cv::Mat (the
// module and the program share libopencv_core), ownership of readers and
// writers passes to the caller (delete them through the same table).
#include <opencv2/core.hpp>

namespace veneer::cli::video {

class Reader {
 public:
  virtual ~Reader() = default;
  // The next frame (BGR, 8 bit); false at the end or on a read error.
  virtual bool read(cv::Mat* frame) = 0;
};

class Writer {
 public:
  virtual ~Writer() = default;
  virtual bool write(const cv::Mat& frame) = 0;
  // Finishes the file (also done by the destructor).
  virtual void close() = 0;
};

struct ModuleTable {
  int version;  // kModuleVersion of the module's build
  // nullptr when OpenCV cannot open the file as a video
  Reader* (*open_reader)(const char* path);
  // an MPEG-4 (mp4v) file at `fps` of `width` x `height` BGR frames; nullptr when it cannot be made
  Writer* (*open_writer)(const char* path, double fps, int width, int height);
};

constexpr int kModuleVersion = 1;

}  // namespace veneer::cli::video

// The module's one exported symbol.
extern "C" const veneer::cli::video::ModuleTable* veneer_video_module();
