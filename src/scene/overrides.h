// Command-line overrides of a scene's lights and camera.
//
//   --light "point pos=X,Y,Z [color=R,G,B] [intensity=I] [range=R]"
//   --light "spot pos=X,Y,Z dir=X,Y,Z [inner=DEG] [outer=DEG] [color=R,G,B] [intensity=I]
//            [range=R]"
//   --light "directional dir=X,Y,Z [color=R,G,B] [intensity=I]"
//
// Words are separated by spaces; the type comes first, then key=value pairs in any order, each at
// most once. dir is where the light points (normalised on parsing). Defaults: color 1,1,1,
// intensity 1 (candela for point and spot, lux for directional, as KHR_lights_punctual),
// range 0 (unlimited), inner 0, outer 45 degrees; 0 <= inner < outer <= 90. Colour, intensity and
// range are >= 0.
//
//   --camera "EX,EY,EZ:TX,TY,TZ[:UX,UY,UZ][:FOVDEG]"
//
// eye, target, optional up (default 0,1,0), optional vertical field of view in degrees (default
// 45), in that order: a third part with one number is the field of view, with three the up
// vector. fov must lie in (0, 180); eye and target must differ; up must not be zero or parallel to
// the view direction.
//
// Every number must be finite. A malformed spec throws Error(BadInput) naming the option, the
// spec and the expected syntax, e.g.
//   --light 'point pos=1,2': pos needs three numbers X,Y,Z; expected --light "point pos=X,Y,Z ..."
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "core/camera.h"
#include "scene/scene.h"

namespace mobirt {

Light parse_light(const std::string& spec);
Camera parse_camera(const std::string& spec);

// Lights given on the command line REPLACE the file's lights (none given: the file's stay); a
// camera replaces the file's camera.
void apply_overrides(Scene& scene, const std::vector<Light>& lights,
                     const std::optional<Camera>& camera);

}  // namespace mobirt
