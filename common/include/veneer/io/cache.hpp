#pragma once
// A per-set cache of results on disk (normals, albedo, mask, confidence, the
// photos as the matcher uses them), so a second run over the same set reads a
// few files instead of decoding every frame. Entries live under
// $XDG_CACHE_HOME/veneer (default ~/.cache/veneer), one folder per key, written
// to a temporary folder and renamed into place (a crash leaves no half entry);
// the least recently used entries are evicted beyond a size cap.
#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <optional>
#include <string>

#include <opencv2/core.hpp>

#include "veneer/util/expected.hpp"

namespace veneer::io {

struct CacheOptions {
  bool enabled = true;               // false: never read or write the cache
  std::filesystem::path dir;         // empty = default_cache_dir()
  uint64_t max_bytes = 4ull << 30;   // size cap over all entries [bytes], default 4 GiB; LRU eviction
  Status check() const;
};

// $XDG_CACHE_HOME/veneer, else $HOME/.cache/veneer, else <temp>/veneer-cache.
std::filesystem::path default_cache_dir();

// A set folder's checksum (hex): set.json's bytes (or DiLiGenT/thesis lists)
// and, for every file in the folder and truth/, its name, size and
// modification time (ns), plus `salt` (how results are made from it). Sets
// are written once, atomically, so this identifies their contents without
// reading the frames.
Expected<std::string> set_checksum(const std::filesystem::path& folder, const std::string& salt);

// One cache entry: named blobs.
using CacheEntry = std::map<std::string, std::string>;
// Named matrices stored beside the blobs, each straight from its Mat to its
// file (write_mat_file): a full-resolution photo is hundreds of MB, so no blob
// is made of it. `half` stores a CV_32F matrix as half floats.
struct CachedMat {
  cv::Mat mat;
  bool half = false;
};
using CacheMats = std::map<std::string, CachedMat>;

class ResultCache {
 public:
  explicit ResultCache(CacheOptions options);
  const std::filesystem::path& dir() const { return dir_; }
  // The entry stored under `key`, or nullopt (miss, disabled, or damaged: a
  // damaged entry is removed). A hit marks the entry as recently used.
  // With `mats`, the entry's matrix files are read into it (in parallel,
  // CV_32F where stored as half floats, but those whose file name
  // `keep_half` takes, which stay CV_16F as stored: issue 48) instead of into the blobs.
  std::optional<CacheEntry> load(const std::string& key, std::map<std::string, cv::Mat>* mats = nullptr,
                                 const std::function<bool(const std::string&)>& keep_half = {}) const;
  // Stores `entry` and `mats` under `key` (temp folder + rename, no fsync: a
  // lost entry is recomputed), then evicts least recently used entries until
  // the cache is within max_bytes.
  Status store(const std::string& key, const CacheEntry& entry, const CacheMats& mats = {}) const;
  // store() in steps, for a write that several threads share: begin_store
  // makes the entry's temporary folder (empty path when the cache is off),
  // the matrices go into it with write_mat_file(folder / name, ...), any
  // thread each, and commit_store writes the blobs and renames the folder
  // into place (or removes it when `failed`), then evicts.
  Expected<std::filesystem::path> begin_store(const std::string& key) const;
  Status commit_store(const std::string& key, const std::filesystem::path& folder, const CacheEntry& entry,
                      bool failed = false) const;
  uint64_t size_bytes() const;

 private:
  void evict() const;
  CacheOptions options_;
  std::filesystem::path dir_;
};

// Matrices as cache blobs: a 16-byte header (rows, cols, type) + pixels.
// CV_32F images may be stored as half floats (`half`) to halve the bytes.
std::string encode_mat(const cv::Mat& m, bool half = false);
Expected<cv::Mat> decode_mat(const std::string& blob, const std::string& name);
// The same format straight between a Mat and a file, through a small buffer
// (no copy of the whole matrix); half floats come back as CV_32F, or as
// stored with `keep_half`.
Status write_mat_file(const std::filesystem::path& file, const cv::Mat& m, bool half = false);
Expected<cv::Mat> read_mat_file(const std::filesystem::path& file, bool keep_half = false);

}  // namespace veneer::io
