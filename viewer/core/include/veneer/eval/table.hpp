#pragma once
// The quality table of the thesis pairs: simulated sets, every chosen method
// x feature x patch, measured against the simulator's truth.
#include <string>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/eval/metrics.hpp"
#include "veneer/io/imageset.hpp"
#include "veneer/match/matcher.hpp"
#include "veneer/sim/simulator.hpp"
#include "veneer/util/expected.hpp"
#include "veneer/util/progress.hpp"

namespace veneer::eval {

using match::ObjectView;

// The quality table of the thesis pairs (issue 3): simulated sets at a reduced
// size, every chosen method x feature x patch.
struct TableOptions {
  cv::Size size{512, 340};     // render size of both sets [px] (the faithful methods are slow at 1024x680)
  std::vector<std::pair<std::string, std::string>> pairs;  // (destination, source); empty = the eight of issue 3
  bool full = false;           // false: a chosen subset of rows per pair (fits a bench); true: all combinations
  bool truth_normals = false;  // match on true normals instead of photometric stereo
  double noise = 0.005;        // sensor noise of the simulated sets (fraction of full scale; `veneer simulate`'s default)
  int threads = 0;             // 0 = all cores
  bool include_fast = true;    // add rows of the fast engine where it serves
};
struct TableRow {
  std::string destination, source, method, feature, engine;  // engine: "faithful" | "fast"
  int patch = 1, candidates = 0;
  double threshold = 0;
  int destination_pixels = 0, source_pixels = 0;
  Quality quality;
  double seconds = 0;  // compute_map wall time
  std::string error;   // non-empty when the run failed
};
// One object of the quality table, simulated and prepared as the table does
// it for `options` (size, noise, threads, normals from the truth or from
// photometric stereo); second = the moved, smaller second capture a pair of
// an object with itself takes as its source (second_capture()).
struct TableObject {
  io::ImageSet set;
  ObjectView view;
};
Expected<TableObject> table_object(const std::string& scene, bool second, const TableOptions& options);
std::vector<std::pair<std::string, std::string>> thesis_pairs();
// A pair of one object with itself (blocks -> blocks) compares two captures:
// the source's is moved in the frame and made smaller, like a second shot.
void second_capture(sim::RenderOptions& options);
Expected<std::vector<TableRow>> quality_table(const TableOptions& options, const Progress& progress = {});
std::string format_table(const std::vector<TableRow>& rows, const TableOptions& options);

}  // namespace veneer::eval
