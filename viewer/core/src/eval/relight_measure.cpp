// The relighting measure (metrics.hpp): the source under an extra lamp carried
// through a map, against the destination's shape rendered in the source's material.
#include <vector>

#include "veneer/eval/metrics.hpp"
#include "veneer/repaint/repaint.hpp"
#include "veneer/sim/simulator.hpp"

namespace veneer::eval {

using match::Map;
namespace fast = match::fast;

namespace {

sim::RenderOptions render_options_for(const io::ImageSet& set) {
  sim::RenderOptions o;
  o.size = set.size;
  o.focal_px = set.camera.focal_px;
  return o;
}

}  // namespace

Expected<RelightScenes> relight_scenes(const io::ImageSet& destination, const io::ImageSet& source) {
  if (!relight_measurable(source.scene))
    return make_error("relighting is measured with a source of uniform material (sphere-red-gloss, sphere-gray), not '" +
                      source.scene + "'");
  if (destination.scene.empty()) return make_error("the destination set is not simulated (no scene name)");
  const std::vector<sim::Lamp> lamp{sim::Lamp{relight_lamp_position(), {1, 1, 1}, 1.0f}};
  const auto src_options = render_options_for(source);
  auto src_scene = sim::make_scene(source.scene, src_options);
  if (!src_scene) return src_scene.error();
  RelightScenes out;
  out.lit_source = sim::render(**src_scene, lamp, src_options);
  const auto dst_options = render_options_for(destination);
  auto reference_scene = sim::make_scene_with_material(destination.scene, source.scene, dst_options);
  if (!reference_scene) return reference_scene.error();
  out.reference = sim::render(**reference_scene, lamp, dst_options);
  auto unshadowed_options = dst_options;
  unshadowed_options.cast_shadows = false;
  const cv::Mat unshadowed = sim::render(**reference_scene, lamp, unshadowed_options);
  if (out.lit_source.empty() || out.reference.empty() || unshadowed.empty())
    return make_error("rendering the relighting reference failed");
  cv::Mat differs;
  cv::compare(cv::abs(out.reference - unshadowed), cv::Scalar::all(1e-6), differs, cv::CMP_GT);
  cv::transform(differs, out.shadowed, cv::Matx13f(1, 1, 1));
  return out;
}

Expected<Relit> relight(const Map& map, const RelightScenes& scenes, const cv::Mat& source_mask,
                        const cv::Mat& destination_mask, int blend, const fast::BlendGuide* guide) {
  Relit out;
  out.reference = scenes.reference;
  out.lit = destination_mask.clone();
  out.lit.setTo(0, scenes.shadowed);
  auto transferred = repaint::repaint_blended(map, scenes.lit_source, source_mask, blend, {}, guide);
  if (!transferred) return transferred.error();
  out.transferred = std::move(*transferred);
  out.psnr_db = psnr(out.transferred, out.reference, destination_mask);
  out.psnr_lit_db = psnr(out.transferred, out.reference, out.lit);
  return out;
}

Expected<Relit> relight(const Map& map, const io::ImageSet& destination, const io::ImageSet& source,
                        const cv::Mat& destination_mask, int blend, const fast::BlendGuide* guide) {
  auto scenes = relight_scenes(destination, source);
  if (!scenes) return scenes.error();
  return relight(map, *scenes, source.truth.mask, destination_mask, blend, guide);
}


}  // namespace veneer::eval
