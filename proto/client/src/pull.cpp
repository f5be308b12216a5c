// Pulling sets from the rig (client.hpp): whole, or live first -- the
// preview set put in place at once, the full files after, resumably, then
// exchanged with it in one rename.
#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstring>
#include <set>

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include "veneer/io/file_crc.hpp"
#include "veneer/io/image_io.hpp"
#include "veneer/io/imageset.hpp"
#include "veneer/rig/client.hpp"

namespace veneer::rig {

namespace fs = std::filesystem;

namespace {

fs::path target_of(const fs::path& folder) { return folder.has_filename() ? folder : folder.parent_path(); }

fs::path parent_of(const fs::path& target) {
  return target.parent_path().empty() ? fs::path(".") : target.parent_path();
}

void sync_dir(const fs::path& dir) {
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd >= 0) {
    (void)::fsync(fd);
    ::close(fd);
  }
}

// What `folder` holds now, by its set.json.
enum class Holds { nothing, other, preview_of_set, the_set };
Holds what_is_in(const fs::path& folder, const std::string& set_id) {
  std::error_code ec;
  if (!fs::exists(folder, ec)) return Holds::nothing;
  auto text = io::read_file_bytes(folder / "set.json");
  if (!text) return Holds::other;
  auto m = io::parse_manifest(*text, folder);
  if (!m) return Holds::other;
  if (m->set.preview_of) return m->set.preview_of->id == set_id ? Holds::preview_of_set : Holds::other;
  return m->set.id == set_id ? Holds::the_set : Holds::other;
}

// Puts the folder `from` at `to`: a rename when `to` is free, else one
// atomic exchange (a reader of `to` sees the old or the new folder whole),
// the old one then removed.
Status place(const fs::path& from, const fs::path& to) {
  std::error_code ec;
  sync_dir(from);
  if (fs::exists(from / "truth", ec)) sync_dir(from / "truth");
  if (!fs::exists(to, ec)) {
    if (::rename(from.c_str(), to.c_str()) != 0)
      return make_error("cannot move the set to " + to.string() + ": " + std::strerror(errno));
  } else {
    if (::renameat2(AT_FDCWD, from.c_str(), AT_FDCWD, to.c_str(), RENAME_EXCHANGE) != 0)
      return make_error("cannot put the set in place of " + to.string() + ": " + std::strerror(errno));
    fs::remove_all(from, ec);  // now the old folder
  }
  sync_dir(parent_of(to));
  return {};
}

// What an interrupted pull left under `dir`: the files that arrived whole (no
// ".part"), relative, and the starts of those cut mid-way (<rel>.part: its
// size and CRC-32). Empty or unreadable .part files are removed.
struct Held {
  std::vector<std::string> whole;
  std::vector<Client::Partial> partial;
};
Held held_files(const fs::path& dir) {
  Held out;
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(dir, ec); !ec && it != fs::recursive_directory_iterator();
       it.increment(ec)) {
    if (!it->is_regular_file(ec)) continue;
    const fs::path rel = fs::relative(it->path(), dir, ec);
    if (rel.extension() == ".part") {
      std::error_code sec;
      const uint64_t size = fs::file_size(it->path(), sec);
      auto crc = sec || size == 0 ? Expected<uint32_t>(make_error("empty")) : io::file_crc32(it->path(), 0, size);
      if (crc) {
        std::string name = rel.generic_string();
        name.resize(name.size() - 5);  // without ".part"
        out.partial.push_back({name, size, *crc});
      } else {
        fs::remove(it->path(), sec);
      }
    } else if (rel.filename().string().front() != '.') {
      out.whole.push_back(rel.generic_string());
    }
  }
  return out;
}

// Removes the .part files left under `dir` (files the rig no longer sends).
void remove_partial(const fs::path& dir) {
  std::error_code ec;
  std::vector<fs::path> stale;
  for (auto it = fs::recursive_directory_iterator(dir, ec); !ec && it != fs::recursive_directory_iterator();
       it.increment(ec))
    if (it->is_regular_file(ec) && it->path().extension() == ".part") stale.push_back(it->path());
  for (const auto& p : stale) fs::remove(p, ec);
}

// An exclusive lock on a folder for this pull (another process pulling the
// same set into the same place is refused, not interleaved).
class FolderLock {
 public:
  explicit FolderLock(const fs::path& dir) : fd_(::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC)) {
    if (fd_ >= 0 && ::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
      ::close(fd_);
      fd_ = -1;
    }
  }
  ~FolderLock() {
    if (fd_ >= 0) ::close(fd_);
  }
  bool held() const { return fd_ >= 0; }

 private:
  int fd_ = -1;
};

bool unknown_request(const std::string& message) { return message.find("unknown or empty request") != std::string::npos; }

}  // namespace

Status Client::pull(const std::string& set_id, const fs::path& folder, bool include_truth, bool overwrite,
                    const Progress& progress) {
  PullOptions o;
  o.include_truth = include_truth;
  o.overwrite = overwrite;
  return pull_set(set_id, folder, o, progress);
}

Status Client::pull_preview(const std::string& set_id, const fs::path& folder, bool overwrite,
                            const Progress& progress) {
  const fs::path target = target_of(folder);
  const Holds holds = what_is_in(target, set_id);
  if (holds == Holds::the_set || holds == Holds::preview_of_set) {
    progress.report(1.0, "done");
    return {};
  }
  if (holds == Holds::other && !overwrite) return make_error(target.string() + " exists (pull into a new folder)");
  const fs::path parent = parent_of(target);
  std::error_code ec;
  fs::create_directories(parent, ec);
  if (ec) return make_error(parent.string() + ": cannot create: " + ec.message());
  static std::atomic<unsigned> counter{0};
  std::string name = ".";  // built by appending: GCC 12's -Wrestrict misfires on "." + string + ...
  name.append(target.filename().string()).append(".preview-").append(std::to_string(::getpid()));
  name.append("-").append(std::to_string(counter++));
  const fs::path temp = parent / name;
  fs::create_directories(temp, ec);
  if (ec) return make_error(temp.string() + ": cannot create: " + ec.message());
  auto fetched = fetch_into(set_id, true, false, {}, {}, temp, progress);
  Status placed = fetched ? place(temp, target) : Status(fetched.error());
  if (!placed) {
    fs::remove_all(temp, ec);
    return make_error("pull preview of " + set_id + ": " + placed.message());
  }
  progress.report(1.0, "done");
  return {};
}

Status Client::pull_set(const std::string& set_id, const fs::path& folder, const PullOptions& o,
                        const Progress& progress) {
  const fs::path target = target_of(folder);
  Holds holds = what_is_in(target, set_id);
  if (holds == Holds::other && !o.overwrite) return make_error(target.string() + " exists (pull into a new folder)");
  if (holds == Holds::the_set && !o.overwrite) {
    if (o.live_first && o.on_preview) o.on_preview(target);
    progress.report(1.0, "done");
    return {};
  }
  Progress part = progress;  // the preview's share of the bar is small: 5 %
  if (o.live_first && holds != Holds::preview_of_set) {
    part.on_progress = [&progress](double f, const std::string& stage) { progress.report(0.05 * f, stage); };
    Status s = pull_preview(set_id, target, o.overwrite, part);
    if (s) {
      holds = Holds::preview_of_set;
      if (o.on_preview) o.on_preview(target);
    } else if (!unknown_request(s.message())) {
      return s;
    }
  } else if (o.live_first && o.on_preview) {
    o.on_preview(target);  // its preview is already there
  }

  // The full files, resumably, in a staging folder named after the set.
  const fs::path parent = parent_of(target);
  std::error_code ec;
  fs::create_directories(parent, ec);
  std::string name = ".";
  name.append(target.filename().string()).append(".pull-").append(set_id);
  const fs::path staging = parent / name;
  fs::create_directories(staging, ec);
  if (ec) return make_error(staging.string() + ": cannot create: " + ec.message());
  FolderLock lock(staging);
  if (!lock.held()) return make_error("pull " + set_id + ": another pull into " + target.string() + " is running");
  Held held = held_files(staging);
  std::vector<std::string>& have = held.whole;
  have.erase(std::remove(have.begin(), have.end(), "set.json"), have.end());
  held.partial.erase(std::remove_if(held.partial.begin(), held.partial.end(),
                                    [](const Client::Partial& p) { return p.file == "set.json"; }),
                     held.partial.end());
  if (!have.empty() || !held.partial.empty()) {
    progress.report(o.live_first ? 0.05 : 0.0, "resuming: " + std::to_string(have.size()) + " files and the start of " +
                                                   std::to_string(held.partial.size()) + " already here");
  }
  part.on_progress = [&progress, &o](double f, const std::string& stage) {
    progress.report(o.live_first ? 0.05 + 0.95 * f : f, stage);
  };
  auto fetched = fetch_into(set_id, false, o.include_truth, have, held.partial, staging, part);
  if (!fetched) {
    // What arrived whole stays for the next pull of this set into this folder.
    if (fetched.message().find("no set '") != std::string::npos || fetched.message() == "cancelled") fs::remove_all(staging, ec);
    return make_error("pull " + set_id + ": " + fetched.message());
  }
  remove_partial(staging);  // starts of files the rig did not send again
  // Every file the rig listed is here, and so is everything set.json names.
  for (const auto& f : fetched->skipped) {
    if (!fs::is_regular_file(staging / f, ec)) return make_error("pull " + set_id + ": " + f + " is missing");
  }
  auto text = io::read_file_bytes(staging / "set.json");
  if (!text) return make_error("pull " + set_id + ": " + text.message());
  auto manifest = io::parse_manifest(*text, staging);
  if (!manifest) return make_error("pull " + set_id + ": " + manifest.message());
  std::vector<fs::path> named = manifest->image_files;
  named.insert(named.end(), manifest->raw_files.begin(), manifest->raw_files.end());
  for (const auto& f : {manifest->ambient_file, manifest->ambient_raw_file, manifest->mask_file}) named.push_back(f);
  for (const auto& f : named) {
    if (!f.empty() && !fs::is_regular_file(staging / f, ec))
      return make_error("pull " + set_id + ": " + f.string() + " named in set.json did not arrive");
  }
  if (Status s = place(staging, target); !s) return make_error("pull " + set_id + ": " + s.message());
  progress.report(1.0, "done");
  return {};
}

}  // namespace veneer::rig
