#pragma once
// Appearance transfer as the thesis shows it: two image sets in, the map and
// the destination repainted with the source's photos out (DESIGN.md: map.pfm,
// map.png), plus the reuse heat map and metrics.json.
#include <filesystem>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/io/image_io.hpp"
#include "veneer/io/imageset.hpp"
#include "veneer/match/fast.hpp"
#include "veneer/match/matcher.hpp"
#include "veneer/match/metrics.hpp"
#include "veneer/util/expected.hpp"
#include "veneer/util/progress.hpp"

namespace veneer::match {

struct TransferOptions {
  MatchOptions match;          // method, feature, patch, ...
  bool truth_normals = false;  // use truth/normals.pfm and truth/mask.png (simulated sets) instead of
                               // photometric stereo and segmentation
  double scale = 1.0;          // resize both sets first (0 < scale <= 1; 0.5 = half size)
  int blend = 2;               // repaint: blend the chunks meeting at a seam over this radius, px
                               // (0..16; 0 = each pixel its own source pixel; see repaint_blended)
  double blend_guide = 0.1;    // blend: weigh each proposal by its normal's fit, fall-off |dn| (0 = off,
                               // plain Gaussian; [0, 2]; see fast::BlendGuide); maps matched on
                               // normals only (an intensities map is blended plain)
  bool keep_pictures = true;   // transfer(): every photo repainted into result.repainted (~250 MB
                               // each at full resolution); false leaves them out, for
                               // write_transfer(result, pair, ...) to paint and write one at a time
  Status check() const;
};

// One object ready for matching, with the stage timings that produced it.
struct PreparedObject {
  ObjectView view;          // normals, mask, photos (ambient removed), lamp ids
  double segment_seconds = 0;
  double normals_seconds = 0;
};

// Resizes a set in place (photos by area, masks and truth nearest, normals
// renormalized, camera intrinsics scaled).
void scale_set(ImageSet& set, double scale);
// The size scale_set gives a set of `size`.
cv::Size scaled_size(cv::Size size, double scale);

Expected<PreparedObject> prepare_object(const ImageSet& set, bool truth_normals, const Progress& progress = {});
// Only the object's mask, as prepare_object finds it (the truth's with truth
// normals, else the segmentation's), without solving for normals.
Expected<cv::Mat> object_mask(const ImageSet& set, bool truth_normals);

struct TransferResult {
  Map map;
  cv::Size source_size;
  std::vector<cv::Mat> repainted;  // per lamp: the destination photo with the source's pasted through the map
  cv::Mat repainted_median;        // the same from the per-pixel median of all lamps
  cv::Mat reuse;                   // CV_32SC1 counts per source pixel
  cv::Mat source_median;           // the source photos' per-pixel median (backdrop of the reuse picture)
  std::optional<Quality> quality;  // when both sets carry truth
  std::optional<Relit> relit;      // the relighting measure's pictures, when measured
  std::string metrics_json;        // timings, options, sizes, quality
  double match_seconds = 0;        // the map's computation alone (wall; 0 when the map was given)
  MatchOptions match_options;      // what the map was computed with
  bool map_given = false;          // made from a map computed earlier (transfer(pair, options, map))
  std::shared_ptr<const fast::BlendPlan> blend;  // the pictures' blend weights (blend > 0), for
                                                 // repainting more photos the same way (live video)
};

Expected<TransferResult> transfer(const ImageSet& destination, const ImageSet& source,
                                  const TransferOptions& options, const Progress& progress = {});

// The same in two steps: the objects prepared once (sets scaled, segmented,
// normals), then the map and the rest. A caller that keeps the pair
// recomputes only the map when a matching option changes -- the viewer does,
// while the user drags a slider. `options` must have the pair's scale and
// truth_normals (else an error names the difference).
struct PreparedPair {
  ImageSet destination, source;  // as scaled
  PreparedObject dst, src;
  cv::Mat destination_median, source_median;  // per-pixel medians of the photos
  double scale = 1.0;
  bool truth_normals = false;
};
Expected<PreparedPair> prepare_pair(const ImageSet& destination, const ImageSet& source,
                                    const TransferOptions& options, const Progress& progress = {});
Expected<TransferResult> transfer(const PreparedPair& pair, const TransferOptions& options,
                                  const Progress& progress = {});
// The rest (repaint, reuse, quality, metrics) from a map already computed
// for this pair with options.match: what an option that does not change the
// map (the blend radius) needs, in milliseconds. A map of another size than
// the pair's destination is an error.
Expected<TransferResult> transfer(const PreparedPair& pair, const TransferOptions& options, const Map& map,
                                  const Progress& progress = {});
// The blend weights of the pictures transfer() paints through `map` with
// `options` (null when options.blend is 0): guided by the pair's normals when
// the map was matched on them and blend_guide > 0, else plain. The live view
// repaints every frame with the same plan, so frames look like the stills.
// Fails for a map of another size than the pair's destination.
Expected<std::shared_ptr<const fast::BlendPlan>> blend_plan_for(const PreparedPair& pair,
                                                                const TransferOptions& options, const Map& map);
// The options a transfer folder's metrics.json records (write_transfer), for
// redoing its pictures the same way -- TransferOptions' defaults for any it
// leaves out. Fails, naming the file and the key, when the file cannot be
// read, is not JSON, or a value has the wrong type or is out of range.
Expected<TransferOptions> read_transfer_options(const std::filesystem::path& metrics_json);
// The same from the file's text (`name` for the errors), and the options as
// such a file's text ({"options": {...}}; parse_transfer_options reads it back equal).
Expected<TransferOptions> parse_transfer_options(std::string_view text, const std::string& name);
std::string transfer_options_json(const TransferOptions& options);
// Writes map.pfm, map.png, confidence.png, result_light_NN.png, result_median.png, reuse.png,
// metrics.json (and relight_transferred.png / relight_reference.png when the
// relighting was measured) into `folder` (created when missing).
// `progress` hears the fraction of the files written (they are encoded in
// parallel, each written through a temporary and renamed, one folder fsync).
// Its cancel stops the files not yet begun (those being encoded finish) and
// the call fails saying "cancelled", without metrics.json: each file there is
// whole, and a folder without metrics.json is not a whole result.
Status write_transfer(const TransferResult& result, const std::filesystem::path& folder,
                      const Progress& progress = {});
// The same for a result made with keep_pictures = false: each of the pair's
// photos is repainted through the result's map (and blend plan) in place of
// its destination photo, written and released before the next, so the
// pictures never all exist at once. Consumes the pair: what the pictures do
// not need (normals, truth) goes first, and each photo once painted.
Status write_transfer(const TransferResult& result, PreparedPair&& pair, const std::filesystem::path& folder,
                      const Progress& progress = {});

// Quality of a map between two sets: truth masks and normals when both sets
// carry truth (else segmentation masks and no normal agreement), relighting
// PSNR when measurable. Sets are resized to the map's size first when the map
// was computed at a reduced scale (same factor for the source).
Expected<Quality> evaluate_sets(const Map& map, const ImageSet& destination, const ImageSet& source);
// The scale factor a map was computed at relative to `destination` (map width / set width).
double map_scale(const Map& map, const ImageSet& destination);

// Pieces, for the CLI, the viewer and the figures:
cv::Mat median_photo(const std::vector<cv::Mat>& photos);  // per-pixel, per-channel median
// The destination `backdrop` with the source's `photo` pasted through `map`
// (linear BGR CV_32FC3; backdrop may be empty = black).
cv::Mat repaint(const Map& map, const cv::Mat& photo, const cv::Mat& backdrop = {});
// The same with the chunks blended (StyleBlit's optional blending,
// fast::blend_repaint): each mapped pixel averages its neighbours' matches
// within `radius` px continued to it, Gaussian-weighted. Inside a chunk they
// all agree, so texture stays sharp; seams and speckle are softened.
// `source_mask` (CV_8UC1, empty = all) keeps continuations on the object.
// `guide` (optional): proposals weighed by how well their source normal fits
// the destination's, so outlines stay sharp (fast::BlendGuide).
// radius 0 = repaint(). Fails, naming it, on a radius outside 0..16 or a
// mask or guide that does not fit the photo.
Expected<cv::Mat> repaint_blended(const Map& map, const cv::Mat& photo, const cv::Mat& source_mask, int radius,
                                  const cv::Mat& backdrop = {}, const fast::BlendGuide* guide = nullptr);
// How well each match fits (8-bit BGR): white = distance 0, black = 4x the
// median distance or more, or not mapped.
cv::Mat confidence_picture(const Map& map);
// The thesis's picture of a map: R = x / width, G = y / height, B = 1 (8-bit BGR), black unmapped.
cv::Mat map_picture(const Map& map, cv::Size source_size);
// Reuse counts as a heat map over the grey source picture (8-bit BGR).
cv::Mat reuse_picture(const cv::Mat& counts, const cv::Mat& source_photo);

// The thesis's origin tool: destination (left) and source (right) side by
// side (linear photos, tonemapped), a line from each chosen destination pixel
// to its source pixel; unmapped points get a red cross.
cv::Mat origin_picture(const Map& map, const cv::Mat& destination_photo, const cv::Mat& source_photo,
                       const std::vector<cv::Point>& points);
// About `count` mapped destination pixels spread over the object (a grid), for origin_picture.
std::vector<cv::Point> spread_points(const Map& map, int count);

// map.pfm (x, y, distance; -1 unmapped) in and out.
Status write_map(const std::filesystem::path& file, const Map& map, Sync sync = Sync::each);
Expected<Map> read_map(const std::filesystem::path& file);

}  // namespace veneer::match
