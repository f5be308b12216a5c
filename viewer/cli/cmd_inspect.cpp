// veneer inspect: the thesis's origin tool — lines from destination pixels to
// the source pixels the map took their appearance from.
#include <cstdio>
#include <iostream>
#include <sstream>

#include "command.hpp"
#include "inputs.hpp"
#include "output.hpp"
#include "veneer/io/image_io.hpp"
#include "veneer/io/imageset.hpp"
#include "veneer/pipeline/transfer.hpp"

namespace veneer::cli {
namespace {

struct InspectArgs {
  std::string dst, src, map, out, points;
  int count = 16;
};

::veneer::cli::Output report{"inspect"};

int run(const InspectArgs& a) {
  auto in = read_map_inputs(a.dst, a.src, a.map);
  if (!in) return report.fail(in.message());
  io::ImageSet& dst = in->dst;
  io::ImageSet& src = in->src;
  const match::Map& map = in->map;
  const double scale = pipeline::map_scale(map, dst);
  if (!(scale > 0 && scale <= 1.0001)) return report.fail("the map is wider than the destination set");
  match::scale_set(dst, scale);
  match::scale_set(src, scale);
  std::vector<cv::Point> points;
  if (!a.points.empty()) {
    std::stringstream ss(a.points);
    std::string item;
    while (std::getline(ss, item, ';')) {
      int x = 0, y = 0;
      char comma = 0;
      std::stringstream is(item);
      if (!(is >> x >> comma >> y) || comma != ',')
        return report.usage("--points wants 'x,y;x,y;...', could not read '" + item + "'");
      points.emplace_back(static_cast<int>(x * scale), static_cast<int>(y * scale));
    }
  } else {
    points = repaint::spread_points(map, a.count);
  }
  const cv::Mat picture =
      repaint::origin_picture(map, repaint::median_photo(dst.images), repaint::median_photo(src.images), points);
  if (auto s = report.picture(a.out, picture); !s) return report.fail(s.message());
  for (const cv::Point p : points) {
    if (p.x >= 0 && p.y >= 0 && p.x < map.xy.cols && p.y < map.xy.rows && map.valid(p.x, p.y)) {
      const cv::Vec2f m = map.xy.at<cv::Vec2f>(p);
      std::printf("(%d, %d) <- (%.0f, %.0f)  distance %.4f\n", p.x, p.y, m[0], m[1], map.distance.at<float>(p));
    } else {
      std::printf("(%d, %d) not mapped\n", p.x, p.y);
    }
  }
  return 0;
}

}  // namespace
}  // namespace veneer::cli

VENEER_ARGS_COMMAND(inspect, veneer::cli::InspectArgs,
                    "side-by-side picture with lines from destination pixels to their source") {
  veneer::cli::add_map_inputs(cmd, args->dst, args->src, args->map, true);
  cmd->add_option("--out", args->out, "picture to write (PNG)")->required();
  cmd->add_option("--points", args->points, "destination pixels 'x,y;x,y;...' in the set's pixels (default: a grid)");
  cmd->add_option("--count", args->count, "how many grid points when --points is not given (default 16)");
  return [args] { return veneer::cli::run(*args); };
}
