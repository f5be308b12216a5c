// veneer relight: the repainted destination's relightable look, the fit the
// web page shows (repaint/web_export.hpp), drawn at a light as the page draws
// it, from the transfer's repainted photos, not from the page's files.
#include <cstdio>

#include "veneer/io/codecs.hpp"

#include "command.hpp"
#include "inputs.hpp"
#include "output.hpp"
#include "veneer/io/image_io.hpp"
#include "veneer/io/imageset.hpp"
#include "veneer/repaint/web_export.hpp"

namespace veneer::cli {
namespace {

struct RelightArgs {
  std::string transfer, dst, out;
  std::vector<double> light;
  int web_size = repaint::WebExportOptions{}.max_side;
  int hsh_order = 0;
};

::veneer::cli::Output report{"relight"};

int run(const RelightArgs& a) {
  if (a.light.size() != 2) return report.usage("--light takes x,y (x right, y up, in the unit disc)");
  repaint::WebExportOptions options;
  options.max_side = a.web_size;
  options.order = a.hsh_order;
  if (auto s = options.check(); !s) return report.usage(s.message());
  io::ReadOptions manifest;
  manifest.load_photos = false;
  manifest.load_truth = false;
  auto set = io::read_set(a.dst, manifest);
  if (!set) return report.fail(set.message());
  std::vector<cv::Vec3d> directions;
  for (const io::Light& l : set->lights) directions.push_back(l.direction);
  auto photos = read_result_photos(a.transfer, directions.size(), a.web_size);
  if (!photos) return report.fail(photos.message());
  auto fit = repaint::fit_web(*photos, directions, options);
  if (!fit) return report.fail(fit.message());
  const cv::Vec3d d = repaint::web_light(a.light[0], a.light[1]);
  std::vector<uchar> png;
  if (!veneer::io::codecs::imencode(".png", repaint::render_web(*fit, d), png)) return report.fail("the PNG encoder failed");
  if (auto s = io::write_file_atomic(a.out, std::string(png.begin(), png.end())); !s) return report.fail(s.message());
  report.line("relit " + a.transfer + " at light (" + std::to_string(d[0]) + ", " + std::to_string(d[1]) + ", " +
              std::to_string(d[2]) + "): " + std::to_string(fit->size.width) + "x" + std::to_string(fit->size.height) +
              ", HSH " + std::to_string(repaint::hsh_terms(fit->hsh.order)) + " terms, exposure " +
              std::to_string(fit->exposure) + ", written to " + a.out);
  return 0;
}

}  // namespace
}  // namespace veneer::cli

VENEER_ARGS_COMMAND(relight, veneer::cli::RelightArgs,
                    "the repainted destination's relightable look (the web page's fit) drawn at a light, as a PNG") {
  cmd->add_option("--transfer", args->transfer, "a transfer's output folder (its result_light_NN.png)")->required();
  cmd->add_option("--dst", args->dst, "the destination image set it was made for (its lamps)")->required();
  cmd->add_option("--light", args->light, "x,y: the light as the web page takes it (x right, y up, the unit disc)")
      ->required()
      ->delimiter(',')
      ->expected(2);
  cmd->add_option("--out", args->out, "the picture (8-bit sRGB PNG, as the page shows it)")->required();
  cmd->add_option("--web-size", args->web_size, "as veneer transfer --web-size: the look's longer side at most this, px")
      ->capture_default_str();
  cmd->add_option("--hsh-order", args->hsh_order, "as veneer transfer --hsh-order (0 = automatic)")->capture_default_str();
  return [args] { return veneer::cli::run(*args); };
}
