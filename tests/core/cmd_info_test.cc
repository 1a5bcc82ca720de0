// `arreg info --json` on generated files, run as a separate process.
#include <gtest/gtest.h>

#include <sys/wait.h>
#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <ostream>
#include <string>

#include "core/file_util.h"
#include "core/mesh_generators.h"
#include "core/mesh_info.h"
#include "core/mesh_io.h"
#include "core/mesh_ops.h"
#include "test_util.h"

namespace arreg {
namespace {

const char kBinary[] = ARREG_BINARY_DIR "/apps/arreg";

// Runs `arreg args`, returns stdout and sets *status to the exit code.
std::string RunArreg(const std::string& args, int* status) {
  const std::string command = std::string(kBinary) + " " + args + " 2>/dev/null";
  FILE* pipe = popen(command.c_str(), "r");
  if (!pipe) return "";
  std::string out;
  char buffer[4096];
  size_t n;
  while ((n = fread(buffer, 1, sizeof(buffer), pipe)) > 0) out.append(buffer, n);
  const int raw = pclose(pipe);
  *status = WIFEXITED(raw) ? WEXITSTATUS(raw) : -1;
  return out;
}

TEST(CmdInfo, JsonForTetAndSurfaceFiles) {
  if (!FileExists(kBinary)) GTEST_SKIP() << kBinary << " not built; skipped";
  const std::string dir = testing::ScratchDir("cmd_info");
  TetMesh mesh =
      MakeBoxTetMesh(Eigen::Vector3d(4, 2, 3), Eigen::Vector3i(4, 2, 3), BoxTetSplit::kFive);
  std::swap(mesh.tetrahedra(0, 0), mesh.tetrahedra(0, 1));  // one inverted tet
  WriteTetMesh(dir + "/box.msh", mesh);
  int status = -1;
  const nlohmann::json j =
      nlohmann::json::parse(RunArreg("info " + dir + "/box.msh --json", &status));
  EXPECT_EQ(status, 0);
  EXPECT_EQ(j["vertices"], 5 * 3 * 4);
  EXPECT_EQ(j["tetrahedra"], 24 * 5);
  EXPECT_EQ(j["triangles"], 0);
  EXPECT_NEAR(j["volume"].get<double>(), 24.0, 1e-12);
  EXPECT_EQ(j["inverted_elements"], 1);
  EXPECT_EQ(j["boundary_triangles"], 2 * 2 * (8 + 12 + 6));
  EXPECT_EQ(j["components"], 1);
  EXPECT_EQ(j["surface"]["euler_characteristic"], 2);
  EXPECT_EQ(j["bounding_box"]["size"][2], 3.0);
  EXPECT_GT(j["min_dihedral_angle_deg"].get<double>(), 0);

  SurfaceMesh boundary =
      ExtractBoundary(MakeBoxTetMesh(Eigen::Vector3d(4, 2, 3), Eigen::Vector3i(1, 1, 1)));
  RemoveUnreferencedVertices(&boundary);
  WriteSurfaceMesh(dir + "/box.stl", boundary);
  const nlohmann::json s =
      nlohmann::json::parse(RunArreg("info " + dir + "/box.stl --json", &status));
  EXPECT_EQ(status, 0);
  EXPECT_EQ(s["vertices"], 8);
  EXPECT_EQ(s["tetrahedra"], 0);
  EXPECT_EQ(s["triangles"], 12);
  EXPECT_NEAR(s["volume"].get<double>(), 24.0, 1e-12);
  EXPECT_NEAR(s["surface"]["area"].get<double>(), 2 * (8 + 12 + 6), 1e-12);
  EXPECT_TRUE(s["surface"]["closed"].get<bool>());

  // An open surface has no volume; a broken file fails with exit code 1.
  boundary.faces.conservativeResize(11, 3);
  WriteSurfaceMesh(dir + "/open.obj", boundary);
  const nlohmann::json o =
      nlohmann::json::parse(RunArreg("info " + dir + "/open.obj --json", &status));
  EXPECT_TRUE(o["volume"].is_null());
  EXPECT_EQ(o["surface"]["boundary_edges"], 3);
  WriteFileAtomic(dir + "/bad.off", [](std::ostream& os) { os << "OFF\n3 1 0\n0 0 0\n"; });
  RunArreg("info " + dir + "/bad.off", &status);
  EXPECT_EQ(status, 1);
}

TEST(MeshInfo, DescribesTetMeshAndOpenSurface) {
  // Library-level check of the same facts (runs without the binary).
  const std::string dir = testing::ScratchDir("mesh_info");
  const TetMesh box = MakeBoxTetMesh(Eigen::Vector3d(2, 2, 2), Eigen::Vector3i(2, 2, 2));
  WriteTetMesh(dir + "/box.vtk", box);
  const MeshInfo info = DescribeMeshFile(dir + "/box.vtk");
  EXPECT_EQ(info.vertices, 27);
  EXPECT_EQ(info.tetrahedra, 48);
  EXPECT_EQ(info.element_counts.at("tetrahedron"), 48);
  EXPECT_NEAR(info.volume, 8.0, 1e-12);
  EXPECT_NEAR(info.quality.min_dihedral_angle_rad, std::acos(-1.0) / 4, 1e-12);  // Kuhn: 45 deg
  ASSERT_TRUE(info.enclosed_volume.has_value());
  EXPECT_NEAR(*info.enclosed_volume, 8.0, 1e-12);
  const std::string text = MeshInfoToText(info);
  EXPECT_NE(text.find("48 tetrahedron"), std::string::npos) << text;
  EXPECT_NE(text.find("Euler characteristic 2"), std::string::npos) << text;
  const nlohmann::json j = MeshInfoToJson(info);
  for (const char* key : {"vertices", "tetrahedra", "triangles", "volume"})
    EXPECT_TRUE(j.contains(key)) << key;

  SurfaceMesh open = ExtractBoundary(box);
  open.faces.conservativeResize(open.num_faces() - 2, 3);
  WriteSurfaceMesh(dir + "/open.off", open);
  const MeshInfo o = DescribeMeshFile(dir + "/open.off");
  EXPECT_FALSE(o.enclosed_volume.has_value());
  EXPECT_EQ(o.surface.num_boundary_edges, 4);
  EXPECT_TRUE(MeshInfoToJson(o)["volume"].is_null());
  EXPECT_NE(MeshInfoToText(o).find("4 boundary edges"), std::string::npos);
}

}  // namespace
}  // namespace arreg
