#pragma once
// The set store: one veneer-set/1 folder per captured set under a root folder.
// Sets are written with veneer::write_set, or frame by frame as the camera
// delivers them (SetWriter), both into a temporary folder that is fsynced and
// renamed into place, so after a crash or power cut a set is either all there
// or not at all; opening the store removes leftover temporary folders and
// lists what is stored.
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <mutex>
#include <string>
#include <string_view>
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/io/imageset.hpp"
#include "veneer/util/expected.hpp"

namespace veneerd {

struct StoredSet {
  std::string id;
  veneer::io::Role role = veneer::io::Role::unknown;
  std::string object;
  std::string created;
  std::string scene;
  cv::Size size;
  int lights = 0;
  std::vector<std::string> warnings;
  bool has_truth = false;
  uint64_t bytes = 0;
  std::string deleted;  // sets in the trash: when it was deleted (UTC, ISO 8601)
};

// A fault a file write of a set takes (the simulated rig's fault plan, tests).
struct WriteFault {
  int error = 0;                       // errno the write fails with, after half the file is written; 0 = none
  std::chrono::milliseconds delay{0};  // the write takes this much longer (a slow card)
};

// Set ids are file names: 1..96 of [A-Za-z0-9._-], not starting with '.'.
bool valid_set_id(const std::string& id);

class SetWriter;

class Store {
 public:
  // Opens (creating if needed) the store folder, takes its lock (one daemon
  // per store), removes leftover temporary folders and scans the sets.
  static veneer::Expected<std::unique_ptr<Store>> open(const std::filesystem::path& root);
  ~Store();

  const std::filesystem::path& root() const { return root_; }
  std::vector<StoredSet> list() const;  // oldest first
  veneer::Expected<StoredSet> find(const std::string& id) const;
  veneer::Expected<std::string> manifest(const std::string& id) const;  // set.json text
  // Relative paths of the set's files: set.json, the photos, and truth/* when asked.
  veneer::Expected<std::vector<std::string>> files(const std::string& id, bool include_truth) const;
  std::filesystem::path folder(const std::string& id) const { return root_ / id; }

  // A fresh id for a new set, e.g. "20261122-081530-destination-bull".
  std::string new_id(veneer::io::Role role, const std::string& object) const;
  // Bytes a set of this size will take (16-bit PNGs, upper bound) and the free space.
  static uint64_t estimate_bytes(cv::Size size, int photos, bool truth);
  uint64_t free_bytes() const;

  // Stores the set under set.id. Fails with a clear error (disk full, ...)
  // and leaves nothing behind.
  veneer::Status save(const veneer::io::ImageSet& set);

  // Starts writing set `id` frame by frame (a capture at the camera's full
  // resolution holds one frame at a time, not the whole set): see SetWriter.
  // `truth`: the set will have ground truth (the simulated rig), counted in
  // the free space it needs.
  veneer::Expected<std::unique_ptr<SetWriter>> begin(const std::string& id, bool truth = false);

  // The trash: a deleted set is moved into <root>/.trash and can be restored
  // until it is purged -- when it is older than trash_keep_s, or, oldest
  // first, when a new set needs its space.
  veneer::Status remove(const std::string& id);  // into the trash
  std::vector<StoredSet> trash() const;          // newest deletion first
  veneer::Status restore(const std::string& id);
  // Removes for good what is older than trash_keep_s and, oldest first, what
  // must go to leave `need_bytes` free; returns how many sets went.
  int purge_trash(uint64_t need_bytes = 0);
  void set_trash_keep(double seconds) { trash_keep_s_ = seconds; }
  std::filesystem::path trash_folder() const { return root_ / ".trash"; }

  // Faults for the files of the sets being written (SetWriter): `hook` is
  // asked before each file is written. Set before the first capture; empty = none.
  void set_write_faults(std::function<WriteFault(const std::filesystem::path& file)> hook) {
    write_faults_ = std::move(hook);
  }

 private:
  // A file of a set being written (fsynced), through the write faults.
  veneer::Status write_file(const std::filesystem::path& file, std::string_view bytes) const;
  std::function<WriteFault(const std::filesystem::path&)> write_faults_;
  friend class SetWriter;
  explicit Store(std::filesystem::path root, int lock_fd);
  veneer::Expected<StoredSet> scan_one(const std::string& id) const;

  std::filesystem::path root_;
  int lock_fd_ = -1;
  mutable std::mutex mutex_;
  std::vector<StoredSet> sets_;
  double trash_keep_s_ = 7 * 24 * 3600.0;  // a week
};

// One set being written into a temporary folder of the store as its frames
// are taken; commit() adds the manifest (and truth) and renames it into place.
// The files are byte for byte those Store::save writes for the same set.
// Dropped without commit (a failed or cancelled capture), it leaves nothing.
class SetWriter {
 public:
  ~SetWriter();
  SetWriter(const SetWriter&) = delete;
  SetWriter& operator=(const SetWriter&) = delete;

  // Frame k of the capture: k = 0 the ambient frame, k >= 1 lit by light k - 1.
  // `photo` is CV_32FC3 as in veneer::ImageSet; `raw` the camera's RAW file
  // (empty bytes = none); `developed` the camera's JPEG of the photo, stored
  // as light_NN.jpg instead of a 16-bit PNG of `photo` (empty = the PNG).
  // Written (and fsynced) before this returns; the first frame checks the
  // free space for the whole set (`photos` frames).
  veneer::Status add_frame(int k, const cv::Mat& photo, const veneer::io::ImageSet::RawFile& raw, int photos,
                           const veneer::io::ImageSet::RawFile& developed = {});
  // Writes the supplied mask, the truth (releasing each of its images once
  // written) and set.json for `set` (metadata and lights; its photos may be
  // empty: the frames added are what set.json names), then renames the folder
  // into place and lists the set. Every light needs its frame.
  veneer::Status commit(veneer::io::ImageSet& set);

 private:
  friend class Store;
  SetWriter(Store& store, std::string id, std::filesystem::path tmp, bool truth)
      : store_(store), id_(std::move(id)), tmp_(std::move(tmp)), truth_(truth) {}
  veneer::Status write_encoded(const std::filesystem::path& file, const veneer::Expected<std::string>& bytes);
  Store& store_;
  std::string id_;
  std::filesystem::path tmp_;  // removed by the destructor unless committed
  bool truth_ = false;
  cv::Size size_;
  bool ambient_ = false;
  std::vector<bool> lit_;                          // lit_[i]: light i's frame is written
  std::vector<veneer::io::ImageSet::RawFile> raw_names_;  // extension only (bytes "1" when a RAW file was written)
  veneer::io::ImageSet::RawFile ambient_raw_;
  std::vector<veneer::io::ImageSet::RawFile> developed_names_;  // the same for the camera's JPEGs
  veneer::io::ImageSet::RawFile ambient_developed_;
};

}  // namespace veneerd
