// Writes a veneer-set/1 folder atomically (imageset.hpp, write_set).
#include <cerrno>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <ctime>

#include <fcntl.h>
#include <unistd.h>

#include <opencv2/core/utility.hpp>

#include "file_util.hpp"
#include "set_detail.hpp"
#include "veneer/io/image_io.hpp"
#include "veneer/util/log.hpp"
#include "veneer/util/utc_time.hpp"

namespace veneer::io {
namespace fs = std::filesystem;
using namespace detail;

namespace {

// Removes temporary folders left beside `target` by writers that died.
void clean_stale_temps(const fs::path& target) {
  std::error_code ec;
  fs::path parent = target.parent_path().empty() ? fs::path(".") : target.parent_path();
  for (const auto& entry : fs::directory_iterator(parent, ec)) {
    const std::string name = entry.path().filename().string();
    for (const char* kind : {"tmp", "old"}) {
      long pid = detail::temp_sibling_pid(target, name, kind);
      if (pid <= 0) continue;
      if (pid == static_cast<long>(::getpid())) continue;  // ours, maybe another thread's
      if (::kill(static_cast<pid_t>(pid), 0) == 0 || errno != ESRCH) continue;
      std::error_code rm;
      fs::remove_all(entry.path(), rm);
      VLOG_INFO("ImageSet", "removed {} left by a writer that stopped (pid {})", entry.path().string(), pid);
    }
  }
}

// Removes a folder on scope exit unless released.
struct FolderGuard {
  fs::path path;
  ~FolderGuard() {
    if (path.empty()) return;
    std::error_code ec;
    fs::remove_all(path, ec);
  }
};

Status write_bytes(const fs::path& file, const Expected<std::string>& bytes) {
  if (!bytes) return make_error(file.string() + ": " + bytes.message());
  return detail::write_file_synced(file, *bytes);
}

Status write_contents(const ImageSet& set, const fs::path& dir) {
  // Encode the photos in parallel (the slow part), each written as soon as
  // it is encoded and its bytes dropped: a full-resolution PNG is ~100 MB,
  // so only those being encoded are held, not every one (the rig's capture).
  std::vector<Status> written(set.images.size(), Status::success());
  cv::parallel_for_(cv::Range(0, static_cast<int>(set.images.size())), [&](const cv::Range& r) {
    for (int i = r.start; i < r.end; ++i) {
      const size_t k = static_cast<size_t>(i);
      const ImageSet::RawFile* camera = developed_file(set, k);
      written[k] = camera ? detail::write_file_synced(dir / light_file_name(set.lights[k].index, camera->extension),
                                                         camera->bytes)
                          : write_bytes(dir / light_file_name(set.lights[k].index), encode_png16(set.images[k]));
    }
  });
  for (const Status& s : written) {
    if (!s) return s;  // the first by file order
  }
  for (size_t i = 0; i < set.raw.size() && i < set.lights.size(); ++i) {
    if (set.raw[i].bytes.empty()) continue;
    const fs::path f = dir / raw_file_name(set.lights[i].index, set.raw[i].extension);
    if (Status s = detail::write_file_synced(f, set.raw[i].bytes); !s) return s;
  }
  if (!set.ambient.empty()) {
    const ImageSet::RawFile& camera = set.ambient_developed;
    if (Status s = camera.bytes.empty() ? write_bytes(dir / "ambient.png", encode_png16(set.ambient))
                                        : detail::write_file_synced(dir / ("ambient." + camera.extension), camera.bytes);
        !s)
      return s;
    if (!set.ambient_raw.bytes.empty()) {
      const fs::path f = dir / ("ambient." + set.ambient_raw.extension);
      if (Status s = detail::write_file_synced(f, set.ambient_raw.bytes); !s) return s;
    }
  }
  if (!set.mask.empty()) {
    if (Status s = write_bytes(dir / "mask.png", encode_png8(set.mask)); !s) return s;
  }
  const Truth& t = set.truth;
  if (!t.normals.empty() || !t.mask.empty() || !t.albedo.empty() || !t.depth.empty()) {
    fs::path truth = dir / "truth";
    std::error_code ec;
    if (!fs::create_directory(truth, ec)) return make_error(truth.string() + ": cannot create folder: " + ec.message());
    if (!t.normals.empty()) {
      if (Status s = detail::write_file_synced(truth / "normals.pfm", encode_pfm(t.normals, true)); !s) return s;
    }
    if (!t.mask.empty()) {
      if (Status s = write_bytes(truth / "mask.png", encode_png8(t.mask)); !s) return s;
    }
    if (!t.albedo.empty()) {
      if (Status s = write_bytes(truth / "albedo.png", encode_png16(t.albedo)); !s) return s;
    }
    if (!t.depth.empty()) {
      if (Status s = detail::write_file_synced(truth / "depth.pfm", encode_pfm(t.depth, true)); !s) return s;
    }
    if (Status s = detail::fsync_dir(truth); !s) return s;
  }
  // The manifest last: a folder with a set.json has everything it names.
  if (Status s = detail::write_file_synced(dir / "set.json", manifest_json(set)); !s) return s;
  return detail::fsync_dir(dir);
}
}  // namespace

Status write_set(const ImageSet& set_in, const fs::path& folder_in, bool overwrite) {
  fs::path folder = folder_in;
  if (!folder.has_filename()) folder = folder.parent_path();  // "out/" -> "out"
  if (folder.empty()) return make_error("write_set: empty folder name");
  if (Status s = validate(set_in); !s) return make_error(folder.string() + ": cannot write set: " + s.message());
  std::error_code ec;
  const bool exists = fs::exists(fs::symlink_status(folder, ec));
  if (exists && !overwrite) return make_error(folder.string() + ": already exists (not overwriting it)");
  fs::path parent = folder.parent_path().empty() ? fs::path(".") : folder.parent_path();
  fs::create_directories(parent, ec);
  if (ec) return make_error(parent.string() + ": cannot create folder: " + ec.message());
  clean_stale_temps(folder);

  ImageSet set = set_in;  // shallow: cv::Mat shares pixels
  if (set.created.empty()) set.created = veneer::utc_now();
  if (set.id.empty()) set.id = folder.filename().string();

  fs::path tmp = detail::temp_sibling(folder);
  if (!fs::create_directory(tmp, ec)) return make_error(tmp.string() + ": cannot create temporary folder: " + ec.message());
  FolderGuard guard{tmp};
  if (Status s = write_contents(set, tmp); !s) return s;

  if (!exists) {
    // RENAME_NOREPLACE: a folder that appeared meanwhile is never replaced.
    if (::renameat2(AT_FDCWD, tmp.c_str(), AT_FDCWD, folder.c_str(), RENAME_NOREPLACE) != 0) {
      int err = errno;
      if (err == EEXIST) return make_error(folder.string() + ": already exists (not overwriting it)");
      if (err != EINVAL && err != ENOSYS) return make_error(folder.string() + ": cannot rename set into place: " + std::strerror(err));
      if (::rename(tmp.c_str(), folder.c_str()) != 0)
        return make_error(folder.string() + ": cannot rename set into place: " + std::strerror(errno));
    }
    guard.path.clear();
  } else {
    // Swap the new folder with the old one in one step, then drop the old.
    if (::renameat2(AT_FDCWD, tmp.c_str(), AT_FDCWD, folder.c_str(), RENAME_EXCHANGE) != 0) {
      int err = errno;
      if (err != EINVAL && err != ENOSYS) return make_error(folder.string() + ": cannot swap the new set into place: " + std::strerror(err));
      fs::path old = detail::temp_sibling(folder, "old");
      if (::rename(folder.c_str(), old.c_str()) != 0)
        return make_error(folder.string() + ": cannot move the old set aside: " + std::strerror(errno));
      if (::rename(tmp.c_str(), folder.c_str()) != 0) {
        int err2 = errno;
        (void)::rename(old.c_str(), folder.c_str());
        return make_error(folder.string() + ": cannot rename set into place: " + std::strerror(err2));
      }
      guard.path = old;
    }
    // guard.path now holds the old set (tmp after the exchange) and removes it.
  }
  return detail::fsync_dir(parent);
}

}  // namespace veneer::io
