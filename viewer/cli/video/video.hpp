#pragma once
// Opening videos from `veneer`: loads libveneer_video.so (video_module.hpp)
// on first use, from beside the program (the build tree) or from
// <prefix>/<libdir>/veneer (installed), so that commands without a video
// never map OpenCV videoio and its codecs.
#include <memory>
#include <string>

#include "veneer/util/expected.hpp"
#include "video_module.hpp"

namespace veneer::cli::video {

// The module's table, loaded once; an error names the paths tried and dlerror's reason.
Expected<const ModuleTable*> module();

Expected<std::unique_ptr<Reader>> open_reader(const std::string& path);
Expected<std::unique_ptr<Writer>> open_writer(const std::string& path, double fps, int width, int height);

}  // namespace veneer::cli::video
