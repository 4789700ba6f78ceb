// --light and --camera parsing, and how overrides replace what the file has.
#include <gtest/gtest.h>

#include <glm/gtc/constants.hpp>

#include <cmath>
#include <string>
#include <vector>

#include "core/error.h"
#include "test_support.h"
#include "scene/overrides.h"

namespace mobirt {
namespace {

using test::expect_bad_input;
using test::expect_vec3;

TEST(LightOverride, PointDefaultsAndOptions) {
  const Light a = parse_light("point pos=1,2,3");
  EXPECT_EQ(a.type, LightType::Point);
  expect_vec3(a.position, {1, 2, 3});
  expect_vec3(a.color, {1, 1, 1});
  EXPECT_FLOAT_EQ(a.intensity, 1.0f);
  EXPECT_FLOAT_EQ(a.range, 0.0f);

  const Light b = parse_light("  POINT  intensity=25.5 color=1,0.5,0 pos=-1,0.5e1,2   range=10 ");
  EXPECT_EQ(b.type, LightType::Point);
  expect_vec3(b.position, {-1, 5, 2});
  expect_vec3(b.color, {1, 0.5f, 0});
  EXPECT_FLOAT_EQ(b.intensity, 25.5f);
  EXPECT_FLOAT_EQ(b.range, 10.0f);
}

TEST(LightOverride, Spot) {
  const Light s = parse_light("spot pos=0,5,0 dir=0,-2,0 inner=10 outer=30 intensity=100");
  EXPECT_EQ(s.type, LightType::Spot);
  expect_vec3(s.position, {0, 5, 0});
  expect_vec3(s.direction, {0, -1, 0});
  EXPECT_NEAR(s.inner_cone, glm::radians(10.0f), 1e-6f);
  EXPECT_NEAR(s.outer_cone, glm::radians(30.0f), 1e-6f);
  EXPECT_FLOAT_EQ(s.intensity, 100.0f);

  const Light d = parse_light("spot pos=0,0,0 dir=1,0,0");
  EXPECT_FLOAT_EQ(d.inner_cone, 0.0f);
  EXPECT_NEAR(d.outer_cone, glm::quarter_pi<float>(), 1e-6f);
}

TEST(LightOverride, Directional) {
  const Light d = parse_light("directional dir=1,-1,0 color=0.9,0.9,1 intensity=3");
  EXPECT_EQ(d.type, LightType::Directional);
  const float r = std::sqrt(0.5f);
  expect_vec3(d.direction, {r, -r, 0});
  expect_vec3(d.color, {0.9f, 0.9f, 1});
  EXPECT_FLOAT_EQ(d.intensity, 3.0f);
}

TEST(LightOverride, Errors) {
  expect_bad_input([] { parse_light("point pos=1,2"); },
                   {"--light 'point pos=1,2'", "pos needs three numbers X,Y,Z", "expected --light"});
  expect_bad_input([] { parse_light(""); }, {"--light", "empty"});
  expect_bad_input([] { parse_light("area pos=0,0,0"); }, {"unknown light type 'area'"});
  expect_bad_input([] { parse_light("point"); }, {"needs pos=X,Y,Z"});
  expect_bad_input([] { parse_light("spot pos=0,0,0"); }, {"needs dir=X,Y,Z"});
  expect_bad_input([] { parse_light("directional"); }, {"needs dir=X,Y,Z"});
  expect_bad_input([] { parse_light("directional dir=0,0,0"); }, {"dir must not be zero"});
  expect_bad_input([] { parse_light("directional dir=0,-1,0 pos=1,1,1"); },
                   {"'pos' is not a parameter of a directional light"});
  expect_bad_input([] { parse_light("directional dir=0,-1,0 range=4"); }, {"'range'"});
  expect_bad_input([] { parse_light("point pos=0,0,0 inner=5"); }, {"'inner'"});
  expect_bad_input([] { parse_light("point pos=0,0,0 pos=1,1,1"); }, {"pos is given twice"});
  expect_bad_input([] { parse_light("point pos=nan,0,0"); }, {"pos needs three numbers"});
  expect_bad_input([] { parse_light("point pos=inf,0,0"); }, {"pos needs three numbers"});
  expect_bad_input([] { parse_light("point pos=1,2,3,4"); }, {"pos needs three numbers"});
  expect_bad_input([] { parse_light("point pos=1,2,3x"); }, {"pos needs three numbers"});
  expect_bad_input([] { parse_light("point pos=1,,3"); }, {"pos needs three numbers"});
  expect_bad_input([] { parse_light("point pos=0,0,0 intensity=-1"); }, {"intensity must not be negative"});
  expect_bad_input([] { parse_light("point pos=0,0,0 intensity=lots"); }, {"intensity needs one finite number"});
  expect_bad_input([] { parse_light("point pos=0,0,0 range=1e999"); }, {"range needs one finite number"});
  expect_bad_input([] { parse_light("point pos=0,0,0 color=1,-1,1"); }, {"color components"});
  expect_bad_input([] { parse_light("point pos=0,0,0 color=1,1"); }, {"color needs three numbers R,G,B"});
  expect_bad_input([] { parse_light("point pos=0,0,0 bright"); }, {"'bright' is not key=value"});
  expect_bad_input([] { parse_light("spot pos=0,0,0 dir=0,-1,0 inner=30 outer=20"); },
                   {"0 <= inner < outer <= 90"});
  expect_bad_input([] { parse_light("spot pos=0,0,0 dir=0,-1,0 outer=120"); }, {"<= 90"});
  expect_bad_input([] { parse_light("spot pos=0,0,0 dir=0,-1,0 inner=-1"); }, {"0 <= inner"});
}

TEST(CameraOverride, FullAndShortForms) {
  const Camera c = parse_camera("0,1,5:0,1,0:0,1,0:60");
  expect_vec3(c.eye, {0, 1, 5});
  expect_vec3(c.target, {0, 1, 0});
  expect_vec3(c.up, {0, 1, 0});
  EXPECT_NEAR(c.yfov, glm::radians(60.0f), 1e-6f);
  EXPECT_FLOAT_EQ(c.znear, 0.0f);

  const Camera two = parse_camera("1,2,3:0,0,0");
  expect_vec3(two.up, {0, 1, 0});
  EXPECT_NEAR(two.yfov, glm::radians(45.0f), 1e-6f);

  const Camera fov = parse_camera("1,2,3:0,0,0:30");
  EXPECT_NEAR(fov.yfov, glm::radians(30.0f), 1e-6f);
  expect_vec3(fov.up, {0, 1, 0});

  const Camera up = parse_camera("0,5,0:0,0,0:0,0,-2");
  expect_vec3(up.up, {0, 0, -1});  // normalised
  EXPECT_NEAR(up.yfov, glm::radians(45.0f), 1e-6f);
}

TEST(CameraOverride, Errors) {
  expect_bad_input([] { parse_camera("0,0,5"); },
                   {"--camera '0,0,5'", "2 to 4 parts", "expected --camera"});
  expect_bad_input([] { parse_camera("0,0,5:0,0,0:0,1,0:45:1"); }, {"2 to 4 parts"});
  expect_bad_input([] { parse_camera("0,0:0,0,0"); }, {"the eye needs three numbers"});
  expect_bad_input([] { parse_camera("0,0,5:0,0,x"); }, {"the target needs three numbers"});
  expect_bad_input([] { parse_camera("0,0,5:0,0,0:0,1:45"); }, {"part 3"});
  expect_bad_input([] { parse_camera("0,0,5:0,0,0:45:0,1,0"); }, {"part 3"});
  expect_bad_input([] { parse_camera("0,0,5:0,0,0:0,1,0:0"); }, {"(0, 180)"});
  expect_bad_input([] { parse_camera("0,0,5:0,0,0:180"); }, {"(0, 180)"});
  expect_bad_input([] { parse_camera("0,0,5:0,0,0:-10"); }, {"(0, 180)"});
  expect_bad_input([] { parse_camera("0,0,5:0,0,0:nan"); }, {"field of view needs one number"});
  expect_bad_input([] { parse_camera("nan,0,5:0,0,0"); }, {"the eye needs three numbers"});
  expect_bad_input([] { parse_camera("1,1,1:1,1,1"); }, {"must differ"});
  expect_bad_input([] { parse_camera("0,5,0:0,0,0"); }, {"parallel"});
  expect_bad_input([] { parse_camera("0,0,5:0,0,0:0,0,0"); }, {"up vector is zero"});
}

TEST(Overrides, LightsReplaceAndCameraReplaces) {
  Scene scene;
  scene.lights.push_back(parse_light("point pos=0,0,0"));
  scene.lights.push_back(parse_light("point pos=1,0,0"));
  apply_overrides(scene, {}, std::nullopt);
  EXPECT_EQ(scene.lights.size(), 2u);
  EXPECT_FALSE(scene.camera.has_value());

  apply_overrides(scene, {parse_light("directional dir=0,-1,0")}, parse_camera("0,0,5:0,0,0"));
  ASSERT_EQ(scene.lights.size(), 1u);
  EXPECT_EQ(scene.lights[0].type, LightType::Directional);
  ASSERT_TRUE(scene.camera.has_value());
  expect_vec3(scene.camera->eye, {0, 0, 5});
}

}  // namespace
}  // namespace mobirt
