// Reduced decodes (reduced.hpp): RAW mosaics binned, JPEGs decoded small in
// the DCT, RAW previews, and a set read through them at the live view's size.
#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <memory>
#include <mutex>

#include <libraw/libraw.h>
#include <opencv2/imgcodecs.hpp>  // the IMREAD_* flags
#include <opencv2/imgproc.hpp>
#include <tbb/parallel_for.h>

#include "file_util.hpp"
#include "jpeg_codec.hpp"
#include "pixels.hpp"
#include "set_detail.hpp"
#include "veneer/io/image_io.hpp"
#include "veneer/io/raw.hpp"
#include "veneer/io/reduced.hpp"
#include "veneer/util/enum_names.hpp"

namespace veneer::io {
namespace fs = std::filesystem;

namespace {

constexpr long long kMaxRawPixels = 100'000'000;  // as raw_decode.cpp: a damaged header can claim anything

// LibRaw with a look at what its parser found about the mosaic's layout.
class RawPeek : public LibRaw {
 public:
  RawPeek() : LibRaw(LIBRAW_OPTIONS_NONE) {}
  // The mosaic in `bytes` itself when the file stores it plainly -- one
  // uncompressed strip of little-endian 16-bit samples, no linearisation
  // curve (the simulated rig's DNGs) -- so unpack(), which copies it sample
  // by sample through the curve into a buffer of its own, is not needed.
  const uint16_t* mosaic_in_place(std::string_view bytes) const {
    const auto& u = libraw_internal_data.unpacker_data;
    const auto& s = imgdata.sizes;
    const auto& curve = imgdata.color.curve;
    const uint64_t need = static_cast<uint64_t>(s.raw_width) * s.raw_height * 2;
    const bool plain = imgdata.idata.dng_version != 0 && u.tiff_compress == 1 && u.tiff_bps == 16 &&
                       u.tiff_samples == 1 && u.order == 0x4949 && u.data_offset > 0 && u.data_offset % 2 == 0 &&
                       static_cast<uint64_t>(u.data_offset) + need <= bytes.size() &&
                       (u.tile_width == 0 || u.tile_width >= s.raw_width) && curve[1] == 1 && curve[4095] == 4095 &&
                       curve[65535] == 65535;
    if (!plain) return nullptr;
    return reinterpret_cast<const uint16_t*>(bytes.data() + u.data_offset);
  }
};

// A LibRaw instance opened on `bytes` (LibRaw's state is large: on the heap).
Expected<std::unique_ptr<RawPeek>> open_raw(std::string_view bytes, const std::string& name) {
  if (bytes.empty()) return make_error(name + ": empty file");
  if (Status s = check_raw_structure(bytes, name); !s) return s.error();
  auto raw = std::make_unique<RawPeek>();
  int r = raw->open_buffer(const_cast<char*>(bytes.data()), bytes.size());
  if (r != LIBRAW_SUCCESS)
    return make_error(name + ": not a RAW file LibRaw can read (" + std::string(libraw_strerror(r)) + ")");
  const auto& s = raw->imgdata.sizes;
  if (s.raw_width == 0 || s.raw_height == 0 || static_cast<long long>(s.raw_width) * s.raw_height > kMaxRawPixels)
    return make_error(name + ": RAW size " + std::to_string(s.raw_width) + "x" + std::to_string(s.raw_height) +
                      " is empty or too large");
  return raw;
}

}  // namespace

constexpr EnumName<ReducedDecode> kReducedDecodeNames[] = {
    {ReducedDecode::automatic, "auto"},           {ReducedDecode::raw_binned, "raw-binned"},
    {ReducedDecode::jpeg_reduced, "jpeg-reduced"}, {ReducedDecode::raw_preview, "raw-preview"},
    {ReducedDecode::developed, "developed"}};

const char* reduced_decode_name(ReducedDecode d) { return name_of(kReducedDecodeNames, d); }

Expected<ReducedDecode> parse_reduced_decode(const std::string& name) {
  return parse_name(kReducedDecodeNames, name, "reduced decode");
}

Expected<cv::Mat> decode_raw_binned(std::string_view bytes, int factor, const std::string& name) {
  if (factor < 2 || factor > 32 || factor % 2 != 0)
    return make_error(name + ": binning factor " + std::to_string(factor) + " is not even in 2..32");
  auto opened = open_raw(bytes, name);
  if (!opened) return opened.error();
  RawPeek& raw = **opened;
  if (raw.imgdata.idata.colors != 3 || raw.imgdata.idata.filters < 1000)
    return make_error(name + ": only Bayer (RGB colour filter array) RAW files can be binned");
  const auto& s = raw.imgdata.sizes;
  const uint16_t* mosaic = raw.mosaic_in_place(bytes);
  size_t pitch = s.raw_width;
  if (!mosaic) {
    int r = raw.unpack();
    if (r != LIBRAW_SUCCESS)
      return make_error(name + ": cannot unpack RAW data (" + std::string(libraw_strerror(r)) + ")");
    mosaic = raw.imgdata.rawdata.raw_image;
    if (!mosaic) return make_error(name + ": the RAW file has no single-channel Bayer mosaic to bin");
    if (s.raw_pitch < 2u * s.raw_width) return make_error(name + ": the RAW file's mosaic rows are too short");
    pitch = s.raw_pitch / 2;
  }
  const int w = s.width, h = s.height;
  const int ow = w / factor, oh = h / factor;
  if (ow < 1 || oh < 1) return make_error(name + ": " + std::to_string(w) + "x" + std::to_string(h) + " is too small to bin by " + std::to_string(factor));
  if (s.top_margin + h > s.raw_height || s.left_margin + w > s.raw_width)
    return make_error(name + ": the RAW file's visible area lies outside its mosaic");
  const auto& C = raw.imgdata.color;

  // Per 2x2 position: its colour (0 R, 1 G, 2 B; LibRaw's second green 3 is
  // green) and black level, as LibRaw's black handling sums them.
  int color[2][2];
  double black[2][2];
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < 2; ++x) {
      int c = raw.COLOR(y, x);
      const unsigned c4 = static_cast<unsigned>(c & 3);
      double b = static_cast<double>(C.black) + C.cblack[c4];
      if (C.cblack[4] > 0 && C.cblack[5] > 0 && C.cblack[4] * C.cblack[5] <= LIBRAW_CBLACK_SIZE - 6)
        b += C.cblack[6 + (y % C.cblack[4]) * C.cblack[5] + x % C.cblack[5]];
      if (c == 3) c = 1;
      if (c < 0 || c > 2) return make_error(name + ": unexpected colour filter layout");
      color[y][x] = c;
      black[y][x] = b;
    }
  const double black_common = std::min({black[0][0], black[0][1], black[1][0], black[1][1]});
  const double range = static_cast<double>(C.maximum) - black_common;
  if (!(range > 0)) return make_error(name + ": white level " + std::to_string(C.maximum) + " is not above black");
  // White balance as dcraw's scale_colors with use_camera_wb, highlight 0:
  // the as-shot multipliers (else the daylight ones) divided by their least.
  double mul[4];
  const bool cam_ok = C.cam_mul[0] > 0 && C.cam_mul[1] > 0 && C.cam_mul[2] > 0;
  for (int c = 0; c < 4; ++c) mul[c] = cam_ok ? C.cam_mul[c] : C.pre_mul[c];
  if (!(mul[0] > 0 && mul[1] > 0 && mul[2] > 0)) mul[0] = mul[1] = mul[2] = 1;
  const double least = std::min({mul[0], mul[1], mul[2]});
  double scale[3];
  for (int c = 0; c < 3; ++c) scale[c] = mul[c] / least / range;

  // Each output pixel sums a (k+2) x (k+2) window with the separable weights
  // [1/4, 3/4, 1, ..., 1, 3/4, 1/4]: per colour that is the box over the
  // block with each colour's samples moved half a pixel to the block's
  // centre (the R samples of an RGGB block sit up-left of it, the B samples
  // down-right; a plain box shifts them, and colour fringes at every edge).
  // Each colour's weights sum to (k/2)^2 per Bayer position; black likewise.
  const int half = factor / 2;
  double count[3] = {0, 0, 0}, black_sum[3] = {0, 0, 0};
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < 2; ++x) {
      count[color[y][x]] += half * half;
      black_sum[color[y][x]] += black[y][x] * half * half;
    }
  for (int c = 0; c < 3; ++c)
    if (count[c] == 0) return make_error(name + ": the colour filter array lacks a colour");

  float m[3][3];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) m[i][j] = C.rgb_cam[i][j];
  // The window's rows (cols): block start b - 1 .. b + k, mirrored onto the
  // same colour inside the image at its borders.
  auto mirror = [](int t, int n) { return t < 0 ? t + 2 : (t >= n ? t - 2 : t); };
  std::vector<float> weight(static_cast<size_t>(factor) + 2, 1.0f);
  weight[0] = weight[static_cast<size_t>(factor) + 1] = 0.25f;
  weight[1] = weight[static_cast<size_t>(factor)] = 0.75f;

  cv::Mat out(oh, ow, CV_32FC3);
  cv::parallel_for_(cv::Range(0, oh), [&](const cv::Range& range_rows) {
    std::vector<float> sums(static_cast<size_t>(ow) * 3);
    for (int oy = range_rows.start; oy < range_rows.end; ++oy) {
      std::fill(sums.begin(), sums.end(), 0.0f);
      for (int dy = 0; dy < factor + 2; ++dy) {
        const int y = mirror(oy * factor - 1 + dy, h);
        const float wy = weight[static_cast<size_t>(dy)];
        const uint16_t* row = mosaic + (static_cast<size_t>(s.top_margin) + y) * pitch + s.left_margin;
        const int ce = color[y & 1][0], co = color[y & 1][1];
        float* sum = sums.data();
        for (int ox = 0; ox < ow; ++ox, sum += 3) {
          const int b = ox * factor;
          const uint16_t* p = row + b;
          // even columns b .. b+k (b even), odd columns b-1 .. b+k-1
          float even = 0.75f * p[0], odd = 0.75f * p[factor - 1];
          for (int dx = 2; dx < factor; dx += 2) {
            even += p[dx];
            odd += p[dx - 1];
          }
          even += 0.25f * row[mirror(b + factor, w)];
          odd += 0.25f * row[mirror(b - 1, w)];
          sum[ce] += wy * even;
          sum[co] += wy * odd;
        }
      }
      float* o = out.ptr<float>(oy);
      const float* sum = sums.data();
      for (int ox = 0; ox < ow; ++ox, sum += 3, o += 3) {
        float cam[3];
        for (int c = 0; c < 3; ++c) {
          const double v = (sum[c] - black_sum[c]) / count[c] * scale[c];
          cam[c] = static_cast<float>(std::clamp(v, 0.0, 1.0));
        }
        for (int i = 0; i < 3; ++i) {
          const float v = m[i][0] * cam[0] + m[i][1] * cam[1] + m[i][2] * cam[2];
          o[2 - i] = std::clamp(v, 0.0f, 1.0f);  // RGB -> BGR
        }
      }
    }
  });
  return out;
}

Expected<cv::Mat> decode_raw_binned_to_width(std::string_view bytes, int min_width, const std::string& name,
                                             int* factor_out) {
  auto opened = open_raw(bytes, name);
  if (!opened) return opened.error();
  const int w = (*opened)->imgdata.sizes.width;
  opened->reset();
  int factor = 2;
  while (factor + 2 <= 32 && w / (factor + 2) >= min_width) factor += 2;
  if (factor_out) *factor_out = factor;
  return decode_raw_binned(bytes, factor, name);
}

int jpeg_reduction_for(int width, int min_width) {
  int f = 1;
  while (f < 8 && (width + 2 * f - 1) / (2 * f) >= min_width) f *= 2;
  return f;
}

Expected<cv::Mat> decode_jpeg_reduced(std::string_view bytes, int factor, const std::string& name) {
  int flag = 0;
  switch (factor) {
    case 1: flag = cv::IMREAD_COLOR; break;
    case 2: flag = cv::IMREAD_REDUCED_COLOR_2; break;
    case 4: flag = cv::IMREAD_REDUCED_COLOR_4; break;
    case 8: flag = cv::IMREAD_REDUCED_COLOR_8; break;
    default: return make_error(name + ": JPEG reduction " + std::to_string(factor) + " is not 1, 2, 4 or 8");
  }
  if (!detail::has_jpeg_magic(bytes)) return make_error(name + ": not a JPEG file");
  // through libjpeg itself where the build has it: no image codec library opened for the live view (issue 48)
  if (auto direct = detail::decode_jpeg8(bytes, factor, name)) {
    if (!*direct) return direct->error();
    return detail::srgb8_to_linear(**direct);
  }
  auto bgr8 = detail::imdecode_bytes(bytes, flag | cv::IMREAD_IGNORE_ORIENTATION, name, " JPEG");
  if (!bgr8) return bgr8.error();
  if (bgr8->empty() || bgr8->type() != CV_8UC3) return make_error(name + ": corrupt or truncated JPEG (decoder failed)");
  return detail::srgb8_to_linear(*bgr8);
}

Expected<cv::Mat> decode_raw_preview(std::string_view bytes, const std::string& name) {
  auto opened = open_raw(bytes, name);
  if (!opened) return opened.error();
  RawPeek& raw = **opened;
  int r = raw.unpack_thumb();
  if (r != LIBRAW_SUCCESS)
    return make_error(name + ": no embedded preview LibRaw can read (" + std::string(libraw_strerror(r)) + ")");
  const auto& t = raw.imgdata.thumbnail;
  if (!t.thumb || t.tlength == 0) return make_error(name + ": the embedded preview is empty");
  const std::string_view data(t.thumb, t.tlength);
  if (t.tformat == LIBRAW_THUMBNAIL_JPEG) return decode_jpeg_reduced(data, 1, name + " (preview)");
  if (t.tformat == LIBRAW_THUMBNAIL_BITMAP && t.tcolors == 3 &&
      static_cast<size_t>(t.twidth) * t.theight * 3 <= t.tlength && t.twidth > 0 && t.theight > 0) {
    cv::Mat rgb(t.theight, t.twidth, CV_8UC3, const_cast<char*>(t.thumb));
    cv::Mat bgr;
    cv::cvtColor(rgb, bgr, cv::COLOR_RGB2BGR);
    return detail::srgb8_to_linear(bgr);
  }
  return make_error(name + ": the embedded preview is in a format not read here (" + std::to_string(t.tformat) + ")");
}

Status ReducedOptions::check() const {
  if (width < 64 || width > 8192) return make_error("live width " + std::to_string(width) + " px is not in 64..8192");
  if (decode != ReducedDecode::automatic && decode != ReducedDecode::raw_binned &&
      decode != ReducedDecode::jpeg_reduced && decode != ReducedDecode::raw_preview &&
      decode != ReducedDecode::developed)
    return make_error("unknown reduced decode");
  return Status::success();
}

namespace {

cv::Size fitted(cv::Size s, int width) {
  if (s.width <= width) return s;
  return {width, std::max(1, static_cast<int>(std::lround(static_cast<double>(s.height) * width / s.width)))};
}

void area_to(cv::Mat& m, cv::Size size) {
  if (!m.empty() && m.size() != size) cv::resize(m, m, size, 0, 0, cv::INTER_AREA);
}

// Mask, truth and intrinsics from set.size to `size` (nearest for masks and
// normals, as read_set fits them to a RAW file's size).
void fit_extras(ImageSet& set, cv::Size size) {
  if (size == set.size) return;
  const double sx = static_cast<double>(size.width) / set.size.width;
  const double sy = static_cast<double>(size.height) / set.size.height;
  for (cv::Mat* m : {&set.mask, &set.truth.mask, &set.truth.normals, &set.truth.depth})
    if (!m->empty()) cv::resize(*m, *m, size, 0, 0, cv::INTER_NEAREST);
  area_to(set.truth.albedo, size);
  set.camera.focal_px *= sx;
  set.camera.cx *= sx;
  set.camera.cy *= sy;
  set.size = size;
}

struct Decoded {
  cv::Mat photo;
  std::string kind;
};

// One frame through `decode`; `width` is the target.
Expected<Decoded> decode_one(ReducedDecode decode, const fs::path& file, int width) {
  auto mapped = detail::MappedFile::open(file);
  if (!mapped) return mapped.error();
  const std::string_view bytes = mapped->bytes();
  const std::string name = file.string();
  Decoded d;
  switch (decode) {
    case ReducedDecode::raw_binned: {
      int factor = 0;
      auto m = decode_raw_binned_to_width(bytes, width, name, &factor);
      if (!m) return m.error();
      d = {std::move(*m), "raw-binned-" + std::to_string(factor)};
      break;
    }
    case ReducedDecode::jpeg_reduced: {
      // The JPEG's own size from a header-only look would need libjpeg; the
      // set's size (set.json) is the developed photo's.
      const cv::Size full = [&] {
        // SOF0..SOF15 (not DHT/JPG/DAC) carry height then width.
        for (size_t i = 2; i + 9 < bytes.size();) {
          if (static_cast<unsigned char>(bytes[i]) != 0xFF) break;
          const unsigned char marker = static_cast<unsigned char>(bytes[i + 1]);
          const size_t len = (static_cast<unsigned char>(bytes[i + 2]) << 8) | static_cast<unsigned char>(bytes[i + 3]);
          if (marker >= 0xC0 && marker <= 0xCF && marker != 0xC4 && marker != 0xC8 && marker != 0xCC)
            return cv::Size((static_cast<unsigned char>(bytes[i + 7]) << 8) | static_cast<unsigned char>(bytes[i + 8]),
                            (static_cast<unsigned char>(bytes[i + 5]) << 8) | static_cast<unsigned char>(bytes[i + 6]));
          i += 2 + len;
        }
        return cv::Size();
      }();
      const int factor = full.width > 0 ? jpeg_reduction_for(full.width, width) : 1;
      auto m = decode_jpeg_reduced(bytes, factor, name);
      if (!m) return m.error();
      d = {std::move(*m), "jpeg-reduced-" + std::to_string(factor)};
      break;
    }
    case ReducedDecode::raw_preview: {
      auto m = decode_raw_preview(bytes, name);
      if (!m) return m.error();
      d = {std::move(*m), "raw-preview"};
      break;
    }
    case ReducedDecode::developed:
    case ReducedDecode::automatic: {
      auto m = decode_linear_image(bytes, name);
      if (!m) return m.error();
      d = {std::move(*m), "developed"};
      break;
    }
  }
  area_to(d.photo, fitted(d.photo.size(), width));
  return d;
}

// Every frame through `decode` in parallel; the first error by list order wins.
Status decode_all(ReducedDecode decode, const std::vector<fs::path>& files, int width, const Progress& progress,
                  const std::string& stage, std::vector<Decoded>& out) {
  out.assign(files.size(), Decoded{});
  return detail::for_each_parallel(files.size(), progress, stage, [&](size_t i) -> Status {
    auto d = decode_one(decode, files[i], width);
    if (!d) return d.error();
    out[i] = std::move(*d);
    return Status::success();
  });
}

}  // namespace

Expected<ImageSet> read_set_reduced(const fs::path& folder, const ReducedOptions& options, const Progress& progress) {
  if (Status s = options.check(); !s) return make_error(folder.string() + ": " + s.message());
  std::error_code ec;
  if (!fs::exists(folder / "set.json", ec)) {
    // DiLiGenT / thesis folders: whole, then area-resized.
    auto set = read_set(folder, {}, progress);
    if (!set) return set;
    const cv::Size size = fitted(set->size, options.width);
    for (auto& m : set->images) area_to(m, size);
    area_to(set->ambient, size);
    fit_extras(*set, size);
    set->photos_from = "developed";
    return set;
  }
  auto text = read_file_bytes(folder / "set.json");
  if (!text) return text.error();
  auto manifest = parse_manifest(*text, folder);
  if (!manifest) return manifest.error();
  ReadOptions meta;
  meta.load_photos = false;
  meta.load_truth = options.load_truth;
  meta.load_truth_appearance = false;
  auto set = read_set(folder, meta);  // manifest, mask, truth
  if (!set) return set;

  const bool all_raw =
      !manifest->raw_files.empty() &&
      std::all_of(manifest->raw_files.begin(), manifest->raw_files.end(), [](const fs::path& f) { return !f.empty(); }) &&
      (manifest->ambient_file.empty() || !manifest->ambient_raw_file.empty());
  bool developed_jpeg = false;
  if (!manifest->image_files.empty()) {
    if (auto head = detail::MappedFile::open(folder / manifest->image_files.front()); head)
      developed_jpeg = detail::has_jpeg_magic(head->bytes());
  }
  const bool wider = set->size.width > options.width;
  ReducedDecode decode = options.decode;
  if (decode == ReducedDecode::automatic)
    decode = wider && developed_jpeg ? ReducedDecode::jpeg_reduced
             : wider && all_raw      ? ReducedDecode::raw_binned
                                     : ReducedDecode::developed;
  const bool from_raw = decode == ReducedDecode::raw_binned || decode == ReducedDecode::raw_preview;
  if (from_raw && !all_raw)
    return make_error(folder.string() + ": a " + reduced_decode_name(decode) + " decode was asked for, but not every image" +
                      std::string(manifest->ambient_file.empty() ? "" : " and the ambient frame") + " names a RAW file");
  if (decode == ReducedDecode::jpeg_reduced && !developed_jpeg)
    return make_error(folder.string() + ": a jpeg-reduced decode was asked for, but the photos are not JPEGs");

  auto files_for = [&](bool raw) {
    std::vector<fs::path> files;
    for (size_t i = 0; i < manifest->image_files.size(); ++i)
      files.push_back(folder / (raw ? manifest->raw_files[i] : manifest->image_files[i]));
    if (!manifest->ambient_file.empty())
      files.push_back(folder / (raw ? manifest->ambient_raw_file : manifest->ambient_file));
    return files;
  };
  const std::string stage = "reading " + (set->id.empty() ? folder.filename().string() : set->id) + " at live size";
  std::vector<Decoded> decoded;
  Status s = decode_all(decode, files_for(from_raw), options.width, progress, stage, decoded);
  if (!s && options.decode == ReducedDecode::automatic && decode == ReducedDecode::raw_binned &&
      s.message() != "cancelled") {
    // Not a Bayer mosaic (a linear DNG, X-Trans ...): the developed photos.
    decode = ReducedDecode::developed;
    s = decode_all(decode, files_for(false), options.width, progress, stage, decoded);
  }
  if (!s) return s.error();
  const cv::Size size = decoded.front().photo.size();
  const auto files = files_for(decode == ReducedDecode::raw_binned || decode == ReducedDecode::raw_preview);
  for (size_t i = 0; i < decoded.size(); ++i)
    if (decoded[i].photo.size() != size)
      return make_error(files[i].string() + ": decodes to " + std::to_string(decoded[i].photo.cols) + "x" +
                        std::to_string(decoded[i].photo.rows) + ", the set's first photo to " +
                        std::to_string(size.width) + "x" + std::to_string(size.height));
  if (!manifest->ambient_file.empty()) {
    set->ambient = std::move(decoded.back().photo);
    decoded.pop_back();
  }
  set->images.clear();
  for (auto& d : decoded) set->images.push_back(std::move(d.photo));
  set->photos_from = decoded.front().kind;
  fit_extras(*set, size);
  if (Status v = validate(*set); !v) return make_error(folder.string() + ": " + v.message());
  return set;
}

}  // namespace veneer::io
