// RAW decoding through LibRaw (raw.hpp). The only file that sees LibRaw.
#include <algorithm>
#include <cctype>
#include <cmath>
#include <memory>
#include <optional>
#include <vector>

#include <libraw/libraw.h>
#include <opencv2/core/hal/hal.hpp>

#include "demosaic.hpp"
#include "tiff.hpp"
#include "veneer/io/image_io.hpp"
#include "veneer/io/raw.hpp"

namespace veneer::io {

namespace {

// Most pixels we let LibRaw allocate for (a 100 Mpx sensor); a damaged header
// can claim anything.
constexpr long long kMaxRawPixels = 100'000'000;

std::string libraw_error(int code) { return libraw_strerror(code); }

// An image LibRaw made in memory (dcraw_make_mem_image / _thumb), freed by it.
struct MemImageFree {
  void operator()(libraw_processed_image_t* i) const { LibRaw::dcraw_clear_mem(i); }
};
using MemImage = std::unique_ptr<libraw_processed_image_t, MemImageFree>;

}  // namespace

namespace {

struct DemosaicInfo {
  Demosaic method;
  const char* name;
  int user_qual;  // LibRaw's output_params.user_qual
};
constexpr DemosaicInfo kDemosaics[] = {
    {Demosaic::bilinear, "bilinear", 0}, {Demosaic::vng, "vng", 1},  {Demosaic::ppg, "ppg", 2},
    {Demosaic::ahd, "ahd", 3},           {Demosaic::dcb, "dcb", 4},  {Demosaic::dht, "dht", 11},
    {Demosaic::aahd, "aahd", 12},        {Demosaic::mhc, "mhc", -1},  // ours (demosaic.hpp)
};

const DemosaicInfo* find_demosaic(Demosaic d) {
  for (const auto& i : kDemosaics) {
    if (i.method == d) return &i;
  }
  return nullptr;
}

}  // namespace

const char* demosaic_name(Demosaic d) {
  const DemosaicInfo* i = find_demosaic(d);
  return i ? i->name : "unknown";
}

namespace {

// The unpacked mosaic handed to demosaic_mhc: LibRaw's black levels, white
// level, as-shot white balance and colour matrix, applied as its
// dcraw_process applies them with the options decode_raw_linear sets
// (highlight 0: the smallest multiplier is 1, values clip at the white
// level). nullopt when the file is of a kind only LibRaw's own pipeline takes
// (not a plain 2x2 Bayer layout, a black-level pattern over 2x2, odd size).
std::optional<detail::Mosaic> mosaic_of(LibRaw& raw) {
  const auto& sz = raw.imgdata.sizes;
  const auto& col = raw.imgdata.color;
  const uint16_t* data = raw.imgdata.rawdata.raw_image;
  if (!data || sz.width < 4 || sz.height < 4 || sz.width % 2 || sz.height % 2 || sz.raw_pitch < 2) return std::nullopt;
  if (sz.flip != 0 || sz.pixel_aspect != 1.0) return std::nullopt;
  detail::Mosaic m;
  m.data = data;
  m.pitch = static_cast<int>(sz.raw_pitch / 2);
  m.top = sz.top_margin;
  m.left = sz.left_margin;
  m.width = sz.width;
  m.height = sz.height;
  if (m.top + m.height > sz.raw_height || m.left + m.width > m.pitch) return std::nullopt;
  const unsigned ph = col.cblack[4], pw = col.cblack[5];
  if ((ph && 2 % ph) || (pw && 2 % pw)) return std::nullopt;
  float mul[4];
  for (int c = 0; c < 4; ++c) mul[c] = col.cam_mul[c] > 0 ? col.cam_mul[c] : col.pre_mul[c];
  if (!(mul[3] > 0)) mul[3] = mul[1];
  for (int c = 0; c < 4; ++c)
    if (!(mul[c] > 0)) return std::nullopt;
  const float least = *std::min_element(mul, mul + 4);
  const float range = static_cast<float>(col.maximum) - static_cast<float>(col.black);
  if (!(range > 0)) return std::nullopt;
  for (int p = 0; p < 4; ++p) {
    const int y = p / 2, x = p % 2;
    const int raw_colour = raw.COLOR(y, x);  // 0 R, 1 G, 2 B, 3 the second G
    if (raw_colour < 0 || raw_colour > 3) return std::nullopt;
    m.cfa[p] = raw_colour == 3 ? 1 : raw_colour;
    float black = static_cast<float>(col.black + col.cblack[raw_colour]);
    if (ph && pw) black += static_cast<float>(col.cblack[6 + (y % ph) * pw + (x % pw)]);
    m.black[p] = black;
    m.scale[p] = mul[raw_colour] / least / range;
  }
  if (!detail::is_bayer(m.cfa)) return std::nullopt;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) m.rgb_cam[r][c] = col.rgb_cam[r][c];
  return m;
}

}  // namespace

Expected<Demosaic> parse_demosaic(const std::string& name) {
  std::string known;
  for (const auto& i : kDemosaics) {
    if (name == i.name) return i.method;
    known += (known.empty() ? "" : ", ") + std::string(i.name);
  }
  return make_error("demosaic \"" + name.substr(0, 32) + "\" is not one of " + known);
}

Status RawOptions::check() const {
  if (!find_demosaic(demosaic)) return make_error("unknown demosaic method");
  return Status::success();
}

bool is_raw_file_name(const std::string& file_name) {
  const size_t dot = file_name.rfind('.');
  if (dot == std::string::npos) return false;
  std::string ext = file_name.substr(dot + 1);
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  static const char* kRaw[] = {"cr2", "cr3", "crw", "nef", "nrw", "arw", "srf", "sr2", "dng",
                               "orf", "rw2", "raf", "pef", "raw", "rwl", "srw", "3fr", "iiq"};
  return std::any_of(std::begin(kRaw), std::end(kRaw), [&](const char* r) { return ext == r; });
}

bool is_identity(const cv::Matx33f& m) {
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c)
      if (std::abs(m(r, c) - (r == c ? 1.f : 0.f)) > 1e-4f) return false;
  return true;
}

void apply_colour_matrix(cv::Mat& photo, const cv::Matx33f& m) {
  if (photo.empty() || is_identity(m)) return;
  CV_Assert(photo.type() == CV_32FC3 || photo.type() == CV_16FC3);
  const bool half = photo.depth() == CV_16F;
  const int values = photo.cols * 3;
  cv::parallel_for_(cv::Range(0, photo.rows), [&](const cv::Range& rows) {
    std::vector<float> wide(half ? size_t(values) : 0);  // a half row widened, transformed, narrowed
    for (int y = rows.start; y < rows.end; ++y) {
      if (half) cv::hal::cvt16f32f(photo.ptr<cv::float16_t>(y), wide.data(), values);
      float* p = half ? wide.data() : photo.ptr<float>(y);
      for (int x = 0; x < photo.cols; ++x, p += 3) {
        const float b = p[0], g = p[1], r = p[2];
        for (int k = 0; k < 3; ++k) p[k] = std::clamp(m(k, 0) * b + m(k, 1) * g + m(k, 2) * r, 0.f, 1.f);
      }
      if (half) cv::hal::cvt32f16f(wide.data(), photo.ptr<cv::float16_t>(y), values);
    }
  });
}

Status check_raw_structure(std::string_view bytes, const std::string& name) {
  const size_t size = bytes.size();
  detail::Tiff tiff(bytes);
  uint32_t first = 0;
  if (tiff.header(first) != detail::Tiff::Header::tiff) return Status::success();  // not TIFF (e.g. a CR3, RAF or ORF header): LibRaw judges
  auto bad = [&](const std::string& why) { return make_error(name + ": not a whole RAW file: " + why); };
  std::vector<uint32_t> queue{first}, seen;  // depth first: each directory's SubIFDs, then the next
  while (!queue.empty()) {
    const uint32_t at = queue.back();
    queue.pop_back();
    if (at == 0 || std::find(seen.begin(), seen.end(), at) != seen.end()) continue;
    if (seen.size() >= 64) return bad("more than 64 image directories");
    seen.push_back(at);
    detail::TiffDirectory d;
    unsigned entries = 0;
    switch (tiff.directory(at, d, &entries)) {
      case detail::Tiff::Read::ok: break;
      case detail::Tiff::Read::count_outside:
        return bad("an image directory at byte " + std::to_string(at) + " lies past its end (" + std::to_string(size) + " bytes)");
      case detail::Tiff::Read::entries_out_of_range:  // (any count is in range here)
      case detail::Tiff::Read::table_outside:
        return bad("the image directory at byte " + std::to_string(at) + " (" + std::to_string(entries) +
                   " entries) runs past its end (" + std::to_string(size) + " bytes)");
    }
    for (const detail::TiffEntry& e : d.entries) {
      const uint64_t bytes_needed = detail::Tiff::value_bytes(e);
      if (bytes_needed > 4 && static_cast<uint64_t>(e.offset) + bytes_needed > size)
        return bad("tag " + std::to_string(e.tag) + "'s " + std::to_string(e.count) + " values at byte " +
                   std::to_string(e.offset) + " run past its end (" + std::to_string(size) + " bytes)");
      if (e.tag == 0x14a && (e.type == 4 || e.type == 13) && e.count <= 64)  // SubIFDs: the full-size image of most DNGs
        for (uint32_t i = 0; i < e.count; ++i) queue.push_back(tiff.value(e, i));
    }
    queue.push_back(d.next);
  }
  return Status::success();
}

Expected<cv::Mat> decode_raw_linear(std::string_view bytes, const RawOptions& options, const std::string& name) {
  auto photo = decode_raw(bytes, options, name);
  if (!photo) return photo.error();
  return std::move(photo->image);
}

Expected<RawPhoto> decode_raw(std::string_view bytes, const RawOptions& options, const std::string& name) {
  if (Status s = options.check(); !s) return make_error(name + ": " + s.message());
  if (bytes.empty()) return make_error(name + ": empty file");
  // LibRaw is large (hundreds of kB of state): on the heap, one per call, so
  // frames decode in parallel on their own instances.
  if (Status s = check_raw_structure(bytes, name); !s) return s.error();
  auto raw = std::make_unique<LibRaw>(LIBRAW_OPTIONS_NONE);
  libraw_output_params_t& p = raw->imgdata.params;
  p.output_bps = 16;
  p.gamm[0] = 1.0;  // linear: no transfer curve
  p.gamm[1] = 1.0;
  p.no_auto_bright = 1;
  p.use_camera_wb = 1;  // the white balance the camera recorded (DNG: AsShotNeutral)
  p.use_auto_wb = 0;
  p.output_color = options.camera_space ? 0 : 1;  // the camera's RGB, or sRGB primaries; linear
  p.highlight = 0;     // clip at the white level
  // LibRaw's default (0.75) takes a frame's own data maximum as its white
  // level when that lies between 75 % and 100 % of the real one: each photo
  // with a highlight near clipping would be scaled by its own factor
  // (measured on the rig twin's DNGs: 4 of 7 frames 25-30 % too bright,
  // normals off by 12 degrees). Off: the file's white level for every frame.
  p.adjust_maximum_thr = 0.0f;
  p.half_size = options.half_size ? 1 : 0;
  p.user_qual = find_demosaic(options.demosaic)->user_qual;
  // LibRaw reads from the buffer without writing to it.
  int r = raw->open_buffer(const_cast<char*>(bytes.data()), bytes.size());
  if (r != LIBRAW_SUCCESS) return make_error(name + ": not a RAW file LibRaw can read (" + libraw_error(r) + ")");
  const auto& sizes = raw->imgdata.sizes;
  if (sizes.raw_width == 0 || sizes.raw_height == 0 ||
      static_cast<long long>(sizes.raw_width) * sizes.raw_height > kMaxRawPixels)
    return make_error(name + ": RAW size " + std::to_string(sizes.raw_width) + "x" + std::to_string(sizes.raw_height) +
                      " is empty or too large");
  if (raw->imgdata.idata.colors != 3 || raw->imgdata.idata.filters == 0)
    return make_error(name + ": only Bayer (RGB colour filter array) RAW files are supported");
  r = raw->unpack();
  if (r != LIBRAW_SUCCESS) return make_error(name + ": cannot unpack RAW data (" + libraw_error(r) + ")");
  RawPhoto photo;
  // camera RGB -> linear sRGB as LibRaw applies it (out_cam = rgb_cam for sRGB; none for a raw-colour file),
  // turned to act on BGR pixels
  if (options.camera_space && !raw->imgdata.rawdata.ioparams.raw_color)
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) photo.camera_to_srgb(2 - r, 2 - c) = raw->imgdata.color.rgb_cam[r][c];
  if (options.demosaic == Demosaic::mhc && !options.half_size) {
    if (auto mosaic = mosaic_of(*raw)) {
      if (options.camera_space) {
        for (int r = 0; r < 3; ++r)
          for (int c = 0; c < 3; ++c) mosaic->rgb_cam[r][c] = r == c ? 1.f : 0.f;
      }
      photo.image = detail::demosaic_mhc(*mosaic, options.half_floats);
      return photo;
    }
    p.user_qual = find_demosaic(Demosaic::ahd)->user_qual;  // a layout only LibRaw's pipeline takes
  }
  r = raw->dcraw_process();
  if (r != LIBRAW_SUCCESS) return make_error(name + ": cannot develop RAW data (" + libraw_error(r) + ")");
  int err = 0;
  const MemImage img(raw->dcraw_make_mem_image(&err));
  if (!img || err != LIBRAW_SUCCESS) return make_error(name + ": cannot make an image from RAW data (" + libraw_error(err) + ")");
  if (img->type != LIBRAW_IMAGE_BITMAP || img->bits != 16 || img->colors != 3 || img->width == 0 || img->height == 0)
    return make_error(name + ": LibRaw returned an unexpected image layout");
  // RGB 16-bit interleaved (native byte order) -> BGR float (or half, a row at a time), 1.0 = white level.
  cv::Mat rgb16(img->height, img->width, CV_16UC3, img->data);
  cv::Mat out(rgb16.size(), options.half_floats ? CV_16FC3 : CV_32FC3);
  std::vector<float> row(options.half_floats ? size_t(rgb16.cols) * 3 : 0);
  constexpr float k = 1.0f / 65535.0f;
  for (int y = 0; y < rgb16.rows; ++y) {
    const uint16_t* s = rgb16.ptr<uint16_t>(y);
    float* o = options.half_floats ? row.data() : out.ptr<float>(y);
    for (int x = 0; x < rgb16.cols; ++x) {
      o[3 * x + 0] = s[3 * x + 2] * k;
      o[3 * x + 1] = s[3 * x + 1] * k;
      o[3 * x + 2] = s[3 * x + 0] * k;
    }
    if (options.half_floats) cv::hal::cvt32f16f(o, out.ptr<cv::float16_t>(y), rgb16.cols * 3);
  }
  photo.image = std::move(out);
  return photo;
}

Expected<cv::Mat> read_raw_linear(const std::filesystem::path& file, const RawOptions& options) {
  auto bytes = read_file_bytes(file);
  if (!bytes) return bytes.error();
  return decode_raw_linear(*bytes, options, file.string());
}

Expected<std::string> raw_preview_jpeg(std::string_view bytes, const std::string& name) {
  if (bytes.empty()) return make_error(name + ": empty file");
  if (Status s = check_raw_structure(bytes, name); !s) return s.error();
  auto raw = std::make_unique<LibRaw>(LIBRAW_OPTIONS_NONE);
  int r = raw->open_buffer(const_cast<char*>(bytes.data()), bytes.size());
  if (r != LIBRAW_SUCCESS) return make_error(name + ": not a RAW file LibRaw can read (" + libraw_error(r) + ")");
  r = raw->unpack_thumb();
  if (r != LIBRAW_SUCCESS) return make_error(name + ": no preview LibRaw can take (" + libraw_error(r) + ")");
  int err = 0;
  const MemImage thumb(raw->dcraw_make_mem_thumb(&err));
  if (!thumb || err != LIBRAW_SUCCESS) return make_error(name + ": cannot take its preview (" + libraw_error(err) + ")");
  if (thumb->type != LIBRAW_IMAGE_JPEG) return make_error(name + ": its preview is not a JPEG");
  return std::string(reinterpret_cast<const char*>(thumb->data), thumb->data_size);
}

std::string raw_decoder_version() { return LibRaw::version(); }

}  // namespace veneer::io
