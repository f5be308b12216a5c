// The web page of the look (web_export.hpp).
#include "veneer/repaint/web_export.hpp"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <csetjmp>
#include <cstdio>
#include <cstdlib>
#include <limits>

#include <jpeglib.h>

#include <nlohmann/json.hpp>
#include <opencv2/core/utility.hpp>
#include "veneer/io/codecs.hpp"
#include <opencv2/imgproc.hpp>

#include "veneer/io/image_io.hpp"
#include "veneer/repaint/rti_export.hpp"
#include "web_page.hpp"

namespace veneer::repaint {
namespace fs = std::filesystem;

namespace {

// The captured lamp the page opens at: the one nearest the upper left, the
// light painters and photographers show things in.
cv::Vec2d first_light_of(const std::vector<cv::Vec3d>& lamps) {
  cv::Vec2d best(0, 0);
  double score = -std::numeric_limits<double>::max();
  for (const cv::Vec3d& d : lamps) {
    const double s = -d[0] + d[1];
    if (s > score) score = s, best = cv::Vec2d(d[0], d[1]);
  }
  return best;
}

// libjpeg's errors end the encode here instead of the process.
struct JpegError {
  jpeg_error_mgr mgr;
  std::jmp_buf jump;
};
[[noreturn]] void jpeg_fail(j_common_ptr cinfo) { std::longjmp(reinterpret_cast<JpegError*>(cinfo->err)->jump, 1); }

// A baseline JPEG stored as RGB (no YCbCr transform, no chroma subsampling,
// as Relight writes its planes): a plane's three channels are three colours'
// coefficients, whose differences YCbCr's halved chroma would blur. Browsers,
// Relight and OpenLIME read such files (the Adobe marker says RGB).
Expected<std::string> encode_jpeg(const cv::Mat& bgr8, int quality, const std::string& what) {
  cv::Mat rgb;
  cv::cvtColor(bgr8, rgb, cv::COLOR_BGR2RGB);
  jpeg_compress_struct cinfo{};
  JpegError err{};
  cinfo.err = jpeg_std_error(&err.mgr);
  err.mgr.error_exit = jpeg_fail;
  unsigned char* buffer = nullptr;
  unsigned long size = 0;
  if (setjmp(err.jump)) {
    jpeg_destroy_compress(&cinfo);
    std::free(buffer);
    return make_error(what + ": the JPEG encoder failed");
  }
  jpeg_create_compress(&cinfo);
  jpeg_mem_dest(&cinfo, &buffer, &size);
  cinfo.image_width = static_cast<JDIMENSION>(rgb.cols);
  cinfo.image_height = static_cast<JDIMENSION>(rgb.rows);
  cinfo.input_components = 3;
  cinfo.in_color_space = JCS_RGB;
  jpeg_set_defaults(&cinfo);
  jpeg_set_colorspace(&cinfo, JCS_RGB);
  jpeg_set_quality(&cinfo, quality, TRUE);
  cinfo.optimize_coding = TRUE;
  jpeg_start_compress(&cinfo, TRUE);
  while (cinfo.next_scanline < cinfo.image_height) {
    JSAMPROW row = rgb.ptr<uchar>(static_cast<int>(cinfo.next_scanline));
    jpeg_write_scanlines(&cinfo, &row, 1);
  }
  jpeg_finish_compress(&cinfo);
  std::string out(reinterpret_cast<const char*>(buffer), size);
  jpeg_destroy_compress(&cinfo);
  std::free(buffer);
  return out;
}

// A folder this export may replace: empty, or a page it wrote.
bool replaceable(const fs::path& folder) {
  std::error_code ec;
  if (!fs::exists(folder, ec)) return true;
  if (!fs::is_directory(folder, ec)) return false;
  if (fs::is_empty(folder, ec)) return true;
  return fs::exists(folder / "index.html", ec) && fs::exists(folder / "look.js", ec);
}

}  // namespace

Status check_web_folder(const fs::path& folder) {
  if (folder.empty()) return make_error("web page: no folder named");
  if (!replaceable(folder))
    return make_error(folder.string() + " exists and is not a web page Veneer wrote (index.html and look.js); name a new or empty folder");
  return Status::success();
}

Status WebExportOptions::check() const {
  if (max_side < 0 || (max_side > 0 && max_side < 16)) return make_error("web page: max_side must be 0 (full size) or at least 16 px");
  if (order < 0 || order > 3) return make_error("web page: order must be 1..3 (0 = automatic)");
  if (!std::isfinite(exposure) || exposure < 0) return make_error("web page: exposure must be a finite gain >= 0 (0 = automatic)");
  if (jpeg_quality < 50 || jpeg_quality > 100) return make_error("web page: JPEG quality must be 50..100");
  return Status::success();
}

cv::Size web_size(cv::Size full, int max_side) {
  const int longer = std::max(full.width, full.height);
  if (max_side <= 0 || longer <= max_side) return full;
  const double f = static_cast<double>(max_side) / longer;
  return {std::max(1, static_cast<int>(std::lround(full.width * f))), std::max(1, static_cast<int>(std::lround(full.height * f)))};
}

cv::Vec3d web_light(double x, double y) {
  const double r = std::hypot(x, y);
  if (r > 1) x /= r, y /= r;
  return {x, y, std::sqrt(std::max(0.0, 1 - x * x - y * y))};
}

Expected<WebFit> fit_web(const std::vector<cv::Mat>& photos, const std::vector<cv::Vec3d>& directions,
                         const WebExportOptions& options, const Progress& progress) {
  if (Status s = options.check(); !s) return s.error();
  if (photos.empty() || directions.empty()) return make_error("web page: no lamps (no photos or no lamp directions)");
  if (photos.size() != directions.size())
    return make_error("web page: " + std::to_string(photos.size()) + " photos but " + std::to_string(directions.size()) +
                      " lamp directions");
  const cv::Size size = photos[0].size();
  for (size_t i = 0; i < photos.size(); ++i)
    if (photos[i].type() != CV_32FC3 || photos[i].size() != size || size.area() == 0)
      return make_error("web page: photo " + std::to_string(i) + " is not a linear CV_32FC3 photo of the first's size");
  WebFit fit;
  fit.full_size = size;
  fit.size = web_size(size, options.max_side);
  const int order = options.order > 0 ? options.order : hsh_order_for(photos.size());
  progress.report(0.0, "web page: fitting");
  // the photos at the look's size (area averaging, in linear light), then as the page shows them, 0..1
  std::vector<cv::Mat> reduced(photos.size());
  cv::parallel_for_(cv::Range(0, static_cast<int>(photos.size())), [&](const cv::Range& r) {
    for (int i = r.start; i < r.end; ++i) {
      const size_t k = static_cast<size_t>(i);
      if (photos[k].size() == fit.size)
        reduced[k] = photos[k];
      else
        cv::resize(photos[k], reduced[k], fit.size, 0, 0, cv::INTER_AREA);
    }
  });
  fit.exposure = options.exposure > 0 ? options.exposure : rti_auto_exposure(reduced);
  std::vector<cv::Mat> display(photos.size());
  for (size_t i = 0; i < photos.size(); ++i) display[i] = ptm_display(reduced[i], fit.exposure) / 255.0;
  reduced.clear();
  if (progress.cancelled()) return make_error("web page: cancelled");
  for (const cv::Vec3d& d : directions) fit.lamps.push_back(d / std::max(1e-12, cv::norm(d)));
  auto hsh = fit_hsh(display, directions, order);
  if (!hsh) return make_error("web page: " + hsh.message());
  fit.hsh = std::move(hsh).value();
  // Lamps on one cone around the camera (a ring rig's) leave the terms that vary with theta alone (H2,
  // H6) undetermined: the least-norm fit splits each pixel's constant between them and H0. Folded into
  // H0 here (the same values at every lamp), the light's height changes nothing the lamps did not show,
  // and their planes are constant (a few hundred bytes each).
  double cos_lo = 1, cos_hi = 0;
  for (const cv::Vec3d& d : fit.lamps) cos_lo = std::min(cos_lo, d[2]), cos_hi = std::max(cos_hi, d[2]);
  if (cos_hi - cos_lo < 1e-3 && fit.hsh.order >= 2) {
    const std::vector<double> ring = hsh_basis(fit.lamps[0], fit.hsh.order);
    const int t = hsh_terms(fit.hsh.order);
    for (cv::Mat& c : fit.hsh.coefficients)
      for (int y = 0; y < c.rows; ++y) {
        float* p = c.ptr<float>(y);
        for (int x = 0; x < c.cols; ++x)
          for (int k : {2, 6}) {
            if (k >= t) continue;
            p[x * t] += static_cast<float>(p[x * t + k] * ring[static_cast<size_t>(k)] / ring[0]);
            p[x * t + k] = 0;
          }
      }
  }
  progress.report(0.5, "web page: fitting");
  return fit;
}

cv::Mat render_web(const WebFit& fit, const cv::Vec3d& direction) {
  const cv::Mat v = evaluate_hsh(fit.hsh, direction);
  cv::Mat out(v.size(), CV_8UC3);
  for (int y = 0; y < v.rows; ++y) {
    const float* s = v.ptr<float>(y);
    uchar* o = out.ptr<uchar>(y);
    for (int x = 0; x < v.cols * 3; ++x) o[x] = static_cast<uchar>(std::lround(std::clamp(s[x], 0.0f, 1.0f) * 255.0f));
  }
  return out;
}

std::string WebExport::json() const {
  nlohmann::ordered_json j;
  j["width"] = size.width;
  j["height"] = size.height;
  j["terms"] = terms;
  j["exposure"] = exposure;
  j["first_light"] = {first_light[0], first_light[1]};
  j["folder_bytes"] = folder_bytes;
  return j.dump();
}

Expected<WebExport> export_web(const std::vector<cv::Mat>& photos, const std::vector<cv::Vec3d>& directions,
                               const fs::path& folder_in, const WebExportOptions& options, const Progress& progress) {
  const fs::path folder = folder_in.has_filename() ? folder_in : folder_in.parent_path();
  const std::string name = folder.string();
  if (Status s = check_web_folder(folder); !s) return s.error();
  auto fitted = fit_web(photos, directions, options, progress.part(0, 0.6));
  if (!fitted) return make_error(name + ": " + fitted.message());
  const WebFit& fit = *fitted;
  const int terms = hsh_terms(fit.hsh.order);
  const int w = fit.size.width, h = fit.size.height;

  // Planes: term K's coefficients of R, G, B in plane_K.jpg's R, G, B, each
  // colour of each term quantised over its own range: coefficient = (byte / 255 - bias) * scale.
  std::vector<double> scale(static_cast<size_t>(3 * terms)), bias(static_cast<size_t>(3 * terms));
  std::vector<std::string> plane_bytes;
  for (int k = 0; k < terms; ++k) {
    cv::Mat plane(fit.size, CV_8UC3);
    for (int c = 0; c < 3; ++c) {  // c: R, G, B; the fit's Mats and the plane's channels are B, G, R
      const cv::Mat& coef = fit.hsh.coefficients[static_cast<size_t>(2 - c)];
      // the range of the middle 99.8 %: the few pixels beyond (highlights' and outlines' extremes) are
      // clamped, and the bytes' steps over the rest are finer (the planes' JPEG error scales with them)
      std::vector<float> values;
      values.reserve(static_cast<size_t>(w) * h);
      for (int y = 0; y < h; ++y) {
        const float* p = coef.ptr<float>(y);
        for (int x = 0; x < w; ++x) values.push_back(p[x * terms + k]);
      }
      const size_t n = values.size(), at_lo = n / 1000, at_hi = n - 1 - n / 1000;
      std::nth_element(values.begin(), values.begin() + static_cast<long>(at_lo), values.end());
      const float lo = values[at_lo];
      std::nth_element(values.begin(), values.begin() + static_cast<long>(at_hi), values.end());
      const float hi = values[at_hi];
      const double range = std::max(1e-6, static_cast<double>(hi) - lo);
      const size_t p = static_cast<size_t>(3 * k + c);
      scale[p] = range;
      bias[p] = -lo / range;
      for (int y = 0; y < h; ++y) {
        const float* s = coef.ptr<float>(y);
        uchar* o = plane.ptr<uchar>(y);
        for (int x = 0; x < w; ++x)
          o[x * 3 + 2 - c] = static_cast<uchar>(std::clamp<long>(std::lround((s[x * terms + k] - lo) / range * 255.0), 0, 255));
      }
    }
    auto jpeg = encode_jpeg(plane, options.jpeg_quality, name + ": plane " + std::to_string(k));
    if (!jpeg) return jpeg.error();
    plane_bytes.push_back(std::move(jpeg).value());
    progress.report(0.6 + 0.3 * (k + 1) / terms, "web page: planes");
    if (progress.cancelled()) return make_error(name + ": cancelled");
  }

  WebExport out;
  out.size = fit.size;
  out.terms = terms;
  out.exposure = fit.exposure;
  out.first_light = first_light_of(fit.lamps);
  // the still is a picture like any photo: a plain JPEG (YCbCr, chroma halved) is a fifth of an RGB one
  std::vector<uchar> still;
  if (!veneer::io::codecs::imencode(".jpg", render_web(fit, web_light(out.first_light[0], out.first_light[1])), still,
                    {cv::IMWRITE_JPEG_QUALITY, options.jpeg_quality}))
    return make_error(name + ": still.jpg: the JPEG encoder failed");

  std::vector<double> lights;
  for (const cv::Vec3d& d : fit.lamps) lights.insert(lights.end(), {d[0], d[1], d[2]});
  // Relight's web layout (Rti::load, OpenLIME's LayerRTI)
  nlohmann::ordered_json info;
  info["width"] = w;
  info["height"] = h;
  info["format"] = "jpg";
  info["type"] = "hsh";
  info["colorspace"] = "rgb";
  info["nplanes"] = 3 * terms;
  info["quality"] = options.jpeg_quality;
  info["lights"] = lights;
  info["materials"] = nlohmann::ordered_json::array({{{"scale", scale}, {"bias", bias}}});
  // ours: where the look came from
  info["veneer"] = {{"object", options.object},     {"material", options.material},
                    {"exposure", fit.exposure},     {"full_width", fit.full_size.width},
                    {"full_height", fit.full_size.height}, {"hsh_order", fit.hsh.order}};
  // what the page reads: the same numbers, and the planes as data: URLs
  nlohmann::ordered_json look;
  look["width"] = w;
  look["height"] = h;
  look["terms"] = terms;
  look["scale"] = scale;
  look["bias"] = bias;
  look["lights"] = lights;
  look["first_light"] = {out.first_light[0], out.first_light[1]};
  look["object"] = options.object;
  look["material"] = options.material;
  std::vector<std::string> urls;
  for (const std::string& b : plane_bytes) urls.push_back("data:image/jpeg;base64," + web::base64(b));
  look["planes"] = urls;

  // written into a temporary sibling, renamed into place
  const fs::path temp = folder.parent_path() / ("." + folder.filename().string() + ".part-" + std::to_string(::getpid()));
  std::error_code ec;
  fs::remove_all(temp, ec);
  fs::create_directories(temp, ec);
  if (ec) return make_error(name + ": cannot make " + temp.string() + ": " + ec.message());
  auto fail = [&](const std::string& message) -> Expected<WebExport> {
    std::error_code ignored;
    fs::remove_all(temp, ignored);
    return make_error(message);
  };
  std::vector<std::pair<std::string, std::string>> files;
  for (size_t k = 0; k < plane_bytes.size(); ++k) files.emplace_back("plane_" + std::to_string(k) + ".jpg", plane_bytes[k]);
  files.emplace_back("info.json", info.dump(1) + "\n");
  files.emplace_back("still.jpg", std::string(still.begin(), still.end()));
  files.emplace_back("look.js", "// The look the page shows (Veneer): the fit's numbers and its planes.\nwindow.VENEER_LOOK = " +
                                    look.dump() + ";\n");
  files.emplace_back("index.html", web::index_html(options.object, options.material, w, h));
  for (const auto& [file, bytes] : files) {
    if (progress.cancelled()) return fail(name + ": cancelled");
    if (Status s = io::write_file_synced(temp / file, bytes); !s) return fail(name + ": " + s.message());
    out.folder_bytes += bytes.size();
  }
  if (Status s = io::sync_folder(temp); !s) return fail(name + ": " + s.message());
  if (fs::exists(folder, ec)) {
    const fs::path old = folder.parent_path() / ("." + folder.filename().string() + ".old-" + std::to_string(::getpid()));
    fs::remove_all(old, ec);
    fs::rename(folder, old, ec);
    if (ec) return fail(name + ": cannot move the old page aside: " + ec.message());
    fs::rename(temp, folder, ec);
    if (ec) {
      std::error_code ignored;
      fs::rename(old, folder, ignored);
      return fail(name + ": cannot move the page into place: " + ec.message());
    }
    fs::remove_all(old, ec);
  } else {
    fs::rename(temp, folder, ec);
    if (ec) return fail(name + ": cannot move the page into place: " + ec.message());
  }
  progress.report(1.0, "web page");
  return out;
}

}  // namespace veneer::repaint
