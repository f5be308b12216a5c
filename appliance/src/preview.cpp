#include "veneerd/preview.hpp"

#include <algorithm>
#include <cstdio>

#include "veneer/io/dng.hpp"
#include "veneer/io/file_crc.hpp"
#include "veneer/io/image_io.hpp"
#include "veneer/io/imageset.hpp"

namespace veneerd {

namespace fs = std::filesystem;
using veneer::make_error;

veneer::Expected<std::vector<ServedFile>> set_files(const Store& store, const std::string& id, bool include_truth,
                                                     const std::vector<std::string>& skip,
                                                     std::vector<std::string>* skipped) {
  auto files = store.files(id, include_truth);
  if (!files) return files.error();
  const fs::path folder = store.folder(id);
  std::vector<ServedFile> out;
  for (const auto& rel : *files) {
    // set.json always comes: the client checks what it resumes against it.
    if (rel != "set.json" && std::find(skip.begin(), skip.end(), rel) != skip.end()) {
      if (skipped) skipped->push_back(rel);
      continue;
    }
    std::error_code ec;
    const uint64_t size = fs::file_size(folder / rel, ec);
    if (ec) return make_error("cannot read " + id + "/" + rel);
    out.push_back({rel, folder / rel, 0, size, {}});
  }
  return out;
}

std::vector<api::ResumeFrom> resume_files(std::vector<ServedFile>& files, const std::vector<api::ResumeFrom>& from) {
  std::vector<api::ResumeFrom> honoured;
  for (auto& f : files) {
    if (f.rel == "set.json" || !f.bytes.empty() || f.source.empty()) continue;
    auto it = std::find_if(from.begin(), from.end(), [&](const api::ResumeFrom& r) { return r.file == f.rel; });
    if (it == from.end() || it->offset == 0 || it->offset > f.size) continue;
    auto crc = veneer::io::file_crc32(f.source, f.offset, it->offset);
    if (!crc || *crc != it->crc32) continue;  // not the rig's bytes (or unreadable): sent whole
    f.start = it->offset;
    honoured.push_back(*it);
  }
  return honoured;
}

veneer::Expected<std::vector<ServedFile>> preview_files(const Store& store, const std::string& id) {
  auto text = store.manifest(id);
  if (!text) return text.error();
  const fs::path folder = store.folder(id);
  auto manifest = veneer::io::parse_manifest(*text, folder);
  if (!manifest) return manifest.error();
  veneer::io::ImageSet set = std::move(manifest->set);
  const size_t n = manifest->image_files.size();
  const bool ambient = !manifest->ambient_file.empty();

  // The frames' stored files in image order, then the ambient frame's.
  std::vector<fs::path> raws, photos;
  for (size_t i = 0; i < n; ++i) {
    raws.push_back(i < manifest->raw_files.size() ? manifest->raw_files[i] : fs::path());
    photos.push_back(manifest->image_files[i]);
  }
  if (ambient) {
    raws.push_back(manifest->ambient_raw_file);
    photos.push_back(manifest->ambient_file);
  }
  std::vector<veneer::io::DngPreview> previews;
  for (const auto& raw : raws) {
    if (raw.empty()) break;
    auto p = veneer::io::find_dng_preview(folder / raw);
    if (!p || (!previews.empty() && p->size != previews.front().size)) break;
    previews.push_back(*p);
  }
  const bool reduced = previews.size() == raws.size() && !previews.empty();

  auto frame_name = [&](size_t k, const std::string& extension) {
    if (k == n) return "ambient." + extension;
    char buf[32];
    std::snprintf(buf, sizeof buf, "light_%02d.", set.lights[k].index);
    return buf + extension;
  };
  std::vector<ServedFile> out;
  out.push_back({"set.json", {}, 0, 0, {}});
  set.developed.assign(n, {});
  for (size_t k = 0; k < raws.size(); ++k) {
    const std::string stored = photos[k].extension().string();
    const std::string extension = reduced ? "jpg" : stored.size() > 1 ? stored.substr(1) : "png";
    ServedFile f{frame_name(k, extension), folder / (reduced ? raws[k] : photos[k]), 0, 0, {}};
    if (reduced) {
      f.offset = previews[k].offset;
      f.size = previews[k].length;
    } else {
      std::error_code ec;
      f.size = fs::file_size(f.source, ec);
      if (ec) return make_error("cannot read " + id + "/" + photos[k].string());
    }
    out.push_back(std::move(f));
    (k == n ? set.ambient_developed : set.developed[k]) = {extension, "1"};  // manifest_json names it
  }
  // The manifest of the preview: its size, intrinsics scaled, no RAW files,
  // no mask (it comes with the full files), marked as a preview of `id`.
  const cv::Size full = set.size;
  if (reduced) {
    const cv::Size size = previews.front().size;
    const double sx = static_cast<double>(size.width) / full.width, sy = static_cast<double>(size.height) / full.height;
    set.camera.focal_px *= sx;
    set.camera.cx *= sx;
    set.camera.cy *= sy;
    set.size = size;
  }
  set.raw.clear();
  set.ambient_raw = {};
  set.mask.release();
  if (ambient) set.ambient = cv::Mat(1, 1, CV_32FC3, cv::Scalar::all(0));  // a marker: the ambient frame is there
  set.preview_of = veneer::io::ImageSet::PreviewOf{set.id, full};
  out.front().bytes = veneer::io::manifest_json(set);
  out.front().size = out.front().bytes.size();
  return out;
}

}  // namespace veneerd
