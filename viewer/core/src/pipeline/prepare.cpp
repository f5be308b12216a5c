// Set folders -> prepared objects through the result cache (prepare.hpp).
#include "veneer/pipeline/prepare.hpp"

#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <functional>

#include <future>
#include <map>
#include <mutex>
#include <optional>
#include <vector>

#include <nlohmann/json.hpp>

#include <opencv2/core/hal/hal.hpp>
#include <opencv2/imgproc.hpp>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>

#include "veneer/io/big_buffers.hpp"
#include "veneer/ps/photometric_stereo.hpp"
#include "veneer/ps/segmentation.hpp"
#include "veneer/repaint/repaint.hpp"
#include "veneer/util/log.hpp"

namespace veneer::pipeline {
namespace fs = std::filesystem;

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// Bump when what is cached, or how it is computed, changes.
constexpr const char* kCacheVersion = "prepared-set/3";

Progress sub_progress(const Progress& p, double from, double to) { return p.part(from, to); }

// A digest of a hand-drawn mask as the pipeline applies it (object = above
// 127): FNV-1a over its size and its object bits, row by row.
std::string mask_digest(const cv::Mat& mask) {
  uint64_t h = 1469598103934665603ull;
  auto add = [&h](uint64_t byte) {
    h ^= byte;
    h *= 1099511628211ull;
  };
  for (int v : {mask.cols, mask.rows})
    for (int b = 0; b < 4; ++b) add((static_cast<uint32_t>(v) >> (8 * b)) & 0xff);
  for (int y = 0; y < mask.rows; ++y) {
    const uchar* row = mask.ptr<uchar>(y);
    for (int x = 0; x < mask.cols; x += 8) {
      uint64_t bits = 0;
      for (int k = 0; k < 8 && x + k < mask.cols; ++k) bits |= uint64_t(row[x + k] > 127) << k;
      add(bits);
    }
  }
  char hex[17];
  std::snprintf(hex, sizeof hex, "%016llx", static_cast<unsigned long long>(h));
  return hex;
}

std::string salt_of(const io::ReadOptions& read, double scale, bool truth_normals, const cv::Mat& mask) {
  // frames decoded to half floats give normals a little apart from float frames' (measured in
  // tests/core/pipeline/test_camera_space.cpp): keyed apart; float frames keep the key they always had
  nlohmann::json j{{"mask", mask.empty() ? std::string("segmented") : mask_digest(mask)},
                   {"version", kCacheVersion},
                   {"photos", io::photo_source_name(read.photos)},
                   {"half_size", read.raw.half_size},
                   {"demosaic", io::demosaic_name(read.raw.demosaic)},
                   {"normals_from", "camera space"},  // RAW (issue 42)
                   {"scale", scale},
                   {"truth_normals", truth_normals},
                   {"libraw", io::raw_decoder_version()}};
  if (read.half_floats) j["frames"] = "half floats";
  return j.dump();
}

// What a set's cache entry holds: a small meta.json, and the matrices
// written straight from the Mats (photos and float pictures as half floats).
std::pair<io::CacheEntry, io::CacheMats> to_entry(const PreparedSet& p) {
  io::CacheEntry e;
  io::CacheMats mats;
  const auto& v = p.object.view;
  nlohmann::json meta{{"photos_from", p.set.photos_from},
                      {"images", v.images.size()},
                      {"segment_s", p.object.segment_seconds},
                      {"normals_s", p.object.normals_seconds}};
  e["meta.json"] = meta.dump();
  mats["normals"] = {v.normals, false};
  mats["mask"] = {v.mask, false};
  if (!p.albedo.empty()) mats["albedo"] = {p.albedo, true};
  if (!p.residual.empty()) mats["confidence"] = {p.residual, true};
  mats["median"] = {p.median, true};
  for (size_t i = 0; i < v.images.size(); ++i) mats["photo_" + std::to_string(i)] = {v.images[i], true};
  return {std::move(e), std::move(mats)};
}

// Fills `p` from a cache entry; false when the entry does not fit the set.
bool from_entry(const io::CacheEntry& e, std::map<std::string, cv::Mat>& mats, PreparedSet& p) {
  auto get = [&](const std::string& name) -> cv::Mat {
    auto it = mats.find(name);
    return it == mats.end() ? cv::Mat() : it->second;
  };
  auto meta_it = e.find("meta.json");
  if (meta_it == e.end()) return false;
  const auto meta = nlohmann::json::parse(meta_it->second, nullptr, false);
  if (meta.is_discarded() || !meta.contains("images") || !meta["images"].is_number_unsigned()) return false;
  const size_t n = meta["images"].get<size_t>();
  if (n != p.set.lights.size()) return false;
  auto& v = p.object.view;
  v.normals = get("normals");
  v.mask = get("mask");
  p.albedo = get("albedo");
  p.residual = get("confidence");
  p.median = get("median");
  v.images.assign(n, cv::Mat());
  for (size_t i = 0; i < n; ++i) v.images[i] = get("photo_" + std::to_string(i));
  const cv::Size size = v.normals.size();
  if (v.normals.type() != CV_32FC3 || v.mask.type() != CV_8UC1 || v.mask.size() != size || p.median.size() != size)
    return false;
  for (const auto& im : v.images) {
    if ((im.type() != CV_32FC3 && im.type() != CV_16FC3) || im.size() != size) return false;  // half: kept as stored
  }
  if (p.median.type() != CV_32FC3 && p.median.type() != CV_16FC3) return false;
  p.set.photos_from = meta.value("photos_from", std::string());
  p.object.segment_seconds = meta.value("segment_s", 0.0);
  p.object.normals_seconds = meta.value("normals_s", 0.0);
  return true;
}

// A cache entry being written: its matrices are taken one at a time by the
// background writer (at nice 19, so that on a small machine the map keeps
// both cores) and by whoever waits for the entry (at its own priority), so
// that waiting is never waiting on a starved thread for more than the one
// matrix it holds. Whoever writes the last matrix commits the entry.
struct WriteJob {
  io::ResultCache cache;
  std::string key, id;
  io::CacheEntry entry;
  std::vector<std::pair<std::string, io::CachedMat>> mats;
  fs::path folder;
  std::atomic<size_t> next{0}, done{0};
  std::mutex lock;
  Status error = Status::success();
  std::promise<Status> finished;
  std::shared_future<Status> result = finished.get_future().share();
  Clock::time_point t0 = Clock::now();

  WriteJob(io::ResultCache c, std::string k, std::string i) : cache(std::move(c)), key(std::move(k)), id(std::move(i)) {}

  void help() {
    for (size_t i; (i = next++) < mats.size();) {
      Status s = io::write_mat_file(folder / mats[i].first, mats[i].second.mat, mats[i].second.half);
      mats[i].second.mat.release();  // a photo the caller lets go of is freed
      if (!s) {
        std::lock_guard<std::mutex> hold(lock);
        if (error) error = s;
      }
      if (++done == mats.size()) commit();
    }
  }
  void commit() {
    Status s = Status::success();
    {
      std::lock_guard<std::mutex> hold(lock);
      s = error;
    }
    Status c = cache.commit_store(key, folder, entry, !s);
    if (s) s = c;
    if (!s) VLOG_WARN("Cache", "{}", s.message());
    VLOG_DEBUG("Cache", "{}: entry {} written in {:.2f} s", id, key, since(t0));
    finished.set_value(s);
  }
};

// Cache entries being written, by key (with the background writer's
// future, which the process's exit waits for): a later preparation of the
// same set waits for its entry, finish_cache_writes for all.
struct Pending {
  std::shared_ptr<WriteJob> job;
  std::shared_future<void> writer;
};
struct PendingWrites {
  // The log's registry is made first, so that it is destroyed after this at
  // exit: the writers this joins then still log (they crashed on a
  // destroyed logger when a process ended while an entry was being written).
  PendingWrites() { (void)veneer::log::get("Cache"); }
  std::mutex lock;
  std::map<std::string, Pending> by_key;
};
PendingWrites& pending_writes() {
  static PendingWrites p;
  return p;
}

Status help_and_wait(const Pending& p) {
  if (!p.job) return Status::success();
  p.job->help();
  return p.job->result.get();
}

void wait_for_write(const std::string& key) {
  Pending p;
  {
    std::lock_guard<std::mutex> hold(pending_writes().lock);
    auto it = pending_writes().by_key.find(key);
    if (it == pending_writes().by_key.end()) return;
    p = it->second;
  }
  (void)help_and_wait(p);
}

// Starts writing `p`'s cache entry under `key` in the background.
void start_write(const io::ResultCache& cache, const std::string& key, const PreparedSet& p) {
  auto job = std::make_shared<WriteJob>(cache, key, p.set.id);
  auto [entry, mats] = to_entry(p);
  job->entry = std::move(entry);
  for (auto& m : mats) job->mats.emplace_back(m.first, std::move(m.second));
  auto folder = cache.begin_store(key);
  if (!folder) {
    VLOG_WARN("Cache", "{}", folder.message());
    job->finished.set_value(folder.error());
    job->next = job->mats.size();
    job->mats.clear();  // nothing to write: the photos are not held
  } else {
    job->folder = *folder;
    if (job->mats.empty()) job->commit();
  }
  auto writer = std::async(std::launch::async, [job] {
    ::setpriority(PRIO_PROCESS, static_cast<id_t>(::gettid()), 19);  // Linux: this thread only
    job->help();
  });
  std::lock_guard<std::mutex> hold(pending_writes().lock);
  pending_writes().by_key[key] = Pending{std::move(job), writer.share()};
}

}  // namespace

namespace {
// Each photo as half floats in place (PrepareOptions::half_photos), one at a time.
void to_half(std::vector<cv::Mat>& photos) {
  for (cv::Mat& photo : photos) {
    if (photo.depth() != CV_32F) continue;
    cv::Mat half;
    photo.convertTo(half, CV_MAKETYPE(CV_16F, photo.channels()));
    photo = half;
  }
}
}  // namespace

Status finish_cache_writes() {
  std::map<std::string, Pending> all;
  {
    std::lock_guard<std::mutex> hold(pending_writes().lock);
    all.swap(pending_writes().by_key);
  }
  Status first = Status::success();
  for (auto& [key, p] : all) {
    Status s = help_and_wait(p);
    if (!s && first) first = s;
  }
  return first;
}

namespace {
// The median of `photos` per sample; with `ambient`, first each photo minus
// the ambient frame, clamped at 0, written back in place, in the same pass
// (one read of every photo instead of three: subtract, clamp, median). The
// photos (and the ambient frame) are float or, all alike, half floats
// (io::ReadOptions::half_floats): those are widened a few hundred samples at
// a time and written back narrowed, and the median is half floats too.
cv::Mat median_minus_ambient(const std::vector<cv::Mat>& photos, const cv::Mat* ambient) {
  if (photos.empty()) return {};
  const int n = static_cast<int>(photos.size());
  const bool half = photos[0].depth() == CV_16F;
  if (n > 32) {
    std::vector<cv::Mat> wide;  // half floats: widened whole here (more than 32 lamps only)
    cv::Mat a;
    if (ambient && half) ambient->convertTo(a, CV_32FC3);
    else if (ambient) a = *ambient;
    for (const cv::Mat& im : photos) {
      cv::Mat m = im;  // shares the pixels: in place
      if (half) im.convertTo(m, CV_32FC3);
      if (ambient) {
        cv::subtract(m, a, m);
        cv::max(m, 0.0, m);
        cv::Mat same = im;  // shares the pixels: written back in place
        if (half) m.convertTo(same, CV_16FC3);
      }
      wide.push_back(m);
    }
    cv::Mat median = repaint::median_photo(wide);
    if (half) median.convertTo(median, CV_16FC3);
    return median;
  }
  // An odd-even transposition network (n rounds of compare-exchanges of
  // neighbours) sorts each sample's n values; run on 256 samples at once,
  // every compare-exchange is a min and a max over two short arrays, which
  // the compiler vectorises: no branch per value.
  std::vector<std::pair<int, int>> network;
  for (int round = 0; round < n; ++round)
    for (int i = round % 2; i + 1 < n; i += 2) network.emplace_back(i, i + 1);
  cv::Mat out = io::big_mat(photos[0].size(), half ? CV_16FC3 : CV_32FC3);
  const int width = out.cols * 3;
  constexpr int kLanes = 256;
  cv::parallel_for_(cv::Range(0, out.rows), [&](const cv::Range& rows) {
    std::vector<float> v(size_t(n) * kLanes), wide_ambient(half ? kLanes : 0), row(half ? width : 0);
    for (int y = rows.start; y < rows.end; ++y) {
      float* o = half ? row.data() : out.ptr<float>(y);  // a half median's row is made as float first
      for (int x0 = 0; x0 < width; x0 += kLanes) {
        const int lanes = std::min(kLanes, width - x0);
        if (half) {
          const float* a = nullptr;
          if (ambient) {
            cv::hal::cvt16f32f(ambient->ptr<cv::float16_t>(y) + x0, wide_ambient.data(), lanes);
            a = wide_ambient.data();
          }
          for (int i = 0; i < n; ++i) {
            auto* p = const_cast<cv::float16_t*>(photos[i].ptr<cv::float16_t>(y)) + x0;
            float* d = &v[size_t(i) * kLanes];
            cv::hal::cvt16f32f(p, d, lanes);
            if (a) {
              for (int k = 0; k < lanes; ++k) d[k] = std::max(d[k] - a[k], 0.0f);
              cv::hal::cvt32f16f(d, p, lanes);
            }
          }
        } else if (ambient) {
          const float* a = ambient->ptr<float>(y) + x0;
          for (int i = 0; i < n; ++i) {
            float* p = const_cast<float*>(photos[i].ptr<float>(y)) + x0;
            float* d = &v[size_t(i) * kLanes];
            for (int k = 0; k < lanes; ++k) d[k] = p[k] = std::max(p[k] - a[k], 0.0f);
          }
        } else {
          for (int i = 0; i < n; ++i)
            std::memcpy(&v[size_t(i) * kLanes], photos[i].ptr<float>(y) + x0, lanes * sizeof(float));
        }
        for (const auto& [a, b] : network) {
          float* pa = &v[size_t(a) * kLanes];
          float* pb = &v[size_t(b) * kLanes];
          for (int k = 0; k < kLanes; ++k) {
            const float lo = std::min(pa[k], pb[k]), hi = std::max(pa[k], pb[k]);
            pa[k] = lo;
            pb[k] = hi;
          }
        }
        const float* mid = &v[size_t(n / 2) * kLanes];
        if (n % 2) {
          std::memcpy(o + x0, mid, lanes * sizeof(float));
        } else {
          const float* below = mid - kLanes;
          for (int k = 0; k < lanes; ++k) o[x0 + k] = 0.5f * (mid[k] + below[k]);
        }
      }
      if (half) cv::hal::cvt32f16f(o, out.ptr<cv::float16_t>(y), width);
    }
  });
  return out;
}
}  // namespace

cv::Mat median_of(const std::vector<cv::Mat>& photos) { return median_minus_ambient(photos, nullptr); }

PrepareOptions default_prepare_options() {
  // the defaults are the options' own (io::RawOptions: MHC, full size; io::ReadOptions: RAW where present),
  // so a caller that builds its own options reads as the CLI does
  PrepareOptions o;
  o.half_frames = true;  // the viewer (float photos) and `veneer transfer` (half photos) solve alike
  return o;
}

Status PrepareOptions::check() const {
  if (auto s = read.check(); !s) return s;
  for (const cv::Mat* m : {&mask, &destination_mask, &source_mask})
    if (!m->empty() && m->type() != CV_8UC1) return make_error("a hand-drawn mask must be 8-bit, one channel");
  return cache.check();
}

namespace {
// The hand-drawn mask on the set as read: one clear error for another size
// or a mask that marks nothing.
Status apply_mask(const cv::Mat& mask, io::ImageSet& set) {
  if (mask.size() != set.size)
    return make_error("the mask is " + std::to_string(mask.cols) + "x" + std::to_string(mask.rows) + ", the set " +
                      set.id + " is " + std::to_string(set.size.width) + "x" + std::to_string(set.size.height));
  set.mask = mask > 127;
  if (cv::countNonZero(set.mask) == 0) return make_error("the mask marks no object pixel (all dark)");
  return {};
}
}  // namespace

Expected<PreparedSet> prepare_set(const fs::path& folder, double scale, bool truth_normals,
                                  const PrepareOptions& options, const Progress& progress) {
  if (auto s = options.check(); !s) return s.error();
  const auto t_all = Clock::now();
  PreparedSet p;
  p.report.folder = folder.string();
  io::ResultCache cache(options.cache);
  const bool cacheable = options.cache.enabled && fs::exists(folder / "set.json");
  std::string key;
  io::ReadOptions read = options.read;
  // half_photos: the frames in half floats from their decoding on (issue 42: a set's frames are never
  // all float at once); segmentation, photometric stereo and the median read them a row at a time
  if (options.half_photos || options.half_frames) read.half_floats = true;
  if (cacheable) {
    auto sum = io::set_checksum(folder, salt_of(read, scale, truth_normals, options.mask));
    if (!sum) return sum.error();
    key = *sum;
    p.report.checksum = key;
  }

  // Hit: metadata, mask and truth from the folder, pixels from the cache.
  if (cacheable) {
    auto t0 = Clock::now();
    progress.report(0.0, "cache " + folder.filename().string());
    wait_for_write(key);
    std::map<std::string, cv::Mat> mats;
    // half photos (and their median) come back as stored, not widened to float and narrowed again (issue 48)
    const std::function<bool(const std::string&)> keep_half = [&](const std::string& name) {
      return options.half_photos && (name == "median" || name.rfind("photo_", 0) == 0);
    };
    if (auto entry = cache.load(key, &mats, keep_half)) {
      io::ReadOptions meta = options.read;
      meta.load_photos = false;
      meta.load_truth_appearance = false;
      auto set = io::read_set(folder, meta);
      if (!set) return set.error();
      p.set = std::move(set).value();
      if (!options.mask.empty()) {
        // as on the miss that made the entry (its key holds the mask's size
        // and bits, checked then); the manifest's size can differ from the
        // decoded RAW size the mask was drawn at
        cv::resize(options.mask > 127, p.set.mask, p.set.size, 0, 0, cv::INTER_NEAREST);
      }
      if (from_entry(*entry, mats, p)) {
        const cv::Size size = p.object.view.normals.size();
        if (size != p.set.size) match::scale_set(p.set, static_cast<double>(size.width) / p.set.size.width);
        if (p.set.size == size) {
          if (options.half_photos) {
            to_half(p.object.view.images);
            std::vector<cv::Mat> median{p.median};
            to_half(median);  // as a miss makes it
            p.median = median[0];
          }
          p.set.images = p.object.view.images;  // shared pixels, ambient already removed
          p.set.ambient.release();
          for (const auto& light : p.set.lights) p.object.view.lamps.push_back(light.lamp_id);
          if (p.object.view.lamps.size() != p.object.view.images.size()) p.object.view.lamps.clear();
          p.report.id = p.set.id;
          p.report.cache_hit = true;
          p.report.photos_from = p.set.photos_from;
          p.report.read_s = since(t0);
          p.report.total_s = since(t_all);
          progress.report(1.0, "cache " + folder.filename().string());
          return p;
        }
      }
      VLOG_WARN("Cache", "{}: cache entry {} does not fit the set; recomputing", folder.string(), key);
      p = PreparedSet{};
      p.report.folder = folder.string();
      p.report.checksum = key;
    }
  }

  // Miss: decode every frame once, in parallel; solve; store.
  auto t0 = Clock::now();
  read.load_truth_appearance = false;  // the truth's albedo and depth: a transfer measures with neither
  read.raw.camera_space = true;        // RAW: normals in the camera's space, sRGB after them (below)
  auto set = io::read_set(folder, read, sub_progress(progress, 0.0, 0.6));
  if (!set) return set.error();
  p.set = std::move(set).value();
  if (!options.mask.empty()) {
    if (auto s = apply_mask(options.mask, p.set); !s) return s.error();
  }
  match::scale_set(p.set, scale);
  p.report.read_s = since(t0);
  p.report.id = p.set.id;
  p.report.photos_from = p.set.photos_from;

  t0 = Clock::now();
  auto mask = match::object_mask(p.set, truth_normals);
  if (!mask) return mask.error();
  p.object.view.mask = std::move(mask).value();
  p.object.segment_seconds = since(t0);
  std::optional<ps::PsResult> solved;
  if (truth_normals) {
    p.object.view.normals = p.set.truth.normals.clone();
  } else {
    t0 = Clock::now();
    auto result = ps::photometric_stereo(p.set, p.object.view.mask, {}, sub_progress(progress, 0.6, 0.9));
    if (!result) return make_error("set " + p.set.id + ": photometric stereo: " + result.message());
    solved = std::move(result).value();
    p.object.normals_seconds = since(t0);
  }
  // The photos colour-managed for the matcher and the pictures (a no-op unless a RAW file's colour matrix
  // was kept aside for photometric stereo, issue 42), the albedo with them.
  if (!io::is_identity(p.set.camera_to_srgb)) {
    if (solved && !solved->albedo.empty()) {
      cv::transform(solved->albedo, solved->albedo, p.set.camera_to_srgb);
      solved->albedo = cv::max(solved->albedo, 0.0);
    }
    io::to_colour_managed(p.set);
  }
  // The photos as the matcher and the repaint use them: ambient removed, in
  // place, in the median's pass (read_set made every frame the set's size);
  // beside it, on another core, a base the object stands on is dropped from
  // the solved mask (a supplied mask is the user's word): the base removal
  // is a serial flood fill, and the median leaves no core idle meanwhile.
  progress.report(0.9, "median " + p.set.id);
  const bool ambient = !p.set.ambient.empty() && !p.set.images.empty() &&
                       std::all_of(p.set.images.begin(), p.set.images.end(), [&](const cv::Mat& im) {
                         return im.size() == p.set.ambient.size() && im.type() == p.set.ambient.type();
                       });
  tbb::parallel_invoke(
      [&] {
        if (!solved || !p.set.mask.empty()) return;
        const auto t = Clock::now();
        ps::drop_supports(*solved);
        p.object.normals_seconds += since(t);
      },
      [&] { p.median = median_minus_ambient(p.set.images, ambient ? &p.set.ambient : nullptr); });
  if (solved) {
    if (p.set.mask.empty()) p.object.view.mask = solved->mask;
    p.object.view.normals = solved->normals;
    p.albedo = solved->albedo;
    p.residual = solved->residual;
  }
  p.report.normals_s = p.object.segment_seconds + p.object.normals_seconds;
  p.set.ambient.release();
  if (options.half_photos) to_half(p.set.images);
  if (!options.half_photos && read.half_floats) {
    // half frames, float photos (half_frames): widened once prepared, one at a time
    for (cv::Mat& photo : p.set.images) photo.convertTo(photo, CV_32FC3);
    if (p.median.depth() == CV_16F) p.median.convertTo(p.median, CV_32FC3);
  }
  p.object.view.images = p.set.images;
  for (const auto& light : p.set.lights) p.object.view.lamps.push_back(light.lamp_id);
  if (p.object.view.lamps.size() != p.object.view.images.size()) p.object.view.lamps.clear();

  if (cacheable) {
    // Written in the background (the Mats are shared, not copied, and
    // nothing writes into them after this): the map and the pictures are
    // made meanwhile. finish_cache_writes() waits for it (and helps).
    start_write(cache, key, p);
    p.report.cache_write_s = -1;  // in the background
  }
  p.report.total_s = since(t_all);
  progress.report(1.0, "prepared " + p.set.id);
  return p;
}

Expected<pipeline::PreparedPair> prepare_pair(const fs::path& destination, const fs::path& source,
                                           const pipeline::TransferOptions& transfer, const PrepareOptions& options,
                                           std::vector<SetReport>* reports, const Progress& progress) {
  if (auto s = transfer.check(); !s) return s.error();
  // Both sets at once: their frames share the workers, so no core idles
  // while one set's last frame decodes. Progress is the sum of both halves.
  std::mutex lock;
  double done[2] = {0, 0};
  auto half = [&](int which) {
    Progress p;
    p.cancel = progress.cancel;
    if (progress.on_progress)
      p.on_progress = [&, which](double f, const std::string& stage) {
        std::lock_guard<std::mutex> hold(lock);
        done[which] = f;
        progress.report(0.5 * (done[0] + done[1]), stage);
      };
    return p;
  };
  Expected<PreparedSet> dst = make_error("not run"), src = make_error("not run");
  PrepareOptions for_dst = options, for_src = options;
  for_dst.mask = options.destination_mask;
  for_src.mask = options.source_mask;
  auto prepare_dst = [&] { dst = prepare_set(destination, transfer.scale, transfer.truth_normals, for_dst, half(0)); };
  auto prepare_src = [&] { src = prepare_set(source, transfer.scale, transfer.truth_normals, for_src, half(1)); };
  if (options.half_photos) {
    prepare_dst();  // one set's float frames at a time
    if (dst) {
      // and the destination's cache entry written before the source is
      // decoded, so that what only the cache needed (albedo, residual) is gone
      if (!dst->report.checksum.empty()) wait_for_write(dst->report.checksum);
      dst->albedo.release(), dst->residual.release();
      prepare_src();
    }
  } else {
    tbb::parallel_invoke(prepare_dst, prepare_src);
  }
  if (!dst) return make_error("destination: " + dst.message());
  if (!src) return make_error("source: " + src.message());
  pipeline::PreparedPair pair;
  pair.scale = transfer.scale;
  pair.truth_normals = transfer.truth_normals;
  pair.destination = std::move(dst->set);
  pair.source = std::move(src->set);
  pair.dst = std::move(dst->object);
  pair.src = std::move(src->object);
  pair.destination_median = dst->median;
  pair.source_median = src->median;
  if (reports) *reports = {dst->report, src->report};
  return pair;
}

std::string reports_json(const std::vector<SetReport>& reports) {
  auto one = [](const SetReport& r) {
    nlohmann::json j{{"folder", r.folder},       {"id", r.id},
                     {"checksum", r.checksum},   {"cache", r.checksum.empty() ? "off" : (r.cache_hit ? "hit" : "miss")},
                     {"photos_from", r.photos_from}, {"read_s", r.read_s},
                     {"normals_s", r.normals_s},
                     {"total_s", r.total_s}};
    if (r.cache_write_s < 0) j["cache_write"] = "background";
    else if (r.cache_write_s > 0) j["cache_write_s"] = r.cache_write_s;
    if (!r.cache_error.empty()) j["cache_error"] = r.cache_error;
    return j;
  };
  nlohmann::json j;
  if (reports.size() == 2) {
    j["destination"] = one(reports[0]);
    j["source"] = one(reports[1]);
  } else {
    j = nlohmann::json::array();
    for (const auto& r : reports) j.push_back(one(r));
  }
  return j.dump();
}

}  // namespace veneer::pipeline
