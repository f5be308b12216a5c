#pragma once
// Appearance transfer as the thesis shows it, end to end (matching, repaint,
// quality): two image sets in, the map and
// the destination repainted with the source's photos out (DESIGN.md: map.pfm,
// map.png), plus the reuse heat map and metrics.json.
#include <filesystem>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/eval/metrics.hpp"
#include "veneer/io/image_io.hpp"
#include "veneer/io/imageset.hpp"
#include "veneer/match/fast.hpp"
#include "veneer/match/map_file.hpp"
#include "veneer/match/matcher.hpp"
#include "veneer/match/object.hpp"
#include "veneer/repaint/live_look.hpp"
#include "veneer/repaint/look.hpp"
#include "veneer/repaint/repaint.hpp"
#include "veneer/util/expected.hpp"
#include "veneer/util/progress.hpp"

namespace veneer::pipeline {

using match::Map;
using match::MatchOptions;
using match::PreparedObject;
namespace fast = match::fast;

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
  repaint::Look look = repaint::Look::shaded;  // how the pictures are painted: shaded (the default: the
                               // source's texture through the map, each lamp shading it as it shades the
                               // destination, the source's gloss placed by the destination's normals;
                               // repaint/look.hpp) | copy (each lamp's source photo pasted, blended)
  repaint::LookOptions look_options;  // the shaded look's
  bool keep_pictures = true;   // transfer(): every photo repainted into result.repainted (~250 MB
                               // each at full resolution); false leaves them out, for
                               // write_transfer(result, pair, ...) to paint and write one at a time
  int refine_from_width = 0;   // when the destination is wider: the map computed with `match` on both
                               // objects reduced to this width, then refined to full resolution
                               // (match::refine_map: continued, and the nearest normal within 1 px),
                               // and its coherence measured at the width it was made at; 0 = the map
                               // computed at full resolution (the default); else 64..8192 px
  bool look_when_written = false;  // with keep_pictures false (and no look_floor): metrics.json's "look"
                               // is measured by write_transfer(result, pair, ...) from the pictures it
                               // paints, not by transfer() painting them all once more in grey (at
                               // 5600x3750 that second painting was 33 s of the CLI's 88); until then
                               // result.look_pending says it is missing. Off by default.
  // metrics.json's "look" (eval/look.hpp) is always measured against the
  // destination's own photos (its cost: the pictures in grey, and painted once
  // more when not kept); on a simulated pair also against the truth look (the
  // destination's scene rendered in the source's material: one set rendered).
  bool look_figures = true;    // metrics.json's "look" measured at all; false leaves it out (and its cost:
                               // at 5600x3750 12 s of `veneer transfer`'s 59, issue 48) -- the CLI's
                               // default, `veneer transfer --figures` asks for it. look_floor implies it.
  bool look_floor = false;     // also the floor: the `linear` map's pixel copy scored the same way, and
                               // the ratio shading / floor (a second match and repaint)
  Status check() const;
};


// The matching the product's default transfer runs (the CLI's, the viewer's
// and `make demo`'s defaults): `combined`, whose chunks of the nearest
// normals may err by up to 0.6 with the shaded look -- large chunks keep the
// source's texture whole, the look puts the shading right (bull <- orange
// 512x340: coherence 0.92, shading error 0.45x the linear map's pixel copy)
// -- and by the matcher's 0.10 with the copy look, whose shading is the
// chunks' own.
MatchOptions default_match_options(repaint::Look look = repaint::Look::shaded);
// The whole default transfer for `look`: TransferOptions' defaults with
// default_match_options(look). What `veneer transfer` starts from before its
// flags and what the viewer's default preset shows, so both give one answer.
TransferOptions default_transfer_options(repaint::Look look = repaint::Look::shaded);

struct TransferResult {
  Map map;
  cv::Size source_size;
  std::vector<cv::Mat> repainted;  // per lamp: the destination photo with the source's pasted through the map
  cv::Mat repainted_median;        // the same from the per-pixel median of all lamps
  cv::Mat reuse;                   // CV_32SC1 counts per source pixel
  cv::Mat source_median;           // the source photos' per-pixel median (backdrop of the reuse picture)
  std::optional<eval::Quality> quality;  // when both sets carry truth
  std::optional<eval::Relit> relit;      // the relighting measure's pictures, when measured
  std::string metrics_json;        // timings, options, sizes, quality
  double match_seconds = 0;        // the map's computation alone (wall; 0 when the map was given)
  MatchOptions match_options;      // what the map was computed with
  bool map_given = false;          // made from a map computed earlier (transfer(pair, options, map))
  std::shared_ptr<const fast::BlendPlan> blend;  // the pictures' blend weights (blend > 0), for
                                                 // repainting more photos the same way (live video)
  std::shared_ptr<const repaint::ShadedLook> look;  // what painted the pictures (look shaded; null for copy)
  bool look_pending = false;       // metrics_json's "look" is left to write_transfer(result, pair, ...)
                                   // (TransferOptions::look_when_written)
};

Expected<TransferResult> transfer(const io::ImageSet& destination, const io::ImageSet& source,
                                  const TransferOptions& options, const Progress& progress = {});

// The same in two steps: the objects prepared once (sets scaled, segmented,
// normals), then the map and the rest. A caller that keeps the pair
// recomputes only the map when a matching option changes -- the viewer does,
// while the user drags a slider. `options` must have the pair's scale and
// truth_normals (else an error names the difference).
struct PreparedPair {
  io::ImageSet destination, source;  // as scaled
  PreparedObject dst, src;
  cv::Mat destination_median, source_median;  // per-pixel medians of the photos (of their type: half
                                              // floats from prepare_pair with PrepareOptions::half_photos)
  double scale = 1.0;
  bool truth_normals = false;
};
Expected<PreparedPair> prepare_pair(const io::ImageSet& destination, const io::ImageSet& source,
                                    const TransferOptions& options, const Progress& progress = {});
Expected<TransferResult> transfer(const PreparedPair& pair, const TransferOptions& options,
                                  const Progress& progress = {});
// The same for a pair whose truth the caller gives up (the CLI, which
// writes the result with write_transfer(result, pair) next): the quality
// against the truth is measured right after the map and both sets' truth
// released then, before the look is made (issue 48: at 5600x3750 their
// normals, 0.5 GB, held through the look made the transfer's peak). Only
// when nothing later reads the truth (no look_figures, no look_floor, no
// relighting measure); else it is transfer(pair, ...). The result is the same.
Expected<TransferResult> transfer_releasing_truth(PreparedPair& pair, const TransferOptions& options,
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
// The shaded look of `map` for the pair (options.look_options), what
// transfer() paints the pictures with when options.look is shaded.
Expected<std::shared_ptr<const repaint::ShadedLook>> shaded_look(const PreparedPair& pair,
                                                                 const TransferOptions& options, const Map& map,
                                                                 const Progress& progress = {});
// What the live view paints each frame with at its light (repaint/live_look.hpp,
// issue 40): the live look of `map` for the pair, made from `still` (the
// shaded look of this map, e.g. TransferResult::look; computed when null)
// and the pair's lamps (the source's positions when every lamp has one).
// Fails as ShadedLook::make and LiveLook::make do; "cancelled" on progress.
Expected<std::shared_ptr<const repaint::LiveLook>> live_look(
    const PreparedPair& pair, const TransferOptions& options, const Map& map,
    std::shared_ptr<const repaint::ShadedLook> still = nullptr,
    const repaint::LiveLookOptions& live_options = {}, const Progress& progress = {});
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
// not need (normals, truth) goes first, and each photo once painted; once
// every picture is painted, result.look is released too. With
// result.look_pending, the look is measured from the pictures as they are
// painted (each kept in grey) and written into result.metrics_json too.
Status write_transfer(TransferResult& result, PreparedPair&& pair, const std::filesystem::path& folder,
                      const Progress& progress = {});

// Quality of a map between two sets: truth masks and normals when both sets
// carry truth (else segmentation masks and no normal agreement), relighting
// PSNR when measurable. Sets are resized to the map's size first when the map
// was computed at a reduced scale (same factor for the source).
Expected<eval::Quality> evaluate_sets(const Map& map, const io::ImageSet& destination, const io::ImageSet& source);
// The scale factor a map was computed at relative to `destination` (map width / set width).
double map_scale(const Map& map, const io::ImageSet& destination);


}  // namespace veneer::pipeline
