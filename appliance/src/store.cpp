#include "veneerd/store.hpp"

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <fstream>
#include <thread>

#include <fcntl.h>
#include <sys/file.h>
#include <sys/statvfs.h>
#include <unistd.h>

#include <opencv2/imgcodecs.hpp>

#include "veneer/io/image_io.hpp"
#include "veneer/util/log.hpp"
#include "veneer/util/utc_time.hpp"

namespace veneerd {

namespace fs = std::filesystem;
using veneer::make_error;

bool valid_set_id(const std::string& id) {
  if (id.empty() || id.size() > 96 || id.front() == '.') return false;
  return std::all_of(id.begin(), id.end(), [](char ch) {
    return (ch >= 'a' && ch <= 'z') || (ch >= 'A' && ch <= 'Z') || (ch >= '0' && ch <= '9') || ch == '-' ||
           ch == '_' || ch == '.';
  });
}

namespace {

// ".<name>.<kind>-<pid>-<n>": a temporary folder or file left by an atomic writer.
bool leftover_temp(const std::string& name, long& pid) {
  if (name.size() < 4 || name[0] != '.') return false;
  size_t last_dash = name.rfind('-');
  if (last_dash == std::string::npos || last_dash + 1 >= name.size()) return false;
  size_t pid_dash = name.rfind('-', last_dash - 1);
  if (pid_dash == std::string::npos || pid_dash + 1 >= last_dash) return false;
  std::string n = name.substr(last_dash + 1), p = name.substr(pid_dash + 1, last_dash - pid_dash - 1);
  if (n.find_first_not_of("0123456789") != std::string::npos) return false;
  if (p.empty() || p.size() > 9 || p.find_first_not_of("0123456789") != std::string::npos) return false;
  if (name.rfind('.', pid_dash) == 0) return false;  // needs ".<name>.<kind>-"
  pid = std::stol(p);
  return true;
}

uint64_t folder_bytes(const fs::path& folder) {
  uint64_t total = 0;
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(folder, ec); !ec && it != fs::recursive_directory_iterator();
       it.increment(ec)) {
    if (it->is_regular_file(ec)) total += it->file_size(ec);
  }
  return total;
}

}  // namespace

veneer::Expected<std::unique_ptr<Store>> Store::open(const fs::path& root) {
  std::error_code ec;
  fs::create_directories(root, ec);
  if (ec) return make_error("store " + root.string() + ": cannot create folder: " + ec.message());
  if (!fs::is_directory(root)) return make_error("store " + root.string() + ": not a folder");
  fs::path lock = root / ".lock";
  int fd = ::open(lock.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0600);
  if (fd < 0) return make_error("store " + root.string() + ": cannot open " + lock.string() + ": " + std::strerror(errno));
  if (::flock(fd, LOCK_EX | LOCK_NB) != 0) {
    ::close(fd);
    return make_error("store " + root.string() + " is in use by another veneerd");
  }
  std::unique_ptr<Store> store(new Store(root, fd));

  auto log = veneer::log::get("Store");
  // Every temporary here is stale: the store's lock is ours, so the daemon
  // that wrote it has exited. (The writer's pid in the name says nothing: it
  // may by now belong to another process, or to the writer's unreaped
  // zombie, which is how a leftover used to survive one more restart.) The
  // names are gathered first and removed after: removing entries while
  // reading the folder may make readdir skip others.
  std::vector<std::string> ids;
  std::vector<fs::path> stale;
  for (const auto& entry : fs::directory_iterator(root, ec)) {
    std::string name = entry.path().filename().string();
    long pid = -1;
    if (leftover_temp(name, pid)) {
      stale.push_back(entry.path());
      continue;
    }
    if (!entry.is_directory() || !valid_set_id(name)) continue;
    ids.push_back(name);
  }
  for (const auto& path : stale) {
    log->warn("removing leftover temporary {} (an interrupted write)", path.string());
    std::error_code rm;
    fs::remove_all(path, rm);
    if (rm) log->warn("cannot remove {}: {}", path.string(), rm.message());
  }
  for (const auto& id : ids) {
    auto set = store->scan_one(id);
    if (!set) {
      log->warn("ignoring {}: {}", (root / id).string(), set.message());
      continue;
    }
    store->sets_.push_back(std::move(*set));
  }
  std::sort(store->sets_.begin(), store->sets_.end(), [](const StoredSet& a, const StoredSet& b) {
    return a.created != b.created ? a.created < b.created : a.id < b.id;
  });
  if (int purged = store->purge_trash(); purged > 0) log->info("store {}: {} old set(s) purged from the trash", root.string(), purged);
  log->info("store {}: {} set(s)", root.string(), store->sets_.size());
  return store;
}

Store::Store(fs::path root, int lock_fd) : root_(std::move(root)), lock_fd_(lock_fd) {}

Store::~Store() {
  if (lock_fd_ >= 0) ::close(lock_fd_);
}

veneer::Expected<StoredSet> Store::scan_one(const std::string& id) const {
  fs::path folder = root_ / id;
  auto text = veneer::io::read_file_bytes(folder / "set.json");
  if (!text) return text.error();
  auto manifest = veneer::io::parse_manifest(*text, folder);
  if (!manifest) return manifest.error();
  std::error_code ec;
  for (const auto& f : manifest->image_files) {
    if (!fs::is_regular_file(folder / f, ec)) return make_error((folder / f).string() + ": missing");
  }
  for (const auto& f : manifest->raw_files) {
    if (!f.empty() && !fs::is_regular_file(folder / f, ec)) return make_error((folder / f).string() + ": missing");
  }
  const veneer::io::ImageSet& s = manifest->set;
  return StoredSet{.id = id, .role = s.role, .object = s.object, .created = s.created, .scene = s.scene,
                   .size = s.size, .lights = static_cast<int>(s.lights.size()), .warnings = s.warnings,
                   .has_truth = fs::exists(folder / "truth" / "normals.pfm", ec), .bytes = folder_bytes(folder),
                   .deleted = {}};  // a stored set, not one in the trash
}

std::vector<StoredSet> Store::list() const {
  std::lock_guard lock(mutex_);
  return sets_;
}

veneer::Expected<StoredSet> Store::find(const std::string& id) const {
  if (!valid_set_id(id)) return make_error("'" + id + "' is not a set id");
  std::lock_guard lock(mutex_);
  for (const auto& s : sets_) {
    if (s.id == id) return s;
  }
  return make_error("no set '" + id + "' in the store");
}

veneer::Expected<std::string> Store::manifest(const std::string& id) const {
  auto set = find(id);
  if (!set) return set.error();
  return veneer::io::read_file_bytes(root_ / id / "set.json");
}

veneer::Expected<std::vector<std::string>> Store::files(const std::string& id, bool include_truth) const {
  auto set = find(id);
  if (!set) return set.error();
  fs::path folder = root_ / id;
  auto text = veneer::io::read_file_bytes(folder / "set.json");
  if (!text) return text.error();
  auto manifest = veneer::io::parse_manifest(*text, folder);
  if (!manifest) return manifest.error();
  std::vector<std::string> out{"set.json"};
  for (const auto& f : manifest->image_files) out.push_back(f.generic_string());
  if (!manifest->ambient_file.empty()) out.push_back(manifest->ambient_file.generic_string());
  // The camera's RAW files go with the photos (the viewer decodes them by default).
  for (const auto& f : manifest->raw_files) {
    if (!f.empty()) out.push_back(f.generic_string());
  }
  if (!manifest->ambient_raw_file.empty()) out.push_back(manifest->ambient_raw_file.generic_string());
  if (!manifest->mask_file.empty()) out.push_back(manifest->mask_file.generic_string());
  if (include_truth) {
    std::error_code ec;
    std::vector<std::string> truth;
    for (const auto& entry : fs::directory_iterator(folder / "truth", ec)) {
      if (entry.is_regular_file()) truth.push_back("truth/" + entry.path().filename().string());
    }
    std::sort(truth.begin(), truth.end());
    out.insert(out.end(), truth.begin(), truth.end());
  }
  return out;
}

std::string Store::new_id(veneer::io::Role role, const std::string& object) const {
  std::string base = veneer::utc_now("%Y%m%d-%H%M%S") + "-" + veneer::io::role_name(role);
  std::string clean;
  for (char ch : object) {
    if (clean.size() >= 32) break;
    bool ok = (ch >= 'a' && ch <= 'z') || (ch >= 'A' && ch <= 'Z') || (ch >= '0' && ch <= '9') || ch == '-' || ch == '_';
    clean += ok ? ch : '_';
  }
  if (!clean.empty()) base += "-" + clean;
  std::lock_guard lock(mutex_);
  std::string id = base;
  std::error_code ec;
  for (int n = 2;; ++n) {
    bool taken = fs::exists(root_ / id, ec) ||
                 std::any_of(sets_.begin(), sets_.end(), [&](const StoredSet& s) { return s.id == id; });
    if (!taken) return id;
    id = base + "-" + std::to_string(n);
  }
}

uint64_t Store::estimate_bytes(cv::Size size, int photos, bool truth) {
  uint64_t per_photo = static_cast<uint64_t>(size.area()) * 6 + 4096;  // 16-bit RGB, incompressible bound
  uint64_t total = per_photo * static_cast<uint64_t>(photos) + 65536;
  if (truth) total += static_cast<uint64_t>(size.area()) * (12 + 4 + 6 + 1);
  return total;
}

uint64_t Store::free_bytes() const {
  struct statvfs st {};
  if (::statvfs(root_.c_str(), &st) != 0) return 0;
  return static_cast<uint64_t>(st.f_bavail) * st.f_frsize;
}

veneer::Status Store::save(const veneer::io::ImageSet& set) {
  if (!valid_set_id(set.id)) return make_error("cannot store a set under the id '" + set.id + "'");
  uint64_t need = estimate_bytes(set.size, static_cast<int>(set.images.size()) + (set.ambient.empty() ? 0 : 1),
                                 set.truth.present());
  for (const auto& r : set.raw) need += r.bytes.size();
  need += set.ambient_raw.bytes.size();
  if (free_bytes() < need) purge_trash(need);  // the trash gives way first
  const uint64_t free = free_bytes();
  if (free < need) {
    return make_error("store " + root_.string() + " is full: " + std::to_string(free >> 20) +
                      " MiB free, the set needs about " + std::to_string((need >> 20) + 1) + " MiB; no set stored");
  }
  fs::path folder = root_ / set.id;
  if (auto s = veneer::io::write_set(set, folder); !s) {
    return make_error("storing set " + set.id + " failed: " + s.message() + "; no set stored");
  }
  auto scanned = scan_one(set.id);
  if (!scanned) {
    std::error_code ec;
    fs::remove_all(folder, ec);
    return make_error("set " + set.id + " did not read back: " + scanned.message() + "; no set stored");
  }
  std::lock_guard lock(mutex_);
  sets_.push_back(std::move(*scanned));
  return {};
}


// --- a set written frame by frame --------------------------------------------

namespace {


std::string light_png(int index) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "light_%02d.png", index);
  return buf;
}

}  // namespace

veneer::Status Store::write_file(const fs::path& file, std::string_view bytes) const {
  if (write_faults_) {
    const WriteFault f = write_faults_(file);
    if (f.delay.count() > 0) std::this_thread::sleep_for(f.delay);
    if (f.error != 0) {
      // What a failing card leaves: part of the file, then the error.
      const size_t half = bytes.size() / 2;
      (void)veneer::io::write_file_synced(file, bytes.substr(0, half));
      return make_error(file.string() + ": write failed after " + std::to_string(half) + " bytes: " +
                        std::strerror(f.error) + " (injected fault)");
    }
  }
  return veneer::io::write_file_synced(file, bytes);
}

veneer::Status SetWriter::write_encoded(const fs::path& file, const veneer::Expected<std::string>& bytes) {
  if (!bytes) return make_error(file.string() + ": " + bytes.message());
  return store_.write_file(file, *bytes);
}

veneer::Expected<std::unique_ptr<SetWriter>> Store::begin(const std::string& id, bool truth) {
  if (!valid_set_id(id)) return make_error("cannot store a set under the id '" + id + "'");
  std::error_code ec;
  if (fs::exists(root_ / id, ec)) return make_error("cannot store set " + id + ": it exists");
  // ".<id>.capture-<pid>-0": a name Store::open removes as a leftover after a crash.
  fs::path tmp = root_ / ("." + id + ".capture-" + std::to_string(::getpid()) + "-0");
  fs::remove_all(tmp, ec);
  if (!fs::create_directory(tmp, ec))
    return make_error("cannot store set " + id + ": cannot create " + tmp.string() + ": " + ec.message());
  return std::unique_ptr<SetWriter>(new SetWriter(*this, id, tmp, truth));
}

SetWriter::~SetWriter() {
  if (tmp_.empty()) return;
  std::error_code ec;
  fs::remove_all(tmp_, ec);
}

veneer::Status SetWriter::add_frame(int k, const cv::Mat& photo, const veneer::io::ImageSet::RawFile& raw, int photos,
                                   const veneer::io::ImageSet::RawFile& developed) {
  if (tmp_.empty()) return make_error("set " + id_ + " is already stored");
  auto fail = [&](const veneer::Status& s) {
    return make_error("storing set " + id_ + " failed: " + s.message() + "; no set stored");
  };
  if (k < 0 || photo.empty()) return make_error("set " + id_ + ": frame " + std::to_string(k) + " is empty");
  if (size_.area() == 0) {
    size_ = photo.size();
    // The space for the whole set, checked before its first file (the trash gives way first).
    // With the camera's files the first frame's bytes tell (half as much
    // again for frames that compress worse); else the PNGs' bound.
    uint64_t need = developed.bytes.empty()
                        ? Store::estimate_bytes(size_, photos, truth_) + raw.bytes.size() * static_cast<uint64_t>(photos)
                        : Store::estimate_bytes(size_, 0, truth_) +
                              (developed.bytes.size() + raw.bytes.size()) * 3 / 2 * static_cast<uint64_t>(photos);
    if (store_.free_bytes() < need) store_.purge_trash(need);
    const uint64_t free = store_.free_bytes();
    if (free < need) {
      return make_error("store " + store_.root().string() + " is full: " + std::to_string(free >> 20) +
                        " MiB free, the set needs about " + std::to_string((need >> 20) + 1) + " MiB; no set stored");
    }
  }
  if (photo.size() != size_) return make_error("set " + id_ + ": frame " + std::to_string(k) + " changed size");
  const int index = k - 1;
  veneer::io::ImageSet::RawFile developed_name;
  if (developed.bytes.empty()) {
    const fs::path png = tmp_ / (k == 0 ? std::string("ambient.png") : light_png(index));
    if (auto s = write_encoded(png, veneer::io::encode_png16(photo)); !s) return fail(s);
  } else {
    const std::string file = k == 0 ? "ambient." + developed.extension : light_png(index).substr(0, 9) + developed.extension;
    if (auto s = store_.write_file(tmp_ / file, developed.bytes); !s) return fail(s);
    developed_name = {developed.extension, "1"};
  }
  veneer::io::ImageSet::RawFile name;
  if (!raw.bytes.empty()) {
    const std::string file = k == 0 ? "ambient." + raw.extension : light_png(index).substr(0, 9) + raw.extension;
    if (auto s = store_.write_file(tmp_ / file, raw.bytes); !s) return fail(s);
    name.extension = raw.extension;
    name.bytes = "1";  // manifest_json names a RAW file where its bytes are not empty
  }
  if (k == 0) {
    ambient_ = true;
    ambient_raw_ = name;
    ambient_developed_ = developed_name;
  } else {
    if (lit_.size() <= static_cast<size_t>(index)) {
      lit_.resize(index + 1, false);
      raw_names_.resize(index + 1);
      developed_names_.resize(index + 1);
    }
    lit_[index] = true;
    raw_names_[index] = name;
    developed_names_[index] = developed_name;
  }
  return {};
}

veneer::Status SetWriter::commit(veneer::io::ImageSet& set) {
  if (tmp_.empty()) return make_error("set " + id_ + " is already stored");
  auto fail = [&](const veneer::Status& s) {
    return make_error("storing set " + id_ + " failed: " + s.message() + "; no set stored");
  };
  if (set.id != id_) return make_error("set " + set.id + " is not the set being written (" + id_ + ")");
  if (set.lights.empty() || lit_.size() != set.lights.size() ||
      std::find(lit_.begin(), lit_.end(), false) != lit_.end())
    return make_error("set " + id_ + ": " + std::to_string(set.lights.size()) +
                      " lights but not every frame was taken; no set stored");
  if (!set.mask.empty()) {
    if (auto s = write_encoded(tmp_ / "mask.png", veneer::io::encode_png8(set.mask)); !s) return fail(s);
  }
  veneer::io::Truth& t = set.truth;
  if (!t.normals.empty() || !t.mask.empty() || !t.albedo.empty() || !t.depth.empty()) {
    // One image at a time, each let go once written (at 5600x3750 they are 0.6 GB together).
    const fs::path truth = tmp_ / "truth";
    std::error_code ec;
    if (!fs::create_directory(truth, ec))
      return fail(make_error(truth.string() + ": cannot create folder: " + ec.message()));
    if (!t.normals.empty()) {
      if (auto s = store_.write_file(truth / "normals.pfm", veneer::io::encode_pfm(t.normals, true)); !s) return fail(s);
    }
    t.normals.release();
    if (!t.mask.empty()) {
      if (auto s = write_encoded(truth / "mask.png", veneer::io::encode_png8(t.mask)); !s) return fail(s);
    }
    t.mask.release();
    if (!t.albedo.empty()) {
      if (auto s = write_encoded(truth / "albedo.png", veneer::io::encode_png16(t.albedo)); !s) return fail(s);
    }
    t.albedo.release();
    if (!t.depth.empty()) {
      if (auto s = store_.write_file(truth / "depth.pfm", veneer::io::encode_pfm(t.depth, true)); !s) return fail(s);
    }
    t.depth.release();
    if (auto s = veneer::io::sync_folder(truth); !s) return fail(s);
  }
  // set.json last, from what was written: manifest_json asks only whether a
  // photo or RAW file is there (images are named after the lights).
  veneer::io::ImageSet named;
  named.id = set.id;
  named.role = set.role;
  named.object = set.object;
  named.created = set.created;
  named.size = size_;
  named.camera = set.camera;
  named.lights = set.lights;
  named.warnings = set.warnings;
  named.scene = set.scene;
  named.mask = set.mask;
  named.raw = raw_names_;
  named.developed = developed_names_;
  if (ambient_) {
    named.ambient = cv::Mat(1, 1, CV_32FC3, cv::Scalar::all(0));  // a marker: ambient.png is written
    named.ambient_raw = ambient_raw_;
    named.ambient_developed = ambient_developed_;
  }
  if (auto s = store_.write_file(tmp_ / "set.json", veneer::io::manifest_json(named)); !s) return fail(s);
  if (auto s = veneer::io::sync_folder(tmp_); !s) return fail(s);
  const fs::path folder = store_.root() / id_;
  if (::renameat2(AT_FDCWD, tmp_.c_str(), AT_FDCWD, folder.c_str(), RENAME_NOREPLACE) != 0) {
    const int err = errno;
    return fail(make_error("cannot rename it into place: " + std::string(std::strerror(err))));
  }
  tmp_.clear();
  if (auto s = veneer::io::sync_folder(store_.root()); !s) return fail(s);
  auto scanned = store_.scan_one(id_);
  if (!scanned) {
    std::error_code ec;
    fs::remove_all(folder, ec);
    return make_error("set " + id_ + " did not read back: " + scanned.message() + "; no set stored");
  }
  std::lock_guard lock(store_.mutex_);
  store_.sets_.push_back(std::move(*scanned));
  return {};
}

namespace {
// <trash>/<id>.deleted holds when the set was deleted (Unix seconds).
std::time_t deleted_at(const fs::path& stamp) {
  std::ifstream in(stamp);
  long long t = 0;
  if (!(in >> t)) return 0;  // unreadable: the oldest, so the first to go
  return static_cast<std::time_t>(t);
}
}  // namespace

veneer::Status Store::remove(const std::string& id) {
  if (auto set = find(id); !set) return set.error();
  const fs::path trash = trash_folder();
  std::error_code ec;
  fs::create_directories(trash, ec);
  if (ec) return make_error("cannot delete set " + id + ": cannot create " + trash.string() + ": " + ec.message());
  // An older deletion of the same id makes way (only the newest is restorable).
  fs::remove_all(trash / id, ec);
  const std::time_t now = veneer::wall_now();
  {
    std::ofstream stamp(trash / (id + ".deleted"));
    stamp << static_cast<long long>(now) << "\n";
    if (!stamp) return make_error("cannot delete set " + id + ": cannot write into " + trash.string());
  }
  // One rename: the set leaves the list at once and nothing is copied.
  if (::rename((root_ / id).c_str(), (trash / id).c_str()) != 0) {
    const int err = errno;
    fs::remove(trash / (id + ".deleted"), ec);
    return make_error("cannot delete set " + id + ": " + std::strerror(err));
  }
  std::lock_guard lock(mutex_);
  sets_.erase(std::remove_if(sets_.begin(), sets_.end(), [&](const StoredSet& s) { return s.id == id; }),
              sets_.end());
  return {};
}

std::vector<StoredSet> Store::trash() const {
  std::vector<std::pair<std::time_t, StoredSet>> found;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(trash_folder(), ec)) {
    const std::string id = entry.path().filename().string();
    if (!entry.is_directory() || !valid_set_id(id)) continue;
    auto text = veneer::io::read_file_bytes(entry.path() / "set.json");
    if (!text) continue;
    auto manifest = veneer::io::parse_manifest(*text, entry.path());
    if (!manifest) continue;
    StoredSet out;
    out.id = id;
    out.role = manifest->set.role;
    out.object = manifest->set.object;
    out.created = manifest->set.created;
    out.scene = manifest->set.scene;
    out.size = manifest->set.size;
    out.lights = static_cast<int>(manifest->set.lights.size());
    out.warnings = manifest->set.warnings;
    out.bytes = folder_bytes(entry.path());
    const std::time_t when = deleted_at(trash_folder() / (id + ".deleted"));
    out.deleted = veneer::utc_time(when);
    found.emplace_back(when, std::move(out));
  }
  std::sort(found.begin(), found.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
  std::vector<StoredSet> out;
  for (auto& f : found) out.push_back(std::move(f.second));
  return out;
}

veneer::Status Store::restore(const std::string& id) {
  if (!valid_set_id(id)) return make_error("'" + id + "' is not a set id");
  const fs::path from = trash_folder() / id;
  std::error_code ec;
  if (!fs::is_directory(from, ec)) return make_error("no set '" + id + "' in the trash");
  if (fs::exists(root_ / id, ec) || find(id)) return make_error("cannot restore " + id + ": a set of that id is stored");
  if (::rename(from.c_str(), (root_ / id).c_str()) != 0)
    return make_error("cannot restore set " + id + ": " + std::strerror(errno));
  fs::remove(trash_folder() / (id + ".deleted"), ec);
  auto scanned = scan_one(id);
  if (!scanned) return make_error("set " + id + " restored but does not read: " + scanned.message());
  std::lock_guard lock(mutex_);
  sets_.push_back(std::move(*scanned));
  std::sort(sets_.begin(), sets_.end(), [](const StoredSet& a, const StoredSet& b) {
    return a.created != b.created ? a.created < b.created : a.id < b.id;
  });
  return {};
}

int Store::purge_trash(uint64_t need_bytes) {
  auto log = veneer::log::get("Store");
  const std::time_t now = veneer::wall_now();
  std::vector<std::pair<std::time_t, std::string>> entries;  // oldest first after the sort
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(trash_folder(), ec)) {
    const std::string id = entry.path().filename().string();
    if (entry.is_directory() && valid_set_id(id))
      entries.emplace_back(deleted_at(trash_folder() / (id + ".deleted")), id);
  }
  std::sort(entries.begin(), entries.end());
  int purged = 0;
  for (const auto& [when, id] : entries) {
    const bool old = static_cast<double>(now - when) > trash_keep_s_;
    if (!old && (need_bytes == 0 || free_bytes() >= need_bytes)) continue;
    fs::remove_all(trash_folder() / id, ec);
    if (ec) {
      log->warn("cannot purge {} from the trash: {}", id, ec.message());
      continue;
    }
    fs::remove(trash_folder() / (id + ".deleted"), ec);
    log->info("purged {} from the trash ({})", id, old ? "kept long enough" : "its space was needed");
    ++purged;
  }
  return purged;
}

}  // namespace veneerd
