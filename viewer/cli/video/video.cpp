// Loading libveneer_video.so on demand (video.hpp).
#include "video.hpp"

#include <filesystem>
#include <mutex>

#include <dlfcn.h>

namespace veneer::cli::video {

namespace {

namespace fs = std::filesystem;

struct Loaded {
  const ModuleTable* table = nullptr;
  std::string error;
};

Loaded load() {
  std::error_code ec;
  const fs::path exe_dir = fs::read_symlink("/proc/self/exe", ec).parent_path();
  // beside the program (build/bin), then where `make install` puts it
  const fs::path candidates[] = {exe_dir / "libveneer_video.so",
                                 exe_dir / ".." / VENEER_VIDEO_MODULE_DIR / "libveneer_video.so"};
  Loaded out;
  std::string tried;
  for (const auto& p : candidates) {
    if (!fs::exists(p, ec)) {
      tried += (tried.empty() ? "" : ", ") + p.lexically_normal().string() + " (missing)";
      continue;
    }
    void* handle = ::dlopen(p.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (!handle) {
      const char* why = ::dlerror();
      tried += (tried.empty() ? "" : ", ") + p.lexically_normal().string() + " (" + (why ? why : "?") + ")";
      continue;
    }
    // kept open for the process's life: readers and writers made by it may outlive any scope here
    using Entry = const ModuleTable* (*)();
    auto entry = reinterpret_cast<Entry>(::dlsym(handle, "veneer_video_module"));
    const ModuleTable* table = entry ? entry() : nullptr;
    if (!table || table->version != kModuleVersion) {
      tried += (tried.empty() ? "" : ", ") + p.lexically_normal().string() + " (not a video module of this version)";
      continue;
    }
    out.table = table;
    return out;
  }
  out.error = "the video module libveneer_video.so could not be loaded: tried " + tried;
  return out;
}

std::once_flag once;
Loaded loaded;

}  // namespace

Expected<const ModuleTable*> module() {
  std::call_once(once, [] { loaded = load(); });
  if (!loaded.table) return make_error(loaded.error);
  return loaded.table;
}

Expected<std::unique_ptr<Reader>> open_reader(const std::string& path) {
  auto m = module();
  if (!m) return m.error();
  Reader* r = (*m)->open_reader(path.c_str());
  if (!r) return make_error(path + ": OpenCV cannot read it as a video");
  return std::unique_ptr<Reader>(r);
}

Expected<std::unique_ptr<Writer>> open_writer(const std::string& path, double fps, int width, int height) {
  auto m = module();
  if (!m) return m.error();
  Writer* w = (*m)->open_writer(path.c_str(), fps, width, height);
  if (!w) return make_error(path + ": OpenCV cannot write an MPEG-4 video there");
  return std::unique_ptr<Writer>(w);
}

}  // namespace veneer::cli::video
