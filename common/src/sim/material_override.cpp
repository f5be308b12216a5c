// A scene's shape in another scene's material: the reference render of the
// relighting measure (how the destination would look made of the source's stuff).
#include "scene.hpp"
#include "veneer/sim/simulator.hpp"

namespace veneer::sim {

Expected<std::shared_ptr<const Scene>> make_scene_with_material(const std::string& shape_scene,
                                                               const std::string& material_scene,
                                                               const RenderOptions& options) {
  auto placed = make_scene(shape_scene, options);  // checks options and the shape's name
  if (!placed) return placed.error();
  auto material = build_scene(material_scene);
  if (!material) return make_error("unknown scene '" + material_scene + "' for the material");
  auto scene = build_scene(shape_scene);
  // The surface (its normals, bumps included) stays the shape scene's; the
  // material scene gives what a material is: albedo texture and specular lobe,
  // evaluated at the same object-space point.
  MaterialFn shape_fn = scene->material, material_fn = material->material;
  scene->material = [shape_fn, material_fn](const V3& p, const V3& n, int prim, int part, SurfaceSample* out) {
    SurfaceSample stuff;
    stuff.normal = n;
    material_fn(p, n, prim, part, &stuff);
    shape_fn(p, n, prim, part, out);
    out->albedo = stuff.albedo;
    out->ks = stuff.ks;
    out->shininess = stuff.shininess;
  };
  scene->name = shape_scene + " in " + material_scene;
  scene->offset = (*placed)->offset;
  scene->scale = (*placed)->scale;
  std::shared_ptr<const Scene> shared = std::move(scene);
  return shared;
}

}  // namespace veneer::sim
