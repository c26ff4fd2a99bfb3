// Parameter names, TOML presets and --set overrides.
#include "engine/parameters.h"

#include <gtest/gtest.h>

#include <fstream>

#include "engine/error.h"
#include "engine/fusion.h"
#include "tests/test_util.h"

namespace sf {

TEST(Parameters, SetByNameAndDescribe) {
  FusionOptions o;
  ParameterSet p;
  register_parameters(p, o);
  p.set_assignment("integrate.gamma=8");
  p.set_assignment("regularize.tau1=0.25");
  p.set_assignment("extract.min_component_triangles=100");
  p.set_assignment("input.format=mve");
  EXPECT_DOUBLE_EQ(o.integrate.gamma, 8.0);
  EXPECT_DOUBLE_EQ(o.regularize.tau1, 0.25);
  EXPECT_EQ(o.extract.min_component_triangles, 100u);
  EXPECT_EQ(o.input.format, "mve");
  EXPECT_NE(p.describe().find("integrate.gamma = 8"), std::string::npos);
}

TEST(Parameters, BadNamesAndValuesAreInputErrors) {
  FusionOptions o;
  ParameterSet p;
  register_parameters(p, o);
  EXPECT_THROW(p.set_assignment("integrate.gama=8"), InputError);
  EXPECT_THROW(p.set_assignment("integrate.gamma=eight"), InputError);
  EXPECT_THROW(p.set_assignment("integrate.coarser_levels=1.5"), InputError);
  EXPECT_THROW(p.set_assignment("novalue"), InputError);
  o.integrate.gamma = -1;
  EXPECT_THROW(o.integrate.check(), InputError);
}

TEST(Parameters, EveryPresetLoadsAndChecks) {
  for (const char* name : {"laser", "mvs", "rgbd"}) {
    FusionOptions o;
    ParameterSet p;
    register_parameters(p, o);
    p.load_toml(std::filesystem::path(SCALEFUSE_SOURCE_DIR) / "configs" / (std::string(name) + ".toml"));
    EXPECT_NO_THROW(o.triangulate.check());
    EXPECT_NO_THROW(o.integrate.check());
    EXPECT_NO_THROW(o.regularize.check());
    if (std::string(name) == "mvs") {
      EXPECT_DOUBLE_EQ(o.integrate.gamma, 8.0);
      EXPECT_DOUBLE_EQ(o.regularize.tau0, 0.5);
      EXPECT_DOUBLE_EQ(o.regularize.tau1, 0.1);
    }
    if (std::string(name) == "laser") {
      EXPECT_DOUBLE_EQ(o.regularize.tau0, 0.0);
    }
  }
}

TEST(Parameters, MalformedTomlNamesFileAndLine) {
  const auto dir = test::scratch_dir("params");
  const auto path = dir / "bad.toml";
  std::ofstream(path) << "[integrate]\ngamma = = 3\n";
  FusionOptions o;
  ParameterSet p;
  register_parameters(p, o);
  try {
    p.load_toml(path);
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("bad.toml"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("line 2"), std::string::npos);
  }
  std::ofstream(path) << "[integrate]\nunknown_knob = 3\n";
  EXPECT_THROW(p.load_toml(path), InputError);
}

TEST(Octree, RootCubeAndBbox) {
  Eigen::AlignedBox3d b(Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(2, 1, 1));
  const RootCube r = root_cube_for(b, 0.05);
  EXPECT_DOUBLE_EQ(r.size, 2.2);
  EXPECT_NEAR(r.min.x(), -0.1, 1e-12);
  EXPECT_NEAR(r.min.y(), 0.5 - 1.1, 1e-12);
  EXPECT_THROW(parse_bbox("0,0,0,1,1"), InputError);
  EXPECT_THROW(parse_bbox("0,0,0,1,x,1"), InputError);
  EXPECT_THROW(parse_bbox("0,0,0,-1,1,1"), InputError);
  EXPECT_TRUE(parse_bbox("-1,-1,-1,1,1,1").has_value());
}

}  // namespace sf
