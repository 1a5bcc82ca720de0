// Mesh readers and writers: real files from ../shared/data, exact round trips
// for every format, and errors (never crashes) on broken input.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/file_util.h"
#include "core/mesh_generators.h"
#include "core/mesh_io.h"
#include "core/mesh_ops.h"
#include "test_util.h"

namespace arreg {
namespace {

void WriteText(const std::string& path, const std::string& text) {
  std::ofstream os(path, std::ios::binary);
  os << text;
}

// Expects ReadMeshFile(path) to throw arreg::Error whose message names the
// file and contains `fragment`.
void ExpectReadError(const std::string& path, const std::string& fragment = "") {
  try {
    ReadMeshFile(path);
    ADD_FAILURE() << "no error reading " << path;
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos)
        << "message '" << e.what() << "' lacks '" << fragment << "'";
  }
}

// A box mesh with irregular (non-dyadic) coordinates, so that round trips
// test the number printing, not just small integers.
TetMesh PerturbedBox() {
  TetMesh mesh = MakeBoxTetMesh(Eigen::Vector3d(10, 7, 5), Eigen::Vector3i(3, 2, 2));
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> jitter(-0.2, 0.2);
  for (int v = 0; v < mesh.num_vertices(); ++v)
    for (int k = 0; k < 3; ++k) mesh.vertices(v, k) += jitter(rng) / 3.0;
  return mesh;
}

SurfaceMesh TexturedSurface() {
  const TetMesh box = PerturbedBox();
  SurfaceMesh s = ExtractBoundary(box);
  RemoveUnreferencedVertices(&s);
  s.normals = s.vertices.rowwise().normalized();
  s.uvs = s.vertices.leftCols<2>() / 11.0;  // per vertex
  s.face_uvs = s.faces;
  return s;
}

// ---- Real data --------------------------------------------------------------

TEST(MeshIoShared, LiverMshVersion1) {
  ARREG_REQUIRE_SHARED(path, "meshes/sofa/liver.msh");
  TetMesh mesh = ReadTetMesh(path);
  EXPECT_EQ(mesh.num_vertices(), 181);
  EXPECT_EQ(mesh.num_tetrahedra(), 596);
  FixOrientation(&mesh);
  EXPECT_GT(TetVolumes(mesh).minCoeff(), 0);
  const SurfaceMesh boundary = ExtractBoundary(mesh);
  EXPECT_NEAR(EnclosedVolume(boundary), TetVolumes(mesh).sum(), 1e-9 * TetVolumes(mesh).sum());
  EXPECT_EQ(ReadMeshFile(path).format, "msh 1");
}

TEST(MeshIoShared, Liver2Msh) {
  ARREG_REQUIRE_SHARED(path, "meshes/sofa/liver2.msh");
  TetMesh mesh = ReadTetMesh(path);
  EXPECT_EQ(mesh.num_vertices(), 507);
  EXPECT_EQ(mesh.num_tetrahedra(), 1493);
  FixOrientation(&mesh);
  EXPECT_GT(TetVolumes(mesh).minCoeff(), 0);
  int components = 0;
  ConnectedComponents(mesh, Adjacency::kVertex, &components);
  EXPECT_GE(components, 1);
}

TEST(MeshIoShared, OpenHelpStl) {
  ARREG_REQUIRE_SHARED(liver, "meshes/openhelp/Liver.stl");
  ARREG_REQUIRE_SHARED(kidney, "meshes/openhelp/Kidney_left.stl");
  const SurfaceMesh l = ReadSurfaceMesh(liver);
  const SurfaceMesh k = ReadSurfaceMesh(kidney);
  EXPECT_EQ(l.num_faces(), 30726);
  EXPECT_EQ(k.num_faces(), 6570);
  // Merged vertices: a closed triangulation has about F/2 of them.
  EXPECT_LT(l.num_vertices(), l.num_faces());
  EXPECT_GT(SurfaceArea(l), 0);
  EXPECT_EQ(ReadMeshFile(liver).format, "stl binary");  // its header starts like "COLOR="
}

TEST(MeshIoShared, SofaLiverSurfaceMatchesItsVolumeMesh) {
  // SOFA ships liver.obj as the visual surface of liver.msh: same 181 points,
  // and the enclosed volume agrees with the tetrahedra within 0.1 %.
  ARREG_REQUIRE_SHARED(obj, "meshes/sofa/liver.obj");
  ARREG_REQUIRE_SHARED(msh, "meshes/sofa/liver.msh");
  const SurfaceMesh surface = ReadSurfaceMesh(obj);
  TetMesh mesh = ReadTetMesh(msh);
  FixOrientation(&mesh);
  EXPECT_EQ(surface.num_vertices(), mesh.num_vertices());
  EXPECT_TRUE(AnalyzeSurface(surface).closed_oriented_manifold());
  const double tet_volume = TetVolumes(mesh).sum();
  EXPECT_NEAR(EnclosedVolume(surface), tet_volume, 1e-3 * tet_volume);
}

TEST(MeshIoShared, SofaObjWithUvs) {
  ARREG_REQUIRE_SHARED(path, "meshes/sofa/liver-smoothUV.obj");
  const SurfaceMesh s = ReadSurfaceMesh(path);
  EXPECT_GT(s.num_faces(), 0);
  ASSERT_GT(s.uvs.rows(), 0);
  EXPECT_EQ(s.face_uvs.rows(), s.num_faces());
  EXPECT_GE(s.face_uvs.minCoeff(), 0);
  EXPECT_LT(s.face_uvs.maxCoeff(), s.uvs.rows());
}

TEST(MeshIoShared, BrokenVtkGivesError) {
  ARREG_REQUIRE_SHARED(path, "meshes/sofa/liver_for_test_broken.vtk");
  ExpectReadError(path, "byte offset");
  EXPECT_THROW(ReadSurfaceMesh(path), Error);
}

// ---- Round trips ------------------------------------------------------------

struct TetCase {
  const char* name;
  MeshWriteOptions options;
};

TEST(MeshIoRoundTrip, TetMeshExactInEveryFormat) {
  const TetMesh mesh = [] {
    TetMesh m = PerturbedBox();
    m.triangles = ExtractBoundary(m).faces;
    return m;
  }();
  const std::string dir = testing::ScratchDir("mesh_io_tet_round_trip");
  MeshWriteOptions v22, v41, vtk_ascii, vtk_binary;
  v41.msh_version = MshVersion::kV41;
  vtk_binary.binary = true;
  const std::vector<std::pair<std::string, MeshWriteOptions>> cases = {
      {"a.msh", v22}, {"b.msh", v41}, {"c.vtk", vtk_ascii}, {"d.vtk", vtk_binary}, {"E.MSH", v41}};
  for (const auto& [name, options] : cases) {
    const std::string path = dir + "/" + name;
    WriteTetMesh(path, mesh, options);
    const TetMesh back = ReadTetMesh(path);
    EXPECT_EQ(back.vertices, mesh.vertices) << name;
    EXPECT_EQ(back.tetrahedra, mesh.tetrahedra) << name;
    EXPECT_EQ(back.triangles, mesh.triangles) << name;
  }
}

TEST(MeshIoRoundTrip, QuadraticTetrahedra) {
  // Two quadratic tets sharing a face; edge nodes stored after the corners.
  TetMesh mesh;
  mesh.vertices.resize(5, 3);
  mesh.vertices << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 1, 1, 1;
  mesh.tetrahedra.resize(2, 4);
  mesh.tetrahedra << 0, 1, 2, 3, 1, 2, 3, 4;
  FixOrientation(&mesh);
  const int edges[6][2] = {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}};
  std::vector<Eigen::RowVector3d> extra;
  mesh.high_order_nodes.resize(2, 6);
  for (int t = 0; t < 2; ++t)
    for (int e = 0; e < 6; ++e) {
      const Eigen::RowVector3d mid = 0.5 * (mesh.vertices.row(mesh.tetrahedra(t, edges[e][0])) +
                                            mesh.vertices.row(mesh.tetrahedra(t, edges[e][1])));
      int found = -1;
      for (size_t i = 0; i < extra.size(); ++i)
        if (extra[i] == mid) found = static_cast<int>(i);
      if (found < 0) {
        found = static_cast<int>(extra.size());
        extra.push_back(mid);
      }
      mesh.high_order_nodes(t, e) = 5 + found;
    }
  mesh.vertices.conservativeResize(5 + static_cast<int>(extra.size()), 3);
  for (size_t i = 0; i < extra.size(); ++i) mesh.vertices.row(5 + static_cast<int>(i)) = extra[i];
  const std::string dir = testing::ScratchDir("mesh_io_quadratic");
  MeshWriteOptions binary;
  binary.binary = true;
  MeshWriteOptions v41;
  v41.msh_version = MshVersion::kV41;
  for (const auto& [name, options] : std::vector<std::pair<std::string, MeshWriteOptions>>{
           {"q.msh", {}}, {"q41.msh", v41}, {"q.vtk", {}}, {"qb.vtk", binary}}) {
    WriteTetMesh(dir + "/" + name, mesh, options);
    const TetMesh back = ReadTetMesh(dir + "/" + name);
    EXPECT_EQ(back.vertices, mesh.vertices) << name;
    EXPECT_EQ(back.tetrahedra, mesh.tetrahedra) << name;
    EXPECT_EQ(back.high_order_nodes, mesh.high_order_nodes) << name;
  }
}

TEST(MeshIoRoundTrip, SurfaceExactInEveryFormat) {
  const SurfaceMesh s = TexturedSurface();
  const std::string dir = testing::ScratchDir("mesh_io_surface_round_trip");
  MeshWriteOptions ascii, binary, v41;
  binary.binary = true;
  v41.msh_version = MshVersion::kV41;
  struct Case {
    std::string name;
    MeshWriteOptions options;
    bool normals, uvs;
  };
  const std::vector<Case> cases = {{"s.obj", ascii, true, true},   {"s.off", ascii, true, false},
                                   {"s.vtk", ascii, true, true},   {"sb.vtk", binary, true, true},
                                   {"s.msh", ascii, false, false}, {"s41.msh", v41, false, false}};
  for (const Case& c : cases) {
    const std::string path = dir + "/" + c.name;
    WriteSurfaceMesh(path, s, c.options);
    const SurfaceMesh back = ReadSurfaceMesh(path);
    EXPECT_EQ(back.vertices, s.vertices) << c.name;
    EXPECT_EQ(back.faces, s.faces) << c.name;
    if (c.normals) {
      EXPECT_EQ(back.normals, s.normals) << c.name;
    }
    if (c.uvs) {
      EXPECT_EQ(back.uvs, s.uvs) << c.name;
      EXPECT_EQ(back.face_uvs, s.face_uvs) << c.name;
    }
  }
}

// Groups written one after the other: one `o` line each, face indices offset by the
// vertices before them, so that reading the file back gives the union.
TEST(MeshIoRoundTrip, ObjGroupsReadBackAsTheirUnion) {
  const std::string dir = testing::ScratchDir("obj_groups");
  SurfaceMesh a, b;
  a.vertices = RowMatX3d(3, 3);
  a.vertices << 0, 0, 0, 1, 0, 0, 0, 1, 0;
  a.faces = RowMatX3i(1, 3);
  a.faces << 0, 1, 2;
  b.vertices = RowMatX3d(4, 3);
  b.vertices << 0, 0, 1, 2, 0, 1, 2, 2, 1.25, 0, 2, 1;
  b.faces = RowMatX3i(2, 3);
  b.faces << 0, 1, 2, 0, 2, 3;
  const std::string path = dir + "/groups.obj";
  WriteObjGroups(path, {a, b}, {"tumour"}, "internal structures");
  const std::string text = ReadFileToString(path);
  EXPECT_EQ(text.rfind("# arreg run: internal structures\no tumour\n", 0), 0u) << text;
  EXPECT_NE(text.find("\no structure1\n"), std::string::npos) << text;
  const SurfaceMesh u = ReadSurfaceMesh(path);
  ASSERT_EQ(u.vertices.rows(), 7);
  ASSERT_EQ(u.faces.rows(), 3);
  EXPECT_EQ(u.vertices.row(5), b.vertices.row(2));
  EXPECT_EQ(u.faces.row(2), (Eigen::RowVector3i(3, 5, 6)));
}

TEST(MeshIoRoundTrip, ObjWithPerCornerUvsAndColours) {
  SurfaceMesh s;
  s.vertices.resize(4, 3);
  s.vertices << 0, 0, 0, 1.1, 0, 0, 1.1, 1.3, 0, 0, 1.3, 0.7;
  s.faces.resize(2, 3);
  s.faces << 0, 1, 2, 0, 2, 3;
  s.uvs.resize(5, 2);
  s.uvs << 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 0.15;
  s.face_uvs.resize(2, 3);
  s.face_uvs << 0, 1, 2, 3, 4, 0;
  s.colors = RowMatX3d::Constant(4, 3, 0.25);
  s.colors(2, 1) = 1.0 / 3.0;
  const std::string path = testing::ScratchDir("mesh_io_obj_uv") + "/m.obj";
  WriteSurfaceMesh(path, s);
  const SurfaceMesh back = ReadSurfaceMesh(path);
  EXPECT_EQ(back.uvs, s.uvs);
  EXPECT_EQ(back.face_uvs, s.face_uvs);
  EXPECT_EQ(back.colors, s.colors);
  const std::string off = testing::ScratchDir("mesh_io_off_colour") + "/m.off";
  WriteSurfaceMesh(off, s);
  EXPECT_EQ(ReadSurfaceMesh(off).colors, s.colors);
}

TEST(MeshIoRoundTrip, StlAsciiAndBinary) {
  // STL stores floats: use float-representable coordinates for exactness;
  // vertices are re-merged, so compare triangle corner positions.
  SurfaceMesh s = TexturedSurface();
  s.vertices = s.vertices.cast<float>().cast<double>();
  s.uvs.resize(0, 2);
  s.face_uvs.resize(0, 3);
  const std::string dir = testing::ScratchDir("mesh_io_stl");
  MeshWriteOptions binary;
  binary.binary = true;
  for (const auto& [name, options] :
       std::vector<std::pair<std::string, MeshWriteOptions>>{{"a.stl", {}}, {"b.stl", binary}}) {
    WriteSurfaceMesh(dir + "/" + name, s, options);
    const SurfaceMesh back = ReadSurfaceMesh(dir + "/" + name);
    ASSERT_EQ(back.num_faces(), s.num_faces()) << name;
    EXPECT_EQ(back.num_vertices(), s.num_vertices()) << name;
    for (int f = 0; f < s.num_faces(); ++f)
      for (int k = 0; k < 3; ++k)
        ASSERT_EQ(back.vertices.row(back.faces(f, k)), s.vertices.row(s.faces(f, k))) << name;
    EXPECT_NEAR(EnclosedVolume(back), EnclosedVolume(s), 1e-9);
  }
}

TEST(MeshIoRoundTrip, LowerPrecisionIsWithinItsDigits) {
  const TetMesh mesh = PerturbedBox();
  MeshWriteOptions options;
  options.precision = 6;
  const std::string path = testing::ScratchDir("mesh_io_precision") + "/p.vtk";
  WriteTetMesh(path, mesh, options);
  const TetMesh back = ReadTetMesh(path);
  // 6 significant digits of coordinates below 11: error below 1e-5 * 11 / 2.
  EXPECT_LT((back.vertices - mesh.vertices).cwiseAbs().maxCoeff(), 5.5e-5);
  EXPECT_GT((back.vertices - mesh.vertices).cwiseAbs().maxCoeff(), 0);
  options.precision = 0;
  EXPECT_THROW(WriteTetMesh(path, mesh, options), Error);
}

// ---- Parsing details ----------------------------------------------------------

TEST(MeshIoParse, MshVersion1WithSparseNodeNumbersAndSurfaceElements) {
  const std::string path = testing::ScratchDir("mesh_io_msh1") + "/m.msh";
  WriteText(path,
            "$NOD\n4\n10 0 0 0\n20 1 0 0\n30 0 1 0\n40 0 0 1\n$ENDNOD\n"
            "$ELM\n3\n1 4 1 1 4 10 20 30 40\n2 2 1 1 3 10 30 20\n3 15 1 1 1 40\n$ENDELM\n");
  const MeshFileData d = ReadMeshFile(path);
  ASSERT_EQ(d.tetrahedra.rows(), 1);
  EXPECT_EQ(d.tetrahedra.row(0), Eigen::RowVector4i(0, 1, 2, 3));
  ASSERT_EQ(d.triangles.rows(), 1);
  EXPECT_EQ(d.triangles.row(0), Eigen::RowVector3i(0, 2, 1));
  EXPECT_EQ(d.element_counts.at("point"), 1);
  EXPECT_EQ(d.element_counts.at("tetrahedron"), 1);
}

TEST(MeshIoParse, Msh41WithSeveralBlocksAndSkippedSections) {
  const std::string path = testing::ScratchDir("mesh_io_msh41") + "/m.msh";
  WriteText(path,
            "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$PhysicalNames\n1\n3 1 \"liver\"\n"
            "$EndPhysicalNames\n$Entities\n0 0 0 1\n1 0 0 0 1 1 1 1 1 0\n$EndEntities\n"
            "$Nodes\n2 4 1 4\n0 1 0 1\n1\n0 0 0\n3 1 0 3\n2\n3\n4\n1 0 0\n0 1 0\n0 0 1\n"
            "$EndNodes\n$Elements\n2 2 1 2\n3 1 4 1\n1 1 2 3 4\n1 1 1 1\n2 1 2\n"
            "$EndElements\n$NodeData\n1\n\"x\"\n$EndNodeData\n");
  const MeshFileData d = ReadMeshFile(path);
  EXPECT_EQ(d.vertices.rows(), 4);
  ASSERT_EQ(d.tetrahedra.rows(), 1);
  EXPECT_NEAR(
      SignedVolume(d.vertices.row(0), d.vertices.row(1), d.vertices.row(2), d.vertices.row(3)),
      1.0 / 6, 1e-15);
  EXPECT_EQ(d.element_counts.at("line"), 1);
}

TEST(MeshIoParse, ObjPolygonsNegativeIndicesAndNormals) {
  const std::string path = testing::ScratchDir("mesh_io_obj") + "/m.obj";
  WriteText(path,
            "# quad and pentagon\no thing\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0.5 1.5 0\n"
            "vn 0 0 1\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvt 0.5 1\ng g1\nusemtl m\ns off\n"
            "f 1/1/1 2/2/1 3/3/1 4/4/1\nf -5/-5/-1 -2/-2/-1 -1/-1/-1\n");
  const SurfaceMesh s = ReadSurfaceMesh(path);
  ASSERT_EQ(s.num_faces(), 3);
  EXPECT_EQ(s.faces.row(0), Eigen::RowVector3i(0, 1, 2));
  EXPECT_EQ(s.faces.row(1), Eigen::RowVector3i(0, 2, 3));
  EXPECT_EQ(s.faces.row(2), Eigen::RowVector3i(0, 3, 4));
  EXPECT_EQ(s.face_uvs.row(2), Eigen::RowVector3i(0, 3, 4));
  ASSERT_EQ(s.normals.rows(), 5);
  EXPECT_EQ(s.normals.row(4), Eigen::RowVector3d(0, 0, 1));
  EXPECT_NEAR(SurfaceArea(s), 1.25, 1e-15);
}

TEST(MeshIoParse, BinaryStlWhoseHeaderStartsWithSolid) {
  std::string data = "solid but actually binary";
  data.resize(80, ' ');
  const uint32_t count = 1;
  data.append(reinterpret_cast<const char*>(&count), 4);
  const float values[12] = {0, 0, 1, 0, 0, 0, 2, 0, 0, 0, 3, 0};
  data.append(reinterpret_cast<const char*>(values), sizeof(values));
  data.append(2, '\0');
  const std::string path = testing::ScratchDir("mesh_io_stl_solid") + "/b.stl";
  WriteText(path, data);
  const MeshFileData d = ReadMeshFile(path);
  EXPECT_EQ(d.format, "stl binary");
  ASSERT_EQ(d.triangles.rows(), 1);
  EXPECT_EQ(d.vertices.row(2), Eigen::RowVector3d(0, 3, 0));
}

TEST(MeshIoParse, OffWithCommentsAndCountsOnHeaderLine) {
  const std::string path = testing::ScratchDir("mesh_io_off") + "/m.off";
  WriteText(path, "OFF 4 1 0\n# corners\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3 255 0 0\n");
  const SurfaceMesh s = ReadSurfaceMesh(path);
  EXPECT_EQ(s.num_faces(), 2);
  EXPECT_NEAR(SurfaceArea(s), 1.0, 1e-15);
}

TEST(MeshIoParse, VtkVersion5OffsetsConnectivity) {
  const std::string path = testing::ScratchDir("mesh_io_vtk5") + "/m.vtk";
  WriteText(path,
            "# vtk DataFile Version 5.1\nvtk output\nASCII\nDATASET UNSTRUCTURED_GRID\n"
            "POINTS 4 float\n0 0 0 1 0 0 0 1 0\n0 0 1\nMETADATA\nINFORMATION 0\n\n"
            "CELLS 3 7\nOFFSETS vtktypeint64\n0 4 7\nCONNECTIVITY vtktypeint64\n0 1 2 3 0 2 1\n"
            "CELL_TYPES 2\n10\n5\nCELL_DATA 2\nSCALARS id int 1\nLOOKUP_TABLE default\n1 2\n");
  const MeshFileData d = ReadMeshFile(path);
  EXPECT_EQ(d.tetrahedra.rows(), 1);
  EXPECT_EQ(d.triangles.rows(), 1);
  EXPECT_EQ(d.triangles.row(0), Eigen::RowVector3i(0, 2, 1));
}

TEST(MeshIoParse, FormatByExtension) {
  const std::string dir = testing::ScratchDir("mesh_io_ext");
  EXPECT_THROW(ReadMeshFile(dir + "/m.ply"), Error);
  EXPECT_THROW(WriteTetMesh(dir + "/m.stl", PerturbedBox()), Error);
  EXPECT_THROW(WriteSurfaceMesh(dir + "/m", TexturedSurface()), Error);
  EXPECT_EQ(MeshFileExtension("/a.b/c.OBJ"), ".obj");
  EXPECT_EQ(MeshFileExtension("/a.b/c"), "");
  WriteSurfaceMesh(dir + "/UPPER.OFF", TexturedSurface());
  EXPECT_EQ(ReadSurfaceMesh(dir + "/UPPER.OFF").num_faces(), TexturedSurface().num_faces());
  EXPECT_THROW(ReadTetMesh(dir + "/UPPER.OFF"), Error);
}

// ---- Broken input -------------------------------------------------------------

TEST(MeshIoErrors, EmptyAndMissingFiles) {
  const std::string dir = testing::ScratchDir("mesh_io_empty");
  for (const char* ext : {".msh", ".vtk", ".obj", ".stl", ".off"}) {
    const std::string path = dir + "/empty" + ext;
    WriteText(path, "");
    ExpectReadError(path, "empty");
    ExpectReadError(dir + "/missing" + ext);
  }
  WriteText(dir + "/blank.obj", "\n\n# nothing\n");
  EXPECT_THROW(ReadSurfaceMesh(dir + "/blank.obj"), Error);
}

TEST(MeshIoErrors, TruncatedFilesOfEveryFormat) {
  const std::string dir = testing::ScratchDir("mesh_io_truncated");
  const TetMesh mesh = PerturbedBox();
  const SurfaceMesh surface = TexturedSurface();
  MeshWriteOptions binary, v41;
  binary.binary = true;
  v41.msh_version = MshVersion::kV41;
  WriteTetMesh(dir + "/t22.msh", mesh);
  WriteTetMesh(dir + "/t41.msh", mesh, v41);
  WriteTetMesh(dir + "/ta.vtk", mesh);
  WriteTetMesh(dir + "/tb.vtk", mesh, binary);
  WriteSurfaceMesh(dir + "/sa.vtk", surface);
  WriteSurfaceMesh(dir + "/sb.vtk", surface, binary);
  WriteSurfaceMesh(dir + "/sa.stl", surface);
  WriteSurfaceMesh(dir + "/sb.stl", surface, binary);
  WriteSurfaceMesh(dir + "/s.off", surface);
  WriteSurfaceMesh(dir + "/s.obj", surface);
  for (const char* name : {"t22.msh", "t41.msh", "ta.vtk", "tb.vtk", "sa.vtk", "sb.vtk", "sa.stl",
                           "sb.stl", "s.off", "s.obj"}) {
    const std::string full = ReadFileToString(dir + "/" + name);
    for (double fraction : {0.003, 0.05, 0.3, 0.5, 0.77, 0.95}) {
      const std::string path = dir + "/cut_" + std::to_string(fraction) + "_" + name;
      WriteText(path, full.substr(0, static_cast<size_t>(full.size() * fraction)));
      // OBJ has no counts, and VTK attributes after the cells are optional:
      // a cut at a line end there can leave a valid, smaller file.
      if (std::string(name) == "s.obj" || (std::string(name) == "sa.vtk" && fraction > 0.6)) {
        try {
          ReadMeshFile(path);
        } catch (const Error&) {
        }
      } else {
        SCOPED_TRACE(path);
        ExpectReadError(path);
      }
    }
  }
}

TEST(MeshIoErrors, WrongCountsAbsurdCountsAndBadIndices) {
  const std::string dir = testing::ScratchDir("mesh_io_counts");
  struct Case {
    const char* name;
    std::string text;
    const char* fragment;
  };
  const std::string tet_v22_head = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n";
  const std::vector<Case> cases = {
      {"more_nodes.msh",
       tet_v22_head + "$Nodes\n5\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n$EndNodes\n",
       "line 10: section ends after 4 of 5 nodes"},
      {"fewer_nodes.msh",
       tet_v22_head + "$Nodes\n3\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n$EndNodes\n",
       "line 9: expected $EndNodes"},
      {"bad_node.msh",
       tet_v22_head + "$Nodes\n4\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n$EndNodes\n$Elements\n1\n"
                      "1 4 2 0 1 1 2 3 99\n$EndElements\n",
       "node 99"},
      {"absurd.msh", tet_v22_head + "$Nodes\n1000000000000\n1 0 0 0\n$EndNodes\n", "absurd"},
      {"negative.msh", tet_v22_head + "$Nodes\n-4\n1 0 0 0\n$EndNodes\n", "negative"},
      {"nan.msh", tet_v22_head + "$Nodes\n1\n1 0 nan 0\n$EndNodes\n", "not finite"},
      {"inf.obj", "v 0 0 0\nv 1 inf 0\nv 0 1 0\nf 1 2 3\n", "line 2"},
      {"range.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", "out of range"},
      {"zero.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", "out of range"},
      {"range.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n", "vertex 3"},
      {"count.off", "OFF\n30000 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", "cannot fit"},
      {"range.vtk",
       "# vtk DataFile Version 3.0\nx\nASCII\nDATASET POLYDATA\nPOINTS 3 float\n0 0 0 1 0 0 0 1 0\n"
       "POLYGONS 1 4\n3 0 1 7\n",
       "point 7"},
      {"absurd.vtk",
       "# vtk DataFile Version 3.0\nx\nBINARY\nDATASET POLYDATA\nPOINTS 999999999999 float\n",
       "absurd"},
      {"cells.vtk",
       "# vtk DataFile Version 3.0\nx\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS 4 float\n"
       "0 0 0 1 0 0 0 1 0 0 0 1\nCELLS 1 6\n4 0 1 2 3 0\nCELL_TYPES 1\n10\n",
       "does not match"},
      {"types.vtk",
       "# vtk DataFile Version 3.0\nx\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS 4 float\n"
       "0 0 0 1 0 0 0 1 0 0 0 1\nCELLS 1 5\n4 0 1 2 3\nCELL_TYPES 1\n5\n",
       "expected 3"},
      {"text.stl", "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0\nendloop\n",
       "line 6"},
      {"short.stl", "garbage", "not an STL"},
      {"nodes.msh", "$MeshFormat\n3.0 0 8\n$EndMeshFormat\n", "unsupported Gmsh version"},
      {"binary.msh", "$MeshFormat\n2.2 1 8\n$EndMeshFormat\n", "binary"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const std::string path = dir + "/" + c.name;
    WriteText(path, c.text);
    ExpectReadError(path, c.fragment);
  }
}

TEST(MeshIoErrors, NanInBinaryFiles) {
  const std::string dir = testing::ScratchDir("mesh_io_nan");
  SurfaceMesh s = TexturedSurface();
  s.uvs.resize(0, 2);
  s.face_uvs.resize(0, 3);
  MeshWriteOptions binary;
  binary.binary = true;
  WriteSurfaceMesh(dir + "/s.stl", s, binary);
  WriteSurfaceMesh(dir + "/s.vtk", s, binary);
  // Overwrite one coordinate with a NaN bit pattern in place.
  std::string stl = ReadFileToString(dir + "/s.stl");
  const float nan = std::numeric_limits<float>::quiet_NaN();
  std::memcpy(&stl[84 + 50 * 3 + 12 + 4], &nan, 4);
  WriteText(dir + "/nan.stl", stl);
  ExpectReadError(dir + "/nan.stl", "byte offset 250");
  std::string vtk = ReadFileToString(dir + "/s.vtk");
  const size_t data = vtk.find("double\n") + 7;
  std::memset(&vtk[data + 8 * 4], 0xff, 8);  // a NaN double
  WriteText(dir + "/nan.vtk", vtk);
  ExpectReadError(dir + "/nan.vtk", "not finite");
  // Writers refuse non-finite input too.
  s.vertices(0, 0) = std::nan("");
  EXPECT_THROW(WriteSurfaceMesh(dir + "/bad.obj", s), Error);
  EXPECT_FALSE(FileExists(dir + "/bad.obj"));
}

TEST(MeshIoErrors, GarbageNeverCrashes) {
  // Random bytes and random cuts of valid files behind every extension: the
  // outcome is a mesh or an arreg::Error, never a crash (checked under ASan).
  const std::string dir = testing::ScratchDir("mesh_io_garbage");
  std::mt19937 rng(3);
  std::vector<std::string> seeds;
  const TetMesh mesh = PerturbedBox();
  MeshWriteOptions binary;
  binary.binary = true;
  WriteTetMesh(dir + "/seed.msh", mesh);
  WriteTetMesh(dir + "/seed.vtk", mesh, binary);
  seeds.push_back(ReadFileToString(dir + "/seed.msh"));
  seeds.push_back(ReadFileToString(dir + "/seed.vtk"));
  int errors = 0, total = 0;
  for (int trial = 0; trial < 60; ++trial) {
    std::string data = seeds[trial % seeds.size()];
    // Flip a handful of bytes.
    for (int k = 0; k < 4; ++k) data[rng() % data.size()] = static_cast<char>(rng() % 256);
    for (const char* ext : {".msh", ".vtk", ".obj", ".stl", ".off"}) {
      const std::string path = dir + "/g" + ext;
      WriteText(path, data);
      ++total;
      try {
        const MeshFileData d = ReadMeshFile(path);
        EXPECT_TRUE(d.vertices.allFinite());
      } catch (const Error&) {
        ++errors;
      }
    }
  }
  EXPECT_GT(errors, total / 2);  // most corrupt files are rejected
}

}  // namespace
}  // namespace arreg
