#include "scene/scene.h"

#include <cmath>

namespace mobirt {

glm::mat3 texture_transform_matrix(glm::vec2 offset, float rotation, glm::vec2 scale) {
  // Column-major, as glm (and GLSL) construct matrices: each line below is a column.
  const double c = std::cos(double(rotation)), s = std::sin(double(rotation));
  const glm::dmat3 translate(1.0, 0.0, 0.0,  //
                             0.0, 1.0, 0.0,  //
                             offset.x, offset.y, 1.0);
  const glm::dmat3 rotate(c, -s, 0.0,  //
                          s, c, 0.0,   //
                          0.0, 0.0, 1.0);
  const glm::dmat3 scale_matrix(scale.x, 0.0, 0.0,  //
                                0.0, scale.y, 0.0,  //
                                0.0, 0.0, 1.0);
  return glm::mat3(translate * rotate * scale_matrix);
}

Aabb Scene::bounds() const {
  Aabb box;
  for (const glm::vec3& p : mesh.positions) box.extend(p);
  for (const Shape& s : shapes) box.extend(shape_bounds(s));
  return box;
}

}  // namespace mobirt
