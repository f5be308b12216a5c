// The per-set result cache (cache.hpp).
#include "veneer/io/cache.hpp"

#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <vector>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <tbb/parallel_for.h>

#include "file_util.hpp"
#include "veneer/io/big_buffers.hpp"
#include "veneer/io/image_io.hpp"
#include "veneer/util/log.hpp"

namespace veneer::io {
namespace fs = std::filesystem;

namespace {

constexpr uint32_t kMatMagic = 0x3154414d;  // "MAT1"

// 64-bit FNV-1a: enough to tell sets apart, not a defence against anyone.
struct Hash {
  uint64_t h = 1469598103934665603ull;
  void add(const void* data, size_t n) {
    const auto* p = static_cast<const unsigned char*>(data);
    for (size_t i = 0; i < n; ++i) h = (h ^ p[i]) * 1099511628211ull;
  }
  void add(const std::string& s) {
    add(s.data(), s.size());
    add("\0", 1);
  }
  template <class T>
  void add_value(T v) {
    add(&v, sizeof v);
  }
};

std::string hex(uint64_t v) {
  char buf[17];
  std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(v));
  return buf;
}

bool safe_key(const std::string& key) {
  return !key.empty() && key.size() <= 64 &&
         std::all_of(key.begin(), key.end(), [](unsigned char c) { return std::isalnum(c) || c == '-' || c == '_'; });
}

uint64_t folder_bytes(const fs::path& dir) {
  uint64_t total = 0;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    if (e.is_regular_file(ec)) total += e.file_size(ec);
  }
  return total;
}

struct Fd {
  int fd = -1;
  ~Fd() {
    if (fd >= 0) ::close(fd);
  }
};

// All n bytes at p through `io` (::read or ::write), again after EINTR;
// false on an error or at the end of the file.
template <class Byte, class Io>
bool all_bytes(Io io, int fd, Byte* p, size_t n) {
  while (n > 0) {
    const ssize_t done = io(fd, p, n);
    if (done < 0 && errno == EINTR) continue;
    if (done <= 0) return false;
    p += done;
    n -= static_cast<size_t>(done);
  }
  return true;
}

bool write_all(int fd, const void* data, size_t n) { return all_bytes(::write, fd, static_cast<const char*>(data), n); }
bool read_all(int fd, void* data, size_t n) { return all_bytes(::read, fd, static_cast<char*>(data), n); }

// A file that starts with the matrix header's magic.
bool is_mat_file(const fs::path& file) {
  Fd f{::open(file.c_str(), O_RDONLY | O_CLOEXEC)};
  uint32_t magic = 0;
  return f.fd >= 0 && read_all(f.fd, &magic, sizeof magic) && magic == kMatMagic;
}

// Rows per chunk so that a chunk is about 8 MiB.
int chunk_rows(const cv::Mat& m) { return std::max(1, static_cast<int>((8u << 20) / std::max<size_t>(1, m.step[0]))); }

}  // namespace

Status CacheOptions::check() const {
  if (max_bytes < (1u << 20)) return make_error("cache size cap must be at least 1 MiB");
  return Status::success();
}

fs::path default_cache_dir() {
  if (const char* xdg = std::getenv("XDG_CACHE_HOME"); xdg && *xdg == '/') return fs::path(xdg) / "veneer";
  if (const char* home = std::getenv("HOME"); home && *home) return fs::path(home) / ".cache" / "veneer";
  return fs::temp_directory_path() / "veneer-cache";
}

Expected<std::string> set_checksum(const fs::path& folder, const std::string& salt) {
  std::error_code ec;
  if (!fs::is_directory(folder, ec)) return make_error(folder.string() + ": not a folder");
  Hash h;
  h.add(salt);
  for (const char* list : {"set.json", "filenames.txt", "lights.txt", "light_directions.txt", "light_intensities.txt"}) {
    const fs::path f = folder / list;
    if (!fs::is_regular_file(f, ec)) continue;
    auto bytes = read_file_bytes(f);
    if (!bytes) return bytes.error();
    h.add(list);
    h.add(*bytes);
  }
  // Every file's name, size and modification time, in name order.
  std::vector<std::pair<std::string, fs::path>> files;
  for (const fs::path& dir : {folder, folder / "truth"}) {
    for (const auto& e : fs::directory_iterator(dir, ec)) {
      if (e.is_regular_file(ec)) files.emplace_back(fs::relative(e.path(), folder, ec).generic_string(), e.path());
    }
    ec.clear();
  }
  std::sort(files.begin(), files.end());
  for (const auto& [name, path] : files) {
    struct stat st {};
    if (::stat(path.c_str(), &st) != 0) return make_error(path.string() + ": cannot stat");
    h.add(name);
    h.add_value(static_cast<int64_t>(st.st_size));
    h.add_value(static_cast<int64_t>(st.st_mtim.tv_sec));
    h.add_value(static_cast<int64_t>(st.st_mtim.tv_nsec));
  }
  return hex(h.h);
}

ResultCache::ResultCache(CacheOptions options) : options_(std::move(options)) {
  dir_ = options_.dir.empty() ? default_cache_dir() : options_.dir;
}

std::optional<CacheEntry> ResultCache::load(const std::string& key, std::map<std::string, cv::Mat>* mats,
                                            const std::function<bool(const std::string&)>& keep_half) const {
  if (!options_.enabled || !safe_key(key)) return std::nullopt;
  const fs::path entry_dir = dir_ / key;
  std::error_code ec;
  if (!fs::is_directory(entry_dir, ec)) return std::nullopt;
  CacheEntry entry;
  std::vector<fs::path> matrix_files;
  for (const auto& e : fs::directory_iterator(entry_dir, ec)) {
    if (!e.is_regular_file(ec)) continue;
    if (mats && is_mat_file(e.path())) {
      matrix_files.push_back(e.path());
      continue;
    }
    auto bytes = read_file_bytes(e.path());
    if (!bytes) {
      VLOG_WARN("Cache", "{}: unreadable, dropping the entry", e.path().string());
      fs::remove_all(entry_dir, ec);
      return std::nullopt;
    }
    entry.emplace(e.path().filename().string(), std::move(bytes).value());
  }
  if (mats) {
    std::vector<Expected<cv::Mat>> read(matrix_files.size(), make_error("not read"));
    tbb::parallel_for(size_t(0), matrix_files.size(), [&](size_t i) {
      read[i] = read_mat_file(matrix_files[i], keep_half && keep_half(matrix_files[i].filename().string()));
    });
    for (size_t i = 0; i < read.size(); ++i) {
      if (!read[i]) {
        VLOG_WARN("Cache", "{}, dropping the entry", read[i].message());
        fs::remove_all(entry_dir, ec);
        return std::nullopt;
      }
      (*mats)[matrix_files[i].filename().string()] = std::move(read[i]).value();
    }
  }
  // Recently used: the folder's time is the LRU clock.
  fs::last_write_time(entry_dir, fs::file_time_type::clock::now(), ec);
  return entry;
}

Expected<fs::path> ResultCache::begin_store(const std::string& key) const {
  if (!options_.enabled) return fs::path();
  if (!safe_key(key)) return make_error("cache: bad key \"" + key.substr(0, 80) + "\"");
  std::error_code ec;
  fs::create_directories(dir_, ec);
  if (ec) return make_error(dir_.string() + ": cannot create cache folder: " + ec.message());
  const fs::path tmp = detail::temp_sibling(dir_ / key);
  if (!fs::create_directory(tmp, ec)) return make_error(tmp.string() + ": cannot create: " + ec.message());
  return tmp;
}

Status ResultCache::commit_store(const std::string& key, const fs::path& tmp, const CacheEntry& entry,
                                 bool failed) const {
  if (tmp.empty()) return Status::success();
  std::error_code ec;
  if (failed || !safe_key(key)) {
    fs::remove_all(tmp, ec);
    return failed ? Status::success() : make_error("cache: bad key \"" + key.substr(0, 80) + "\"");
  }
  for (const auto& [name, bytes] : entry) {
    if (name.find('/') != std::string::npos || name.empty() || name[0] == '.') {
      fs::remove_all(tmp, ec);
      return make_error("cache: bad blob name \"" + name + "\"");
    }
    // No fsync: a cache entry lost to a power cut is recomputed; sizes are
    // checked when read (decode_mat).
    const std::string file = (tmp / name).string();
    FILE* f = std::fopen(file.c_str(), "wb");
    const bool ok = f && std::fwrite(bytes.data(), 1, bytes.size(), f) == bytes.size();
    if (f) std::fclose(f);
    if (!ok) {
      fs::remove_all(tmp, ec);
      return make_error(file + ": cannot write cache file");
    }
  }
  const fs::path target = dir_ / key;
  fs::remove_all(target, ec);  // an older entry under the same key
  if (std::rename(tmp.c_str(), target.c_str()) != 0) {
    fs::remove_all(tmp, ec);
    return make_error(target.string() + ": cannot rename cache entry into place");
  }
  evict();
  return Status::success();
}

Status ResultCache::store(const std::string& key, const CacheEntry& entry, const CacheMats& mats) const {
  if (!options_.enabled) return Status::success();
  auto tmp = begin_store(key);
  if (!tmp) return tmp.error();
  for (const auto& [name, m] : mats) {
    if (name.find('/') != std::string::npos || name.empty() || name[0] == '.' || entry.count(name)) {
      (void)commit_store(key, *tmp, entry, true);
      return make_error("cache: bad matrix name \"" + name + "\"");
    }
    if (Status s = write_mat_file(*tmp / name, m.mat, m.half); !s) {
      (void)commit_store(key, *tmp, entry, true);
      return s;
    }
  }
  return commit_store(key, *tmp, entry);
}

uint64_t ResultCache::size_bytes() const {
  uint64_t total = 0;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(dir_, ec)) {
    if (e.is_directory(ec)) total += folder_bytes(e.path());
  }
  return total;
}

void ResultCache::evict() const {
  struct Item {
    fs::path path;
    fs::file_time_type used;
    uint64_t bytes;
  };
  std::vector<Item> items;
  uint64_t total = 0;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(dir_, ec)) {
    if (!e.is_directory(ec)) continue;
    const std::string name = e.path().filename().string();
    if (!name.empty() && name[0] == '.') continue;  // another writer's entry in the making
    Item it{e.path(), fs::last_write_time(e.path(), ec), folder_bytes(e.path())};
    total += it.bytes;
    items.push_back(it);
  }
  if (total <= options_.max_bytes) return;
  std::sort(items.begin(), items.end(), [](const Item& a, const Item& b) { return a.used < b.used; });
  for (const Item& it : items) {
    if (total <= options_.max_bytes) break;
    fs::remove_all(it.path, ec);
    total -= it.bytes;
    VLOG_INFO("Cache", "evicted {} ({} MB)", it.path.string(), it.bytes >> 20);
  }
}

std::string encode_mat(const cv::Mat& m_in, bool half) {
  cv::Mat m = m_in.isContinuous() ? m_in : m_in.clone();
  if (half && m.depth() == CV_32F) m.convertTo(m, CV_MAKETYPE(CV_16F, m.channels()));
  const uint32_t head[4] = {kMatMagic, static_cast<uint32_t>(m.rows), static_cast<uint32_t>(m.cols),
                            static_cast<uint32_t>(m.type())};
  std::string out(sizeof head + m.total() * m.elemSize(), '\0');
  std::memcpy(out.data(), head, sizeof head);
  if (!m.empty()) std::memcpy(out.data() + sizeof head, m.data, m.total() * m.elemSize());
  return out;
}

Expected<cv::Mat> decode_mat(const std::string& blob, const std::string& name) {
  uint32_t head[4];
  if (blob.size() < sizeof head) return make_error(name + ": truncated");
  std::memcpy(head, blob.data(), sizeof head);
  if (head[0] != kMatMagic || head[1] > (1u << 16) || head[2] > (1u << 16)) return make_error(name + ": not a cached matrix");
  const int type = static_cast<int>(head[3]);
  const int depth = CV_MAT_DEPTH(type);
  if (depth != CV_8U && depth != CV_16F && depth != CV_32F && depth != CV_32S) return make_error(name + ": bad type");
  cv::Mat m(static_cast<int>(head[1]), static_cast<int>(head[2]), type);
  if (blob.size() != sizeof head + m.total() * m.elemSize()) return make_error(name + ": size does not match its header");
  if (!m.empty()) std::memcpy(m.data, blob.data() + sizeof head, m.total() * m.elemSize());
  if (depth == CV_16F) m.convertTo(m, CV_MAKETYPE(CV_32F, m.channels()));
  return m;
}

}  // namespace veneer::io

namespace veneer::io {

Status write_mat_file(const fs::path& file, const cv::Mat& m, bool half) {
  const bool to_half = half && m.depth() == CV_32F;
  const int type = to_half ? CV_MAKETYPE(CV_16F, m.channels()) : m.type();
  const uint32_t head[4] = {kMatMagic, static_cast<uint32_t>(m.rows), static_cast<uint32_t>(m.cols),
                            static_cast<uint32_t>(type)};
  Fd f{::open(file.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644)};
  if (f.fd < 0) return make_error(file.string() + ": cannot create cache file: " + std::strerror(errno));
  bool ok = write_all(f.fd, head, sizeof head);
  const int step = chunk_rows(m);
  cv::Mat buffer;
  for (int y = 0; ok && y < m.rows; y += step) {
    cv::Mat rows = m.rowRange(y, std::min(m.rows, y + step));
    if (to_half || !rows.isContinuous()) {
      rows.convertTo(buffer, type);
      rows = buffer;
    }
    ok = write_all(f.fd, rows.data, rows.total() * rows.elemSize());
  }
  if (!ok) return make_error(file.string() + ": cannot write cache file: " + std::strerror(errno));
  return Status::success();
}

Expected<cv::Mat> read_mat_file(const fs::path& file, bool keep_half) {
  const std::string name = file.string();
  Fd f{::open(file.c_str(), O_RDONLY | O_CLOEXEC)};
  if (f.fd < 0) return make_error(name + ": cannot open: " + std::strerror(errno));
  uint32_t head[4];
  if (!read_all(f.fd, head, sizeof head)) return make_error(name + ": truncated");
  if (head[0] != kMatMagic || head[1] > (1u << 16) || head[2] > (1u << 16)) return make_error(name + ": not a cached matrix");
  const int type = static_cast<int>(head[3]);
  const int depth = CV_MAT_DEPTH(type), channels = CV_MAT_CN(type);
  if ((depth != CV_8U && depth != CV_16F && depth != CV_32F && depth != CV_32S) || channels > 4)
    return make_error(name + ": bad type");
  struct stat st {};
  const size_t pixels = size_t(head[1]) * head[2] * CV_ELEM_SIZE(type);
  if (::fstat(f.fd, &st) != 0 || static_cast<size_t>(st.st_size) != sizeof head + pixels)
    return make_error(name + ": size does not match its header");
  const int rows = static_cast<int>(head[1]), cols = static_cast<int>(head[2]);
  if (depth != CV_16F || keep_half) {
    cv::Mat m = big_mat(rows, cols, type);
    if (!m.empty() && !read_all(f.fd, m.data, pixels)) return make_error(name + ": truncated");
    return m;
  }
  // Half floats: read a chunk, widen it into its rows of the result.
  cv::Mat m = big_mat(rows, cols, CV_MAKETYPE(CV_32F, channels));
  const int step = std::max(1, static_cast<int>((8u << 20) / std::max<size_t>(1, size_t(cols) * CV_ELEM_SIZE(type))));
  cv::Mat chunk(std::min(rows, step), cols, type);
  for (int y = 0; y < rows; y += step) {
    const int n = std::min(rows - y, step);
    cv::Mat part = chunk.rowRange(0, n);
    if (!read_all(f.fd, part.data, part.total() * part.elemSize())) return make_error(name + ": truncated");
    cv::Mat out = m.rowRange(y, y + n);
    part.convertTo(out, out.type());
  }
  return m;
}

}  // namespace veneer::io
