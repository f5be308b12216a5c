// Reads a veneer-set/1 folder: set.json, the photos (developed or the
// camera's RAW files), mask and truth.
#include <algorithm>

#include <opencv2/imgproc.hpp>

#include "set_detail.hpp"
#include "veneer/io/image_io.hpp"
#include "veneer/util/log.hpp"

namespace veneer::io::detail {
namespace fs = std::filesystem;

namespace {

Status load_truth(const fs::path& truth_dir, ImageSet& set, bool appearance) {
  std::error_code ec;
  if (!fs::is_directory(truth_dir, ec)) return Status::success();
  Truth& t = set.truth;
  // truth/<name> when there is one, read by `read`, into `into`: of the set's
  // size and, unless `channels` is 0, of that many channels (else `wrong`).
  auto load = [&](const char* name, auto read, int channels, const char* wrong, cv::Mat& into) -> Status {
    const fs::path f = truth_dir / name;
    if (!fs::exists(f, ec)) return Status::success();
    auto m = read(f);
    if (!m) return m.error();
    if (channels && m->channels() != channels) return make_error(f.string() + ": " + wrong);
    if (Status s = check_size(f, *m, set.size, "the set's size"); !s) return s;
    into = std::move(m).value();
    return Status::success();
  };
  auto pfm = [](const fs::path& f) { return read_pfm(f, true); };
  auto mask = [](const fs::path& f) { return read_mask(f); };
  auto picture = [](const fs::path& f) { return read_linear_image(f); };
  if (Status s = load("normals.pfm", pfm, 3, "normals must have 3 channels (x, y, z)", t.normals); !s) return s;
  if (Status s = load("mask.png", mask, 0, "", t.mask); !s) return s;
  if (!appearance) return Status::success();
  if (Status s = load("albedo.png", picture, 0, "", t.albedo); !s) return s;
  return load("depth.pfm", pfm, 1, "depth must have 1 channel", t.depth);
}

// Resizes what comes with the photos (mask, truth, intrinsics) from the
// manifest's size to the size the RAW files decoded to.
void fit_to_photos(ImageSet& set, cv::Size size) {
  if (size == set.size) return;
  const double sx = static_cast<double>(size.width) / set.size.width;
  const double sy = static_cast<double>(size.height) / set.size.height;
  auto nearest = [&](cv::Mat& m) {
    if (!m.empty()) cv::resize(m, m, size, 0, 0, cv::INTER_NEAREST);
  };
  nearest(set.mask);
  nearest(set.truth.mask);
  nearest(set.truth.normals);
  nearest(set.truth.depth);
  if (!set.truth.albedo.empty()) cv::resize(set.truth.albedo, set.truth.albedo, size, 0, 0, cv::INTER_LINEAR);
  set.camera.focal_px *= sx;
  set.camera.cx *= sx;
  set.camera.cy *= sy;
  set.size = size;
}
}  // namespace

Expected<ImageSet> read_veneer(const fs::path& folder, const ReadOptions& options, const Progress& progress) {
  const fs::path manifest_file = folder / "set.json";
  std::error_code ec;
  if (auto bytes = fs::file_size(manifest_file, ec); !ec && bytes > kMaxManifestBytes)
    return make_error(manifest_file.string() + ": " + std::to_string(bytes) + " bytes is too large for a manifest");
  auto text = read_file_bytes(manifest_file);
  if (!text) return text.error();
  auto manifest = parse_manifest(*text, folder);
  if (!manifest) return manifest.error();
  ImageSet set = std::move(manifest->set);

  // RAW where every photo (and the ambient frame) has its RAW file, unless told otherwise.
  const bool all_raw =
      !manifest->raw_files.empty() &&
      std::all_of(manifest->raw_files.begin(), manifest->raw_files.end(), [](const fs::path& f) { return !f.empty(); }) &&
      (manifest->ambient_file.empty() || !manifest->ambient_raw_file.empty());
  if (options.photos == PhotoSource::raw && !all_raw)
    return make_error(manifest_file.string() + ": RAW photos were asked for, but not every image" +
                      std::string(manifest->ambient_file.empty() ? "" : " and the ambient frame") + " names a RAW file");
  const bool use_raw = options.photos != PhotoSource::developed && all_raw;

  // The mask (set.json's size) and the truth, with or without the photos.
  auto load_mask_and_truth = [&]() -> Status {
    if (!manifest->mask_file.empty()) {
      fs::path f = folder / manifest->mask_file;
      auto m = read_mask(f);
      if (!m) return m.error();
      if (Status s = check_size(f, *m, set.size, "set.json's size"); !s) return s;
      set.mask = std::move(m).value();
    }
    if (options.load_truth) return load_truth(folder / "truth", set, options.load_truth_appearance);
    return {};
  };
  if (!options.load_photos) {
    if (Status s = load_mask_and_truth(); !s) return s.error();
    set.photos_from = use_raw ? (options.raw.half_size ? "raw-half" : "raw") : "developed";
    set.photos_read = use_raw ? "the RAW files named by set.json (not decoded: manifest only)"
                              : "the developed photos named by set.json (not decoded: manifest only)";
    return set;
  }
  std::vector<Frame> frames;
  for (size_t i = 0; i < manifest->image_files.size(); ++i)
    frames.push_back(use_raw ? Frame{folder / manifest->raw_files[i], true} : Frame{folder / manifest->image_files[i], false});
  if (!manifest->ambient_file.empty())
    frames.push_back(use_raw ? Frame{folder / manifest->ambient_raw_file, true} : Frame{folder / manifest->ambient_file, false});
  std::vector<cv::Mat> decoded;
  std::vector<PhotoKind> kinds;
  const std::string stage = "reading " + (set.id.empty() ? folder.filename().string() : set.id);
  if (Status s = decode_frames(frames, options.raw, options.half_floats, progress, stage, decoded, &kinds); !s) return s.error();
  if (!manifest->ambient_file.empty()) {
    set.ambient = std::move(decoded.back());
    decoded.pop_back();
  }
  set.images = std::move(decoded);
  note_photo_kinds(set, kinds, false, options.raw);
  settle_camera_space(set, kinds);

  // Developed photos must have set.json's size; RAW photos define it.
  const cv::Size photo_size = set.images.front().size();
  const std::string why = use_raw ? "the first RAW photo's size" : "set.json's size";
  const cv::Size expect = use_raw ? photo_size : set.size;
  for (size_t i = 0; i < frames.size(); ++i) {
    const cv::Mat& m = i < set.images.size() ? set.images[i] : set.ambient;
    if (Status s = check_size(frames[i].file, m, expect, why); !s) return s.error();
  }
  if (Status s = load_mask_and_truth(); !s) return s.error();
  if (use_raw && photo_size != set.size) {
    VLOG_INFO("ImageSet", "{}: RAW photos are {}, set.json says {}; mask, truth and intrinsics scaled to the RAW size",
              folder.string(), size_text(photo_size), size_text(set.size));
    fit_to_photos(set, photo_size);
  }
  return set;
}
}  // namespace veneer::io::detail
