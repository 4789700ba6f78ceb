#include "scene/scene.h"

namespace mobirt {

Aabb Scene::bounds() const {
  Aabb box;
  for (const glm::vec3& p : mesh.positions) box.extend(p);
  for (const Shape& s : shapes) box.extend(shape_bounds(s));
  return box;
}

}  // namespace mobirt
