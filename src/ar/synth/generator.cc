#include "ar/synth/generator.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>

#include <Eigen/Eigenvalues>

#include "ar/render/rasterizer.h"
#include "ar/synth/scenarios.h"
#include "ar/synth/tissue_texture.h"
#include "core/error.h"
#include "core/file_util.h"
#include "core/mesh_io.h"
#include "core/mesh_ops.h"
#include "core/scene.h"
#include "core/version.h"
#include "tracking/video_io.h"

namespace arreg::synth {

void SynthOptions::Check() const {
  ARREG_CHECK_INPUT(!out_dir.empty(), "", "out", "an output folder is required");
  ARREG_CHECK_INPUT(frames >= 2 && frames <= 100000, "", "frames", "must be in [2, 100000], got ",
                    frames);
  ARREG_CHECK_INPUT(fps > 0 && fps <= 1000, "", "fps", "must be in (0, 1000]");
  ARREG_CHECK_INPUT(surface_every_k >= 1, "", "surface_every_k", "must be >= 1");
  ARREG_CHECK_INPUT(noise_sigma >= 0 && noise_sigma <= 50, "", "noise_sigma", "must be in [0, 50]");
  ARREG_CHECK_INPUT(blur_sigma_px >= 0 && blur_sigma_px <= 20, "", "blur_sigma_px",
                    "must be in [0, 20]");
  ARREG_CHECK_INPUT(supersampling >= 1 && supersampling <= 4, "", "supersampling",
                    "must be in [1, 4]");
  ARREG_CHECK_INPUT(crf >= 0 && crf <= 51, "", "crf", "must be in [0, 51]");
  ARREG_CHECK_INPUT(width % 2 == 0 && height % 2 == 0, "", "size",
                    "width and height must be even (H.264 4:2:0), got ", width, "x", height);
}

namespace {

std::string FrameName(int frame, const char* ext) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%06d.%s", frame, ext);
  return buf;
}

// Compact surface (only referenced vertices) of `faces` over `positions`.
SurfaceMesh CompactSurface(const RowMatX3d& positions, const RowMatX3i& faces) {
  SurfaceMesh mesh;
  mesh.vertices = positions;
  mesh.faces = faces;
  RemoveUnreferencedVertices(&mesh);
  return mesh;
}

void WriteJson(const std::string& path, const nlohmann::json& json) {
  WriteFileAtomic(path, [&](std::ostream& os) { os << json.dump(2) << "\n"; });
}

void WritePng(const std::string& path, const cv::Mat& image) {
  const std::string tmp = TemporaryPathFor(path);
  if (!cv::imwrite(tmp, image)) {
    std::remove(tmp.c_str());
    throw Error(path, "", "cannot write PNG");
  }
  CommitTemporaryFile(tmp, path);
}

// The simulated truth: current split topology, positions and solver.
struct Truth {
  RowMatX3d rest;            // (#V' x 3) rest positions of the split vertices
  RowMatX4i tets;            // (#T x 4) over split vertices
  std::vector<int> origin;   // per split vertex: vertex of the unsplit mesh
  RowMatX3d x;               // (#V' x 3) current positions
  std::vector<int> grip_of;  // per split vertex: grip index or -1
  std::unique_ptr<NeoHookeanEnergy> energy;
  std::unique_ptr<QuasiStaticSolver> solver;
};

// Per vertex of the unsplit mesh that the cut split: the largest distance between two of
// its copies (mm); 0 while the copies coincide.
std::map<int, double> CopySeparations(const Truth& truth) {
  std::map<int, std::vector<int>> copies;
  for (size_t v = 0; v < truth.origin.size(); ++v)
    copies[truth.origin[v]].push_back(static_cast<int>(v));
  std::map<int, double> separation;
  for (const auto& kv : copies) {
    if (kv.second.size() < 2) continue;
    double sep = 0;
    for (size_t i = 0; i < kv.second.size(); ++i)
      for (size_t j = i + 1; j < kv.second.size(); ++j)
        sep = std::max(sep, (truth.x.row(kv.second[i]) - truth.x.row(kv.second[j])).norm());
    separation[kv.first] = sep;
  }
  return separation;
}

// How far the cut has opened anywhere: the largest separation over all split vertices.
double LargestSeparation(const Truth& truth) {
  double largest = 0;
  for (const auto& kv : CopySeparations(truth)) largest = std::max(largest, kv.second);
  return largest;
}

void Rebuild(const Scenario& s, const RowMatX3d& original_rest, const ProgressiveCut::Split& split,
             Truth* truth) {
  RowMatX3d new_x(split.origin.size(), 3);
  if (truth->x.rows() > 0) {
    for (int t = 0; t < split.tetrahedra.rows(); ++t)
      for (int c = 0; c < 4; ++c)
        new_x.row(split.tetrahedra(t, c)) = truth->x.row(truth->tets(t, c));
  } else {
    for (size_t v = 0; v < split.origin.size(); ++v)
      new_x.row(v) = original_rest.row(split.origin[v]);
  }
  truth->x = new_x;
  truth->tets = split.tetrahedra;
  truth->origin = split.origin;
  truth->rest.resize(split.origin.size(), 3);
  truth->grip_of.assign(split.origin.size(), -1);
  std::vector<bool> fixed(split.origin.size(), false);
  for (size_t v = 0; v < split.origin.size(); ++v) {
    truth->rest.row(v) = original_rest.row(split.origin[v]);
    const Eigen::Vector3d p = truth->rest.row(v).transpose();
    for (size_t g = 0; g < s.grips.size(); ++g)
      if (s.grips[g].selects(p)) {
        truth->grip_of[v] = static_cast<int>(g);
        fixed[v] = true;
        break;
      }
  }
  truth->solver.reset();
  truth->energy = std::make_unique<NeoHookeanEnergy>(truth->rest, truth->tets, s.truth_material);
  truth->solver = std::make_unique<QuasiStaticSolver>(truth->energy.get(), fixed);
}

// Static background: dark, reddish abdominal wall with soft blotches.
std::vector<Eigen::Vector3f> MakeBackground(const TissueTexture& texture, int width, int height) {
  std::vector<Eigen::Vector3f> bg(static_cast<size_t>(width) * height);
  for (int v = 0; v < height; ++v)
    for (int u = 0; u < width; ++u) {
      const Eigen::Vector3d p(u / 60.0, v / 60.0, 0.5);
      const double n = 0.7 * texture.Noise(p, 11) + 0.3 * texture.Noise(2.3 * p, 12);
      const double vignette = 1.0 - 0.6 * (std::pow((u - width / 2.0) / width, 2) +
                                           std::pow((v - height / 2.0) / height, 2));
      bg[static_cast<size_t>(v) * width + u] =
          static_cast<float>(vignette) * Eigen::Vector3f(0.20f + 0.16f * static_cast<float>(n),
                                                         0.07f + 0.05f * static_cast<float>(n),
                                                         0.06f + 0.04f * static_cast<float>(n));
    }
  return bg;
}

// An instrument shaft with a two-jaw tip entering from the lower right corner.
void DrawOccluder(cv::Mat* bgr, double t, uint64_t seed) {
  const double w = bgr->cols, h = bgr->rows;
  const double phase = static_cast<double>(seed % 1000) * 0.001 * 2 * M_PI;
  const cv::Point2d tip(w * (0.55 + 0.15 * std::sin(2 * M_PI * t + phase)),
                        h * (0.55 + 0.12 * std::cos(2 * M_PI * 0.7 * t + phase)));
  const cv::Point2d base(w * 1.1, h * 1.15);
  cv::Point2d dir = tip - base;
  dir /= std::hypot(dir.x, dir.y);
  const cv::Point2d normal(-dir.y, dir.x);
  const double radius = 0.035 * w;
  const int steps = 12;
  for (int i = 0; i < steps; ++i) {  // shade across the shaft like a metal cylinder
    const double a0 = -1 + 2.0 * i / steps, a1 = -1 + 2.0 * (i + 1) / steps;
    const double shade = 0.35 + 0.55 * std::pow(std::cos(0.5 * M_PI * (0.5 * (a0 + a1) - 0.3)), 3);
    const cv::Point pts[4] = {base + normal * radius * a0, tip + normal * radius * a0,
                              tip + normal * radius * a1, base + normal * radius * a1};
    const int g = static_cast<int>(255 * shade);
    cv::fillConvexPoly(*bgr, pts, 4, cv::Scalar(g, g, g * 0.95), cv::LINE_AA);
  }
  const double open = 0.25 + 0.2 * std::sin(2 * M_PI * 1.5 * t);
  for (int side = -1; side <= 1; side += 2) {
    const cv::Point2d jaw_dir = dir * std::cos(open) + normal * (side * std::sin(open));
    const cv::Point pts[3] = {tip + normal * (radius * 0.8 * side), tip + jaw_dir * (radius * 3.0),
                              tip - normal * (radius * 0.2 * side)};
    cv::fillConvexPoly(*bgr, pts, 3, cv::Scalar(70, 70, 75), cv::LINE_AA);
  }
}

// Deformation gradient of tetrahedron `tet` of the truth (rest -> current).
Eigen::Matrix3d DeformationGradientOf(const Truth& truth, int tet) {
  Eigen::Matrix3d dm, ds;
  for (int c = 0; c < 3; ++c) {
    dm.col(c) =
        (truth.rest.row(truth.tets(tet, c + 1)) - truth.rest.row(truth.tets(tet, 0))).transpose();
    ds.col(c) = (truth.x.row(truth.tets(tet, c + 1)) - truth.x.row(truth.tets(tet, 0))).transpose();
  }
  return ds * dm.inverse();
}

Eigen::Vector3d RestCentroid(const Truth& truth, int tet) {
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (int k = 0; k < 4; ++k) c += truth.rest.row(truth.tets(tet, k)).transpose();
  return c / 4;
}

// Tetrahedra of the process zone: rest centroid within `radius` of `tip` and ahead of it.
std::vector<int> ProcessZone(const Truth& truth, const Eigen::Vector3d& tip,
                             const Eigen::Vector3d& dir, double radius) {
  std::vector<int> zone;
  for (int k = 0; k < truth.tets.rows(); ++k) {
    const Eigen::Vector3d c = RestCentroid(truth, k);
    if ((c - tip).norm() <= radius && (c - tip).dot(dir) >= 0) zone.push_back(k);
  }
  return zone;
}

// Mean over `zone` of the largest principal Cauchy stress of the neo-Hookean truth (Pa):
// sigma = mu / J (B - I) + lambda ln J / J I, B = F F^T.
double MeanLargestPrincipalStress(const Truth& truth, const std::vector<int>& zone,
                                  const NeoHookeanMaterial& material) {
  if (zone.empty()) return 0;
  double sum = 0;
  for (int k : zone) {
    const Eigen::Matrix3d f = DeformationGradientOf(truth, k);
    const double j = f.determinant();
    const Eigen::Matrix3d sigma =
        material.mu() / j * (f * f.transpose() - Eigen::Matrix3d::Identity()) +
        material.lambda() * std::log(j) / j * Eigen::Matrix3d::Identity();
    sum += Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(sigma, Eigen::EigenvaluesOnly)
               .eigenvalues()
               .maxCoeff();
  }
  return sum / zone.size();
}

// Faces of the mid-surface of a membrane slab: the faces of the tetrahedra below the mid-plane
// whose three vertices lie on it (rest z = mid_z), oriented towards +z; over split vertex ids,
// so an opened cut or tear shows in the sheet.
RowMatX3i MidSurfaceFaces(const Truth& truth, double mid_z) {
  std::vector<Eigen::Vector3i> faces;
  for (int t = 0; t < truth.tets.rows(); ++t) {
    if (RestCentroid(truth, t).z() >= mid_z) continue;
    for (int k = 0; k < 4; ++k) {
      const std::array<int, 3> f = TetFace(truth.tets, t, k);
      if (std::all_of(f.begin(), f.end(),
                      [&](int v) { return std::abs(truth.rest(v, 2) - mid_z) < 1e-6; }))
        faces.emplace_back(f[0], f[1], f[2]);
    }
  }
  RowMatX3i out(static_cast<Eigen::Index>(faces.size()), 3);
  for (size_t f = 0; f < faces.size(); ++f)
    out.row(static_cast<Eigen::Index>(f)) = faces[f].transpose();
  return out;
}

// A vessel's centreline nodes embedded in the truth's tetrahedra (barycentric coordinates in the
// rest mesh; tetrahedron ids survive the cut's splits, so the nodes follow their side).
struct VesselEmbedding {
  std::vector<int> tet;
  std::vector<Eigen::Vector4d> bary;
};

VesselEmbedding EmbedNodes(const RowMatX3d& rest, const RowMatX4i& tets, const RowMatX3d& nodes) {
  VesselEmbedding e;
  for (int i = 0; i < nodes.rows(); ++i) {
    const Eigen::Vector3d p = nodes.row(i).transpose();
    int best = -1;
    double best_min = -std::numeric_limits<double>::infinity();
    Eigen::Vector4d best_bary;
    for (int t = 0; t < tets.rows(); ++t) {
      Eigen::Matrix3d m;
      for (int c = 0; c < 3; ++c)
        m.col(c) = (rest.row(tets(t, c + 1)) - rest.row(tets(t, 0))).transpose();
      const Eigen::Vector3d l = m.inverse() * (p - rest.row(tets(t, 0)).transpose());
      const Eigen::Vector4d b(1 - l.sum(), l.x(), l.y(), l.z());
      if (b.minCoeff() > best_min) {
        best_min = b.minCoeff();
        best = t;
        best_bary = b;
      }
      if (best_min >= 0) break;
    }
    ARREG_ASSERT(best >= 0 && best_min > -1e-6, "vessel node ", i, " is outside the truth mesh");
    e.tet.push_back(best);
    e.bary.push_back(best_bary);
  }
  return e;
}

RowMatX3d EmbeddedPositions(const Truth& truth, const VesselEmbedding& e) {
  RowMatX3d x(static_cast<Eigen::Index>(e.tet.size()), 3);
  for (size_t i = 0; i < e.tet.size(); ++i) {
    Eigen::Vector3d p = Eigen::Vector3d::Zero();
    for (int c = 0; c < 4; ++c)
      p += e.bary[i][c] * truth.x.row(truth.tets(e.tet[i], c)).transpose();
    x.row(static_cast<Eigen::Index>(i)) = p.transpose();
  }
  return x;
}

// The vessel as a tube: a ring of `ring` vertices at `radius` around each node of each piece
// (pieces: node chains; a branch point starts its own ring in every piece), no caps.
SurfaceMesh TubeSurface(const RowMatX3d& nodes, const std::vector<std::vector<int>>& pieces,
                        double radius, int ring = 10) {
  std::vector<Eigen::Vector3d> vertices;
  std::vector<Eigen::Vector3i> faces;
  for (const std::vector<int>& piece : pieces) {
    if (piece.size() < 2) continue;
    const int base = static_cast<int>(vertices.size());
    Eigen::Vector3d normal = Eigen::Vector3d::Zero();
    for (size_t i = 0; i < piece.size(); ++i) {
      const Eigen::Vector3d a = nodes.row(piece[i == 0 ? 0 : i - 1]).transpose();
      const Eigen::Vector3d b = nodes.row(piece[i + 1 < piece.size() ? i + 1 : i]).transpose();
      const Eigen::Vector3d tangent = (b - a).normalized();
      if (i == 0) {  // any perpendicular, then parallel transport (no twist along the tube)
        normal = tangent.unitOrthogonal();
      } else {
        normal = (normal - normal.dot(tangent) * tangent).normalized();
      }
      const Eigen::Vector3d binormal = tangent.cross(normal);
      const Eigen::Vector3d c = nodes.row(piece[i]).transpose();
      for (int k = 0; k < ring; ++k) {
        const double phi = 2 * M_PI * k / ring;
        vertices.push_back(c + radius * (std::cos(phi) * normal + std::sin(phi) * binormal));
      }
      if (i == 0) continue;
      const int r0 = base + static_cast<int>(i - 1) * ring, r1 = r0 + ring;
      for (int k = 0; k < ring; ++k) {
        const int k1 = (k + 1) % ring;
        faces.emplace_back(r0 + k, r0 + k1, r1 + k1);
        faces.emplace_back(r0 + k, r1 + k1, r1 + k);
      }
    }
  }
  SurfaceMesh mesh;
  mesh.vertices.resize(static_cast<Eigen::Index>(vertices.size()), 3);
  for (size_t v = 0; v < vertices.size(); ++v)
    mesh.vertices.row(static_cast<Eigen::Index>(v)) = vertices[v].transpose();
  mesh.faces.resize(static_cast<Eigen::Index>(faces.size()), 3);
  for (size_t f = 0; f < faces.size(); ++f)
    mesh.faces.row(static_cast<Eigen::Index>(f)) = faces[f].transpose();
  return mesh;
}

// The vessel's polylines cut into pieces where the cut has opened between two consecutive nodes
// (their rest positions on opposite sides of the cut surface, the crossing already reached).
std::vector<std::vector<int>> VesselPieces(const VesselSpec& vessel, const CutSurfaceSpec* cut,
                                           double advance_mm) {
  std::vector<std::vector<int>> pieces;
  for (const std::vector<int>& line : vessel.polylines) {
    pieces.push_back({line.front()});
    for (size_t i = 1; i < line.size(); ++i) {
      if (cut) {
        const Eigen::Vector3d a = vessel.nodes.row(line[i - 1]).transpose();
        const Eigen::Vector3d b = vessel.nodes.row(line[i]).transpose();
        const double fa = cut->level_set(a), fb = cut->level_set(b);
        if ((fa < 0) != (fb < 0)) {
          const Eigen::Vector3d crossing = a + (b - a) * (fa / (fa - fb));
          if (cut->progress_mm(crossing) <= advance_mm) pieces.push_back({});
        }
      }
      pieces.back().push_back(line[i]);
    }
  }
  return pieces;
}

// The centreline given to the registration: each polyline resampled to about `spacing` (every
// k-th node, ends kept, shared branch nodes shared), OBJ `v` and `l` lines.
void WriteCentreline(const std::string& path, const VesselSpec& vessel, double spacing_mm) {
  std::map<int, int> index;  // truth node -> OBJ vertex (1-based)
  std::vector<int> order;
  std::vector<std::vector<int>> lines;
  for (const std::vector<int>& line : vessel.polylines) {
    double length = 0;
    for (size_t i = 1; i < line.size(); ++i)
      length += (vessel.nodes.row(line[i]) - vessel.nodes.row(line[i - 1])).norm();
    const int segments = std::max(1, static_cast<int>(std::round(length / spacing_mm)));
    std::vector<int> kept;
    for (int k = 0; k <= segments; ++k)
      kept.push_back(line[static_cast<size_t>(std::round(k * (line.size() - 1.0) / segments))]);
    std::vector<int> out;
    for (int node : kept) {
      if (!index.count(node)) {
        order.push_back(node);
        index[node] = static_cast<int>(order.size());
      }
      if (out.empty() || out.back() != index[node]) out.push_back(index[node]);
    }
    lines.push_back(out);
  }
  WriteFileAtomic(path, [&](std::ostream& os) {
    os << "# arreg synth: vessel centreline (model frame, mm)\n";
    char text[96];
    for (int node : order) {
      std::snprintf(text, sizeof(text), "v %.9g %.9g %.9g\n", vessel.nodes(node, 0),
                    vessel.nodes(node, 1), vessel.nodes(node, 2));
      os << text;
    }
    for (const std::vector<int>& l : lines) {
      os << "l";
      for (int v : l) os << ' ' << v;
      os << '\n';
    }
  });
}

// Crack direction of a tear: the notched sheet is solved at the grips' state of time t_probe (in
// 4 load steps); the crack runs in the sheet plane perpendicular to the largest principal stretch
// direction (rest frame; coaxial with the largest principal stress of the isotropic material),
// from C = F^T F averaged over the process zone ahead of the notch tip.
Eigen::Vector3d TearDirection(const Scenario& s, double t_probe) {
  const TearSpec& tear = *s.tear;
  TetMesh mesh = s.truth.mesh;  // a copy: this notch's snapping must not move the real rest mesh
  ProgressiveCut notch(&mesh, TearPath(tear, tear.notch_dir), s.cut->options);
  notch.Advance(tear.notch_mm);
  Truth truth;
  Rebuild(s, mesh.vertices, notch.ComputeSplit(), &truth);
  for (int step = 1; step <= 4; ++step) {
    const double t = t_probe * step / 4;
    RowMatX3d targets = truth.x;
    for (int v = 0; v < truth.x.rows(); ++v)
      if (truth.grip_of[v] >= 0)
        targets.row(v) =
            s.grips[truth.grip_of[v]].Target(truth.rest.row(v).transpose(), t).transpose();
    truth.solver->Solve(targets, &truth.x);
  }
  Eigen::Matrix3d c = Eigen::Matrix3d::Zero();
  for (int k : ProcessZone(truth, tear.notch_tip, tear.notch_dir, tear.process_zone_mm)) {
    const Eigen::Matrix3d f = DeformationGradientOf(truth, k);
    c += f.transpose() * f;
  }
  const Eigen::Vector3d n = tear.plane_normal.normalized();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(c);
  Eigen::Vector3d e = eigen.eigenvectors().col(2);  // largest eigenvalue last
  e -= e.dot(n) * n;
  if (e.norm() < 1e-9) return tear.notch_dir;  // no in-plane stretch: continue straight
  Eigen::Vector3d crack = n.cross(e).normalized();
  if (crack.dot(tear.notch_dir) < 0) crack = -crack;
  return crack;
}

}  // namespace

SynthSummary GenerateSyntheticScene(const SynthOptions& options) {
  options.Check();
  const auto start = std::chrono::steady_clock::now();
  ScenarioOptions scenario_options;
  scenario_options.width = options.width;
  scenario_options.height = options.height;
  scenario_options.amplitude = options.amplitude;
  scenario_options.zoom = options.zoom;
  scenario_options.fine_cell_mm = options.fine_cell_mm;
  scenario_options.kidney_cell_mm = options.kidney_cell_mm;
  scenario_options.membrane_cell_mm = options.membrane_cell_mm;
  scenario_options.seed = options.seed;
  Scenario s = BuildScenario(options.scenario, scenario_options);
  ARREG_CHECK_INPUT(
      !s.has_model || s.truth.mesh.num_tetrahedra() >= 4 * s.model.mesh.num_tetrahedra(), "",
      "fine_cell_mm", "the truth mesh needs at least 4x the model's tetrahedra (",
      s.truth.mesh.num_tetrahedra(), " vs ", s.model.mesh.num_tetrahedra(),
      "); use a finer truth mesh");
  SynthSummary summary;
  summary.frames = options.frames;
  summary.truth_tetrahedra = s.truth.mesh.num_tetrahedra();
  summary.truth_vertices = s.truth.mesh.num_vertices();
  summary.model_tetrahedra = s.model.mesh.num_tetrahedra();
  summary.model_vertices = s.model.mesh.num_vertices();

  const std::string dir = options.out_dir;
  const std::string gt = dir + "/gt";
  CreateDirectories(gt + "/masks");
  CreateDirectories(gt + "/surface");
  if (s.has_internal_structure) CreateDirectories(gt + "/internal");
  const bool has_thin = s.membrane || s.vessel;
  if (has_thin) CreateDirectories(gt + "/thin");

  // A tear's path: the notch, then the crack perpendicular to the largest principal stress at the
  // notch tip (probed at the end of the first loading phase).
  Eigen::Vector3d crack_dir = Eigen::Vector3d::Zero();
  if (s.tear) {
    crack_dir = TearDirection(s, 0.3);
    s.cut->surface = TearPath(*s.tear, crack_dir);
    s.cut->length_mm = s.tear->max_length_mm;
  }
  // Cut: conforming faces in the truth mesh (snapping moves rest vertices).
  std::unique_ptr<ProgressiveCut> cut;
  if (s.cut) {
    cut = std::make_unique<ProgressiveCut>(&s.truth.mesh, s.cut->surface, s.cut->options);
    summary.snapped_vertices = cut->num_snapped_vertices();
  }
  const RowMatX3d original_rest = s.truth.mesh.vertices;
  Truth truth;
  ProgressiveCut::Split split;
  if (cut) {
    cut->Advance(s.cut->advance_mm.At(0).x());
    split = cut->ComputeSplit();
  } else {
    split.tetrahedra = s.truth.mesh.tetrahedra;
    split.origin.resize(original_rest.rows());
    for (int v = 0; v < original_rest.rows(); ++v) split.origin[v] = v;
  }
  Rebuild(s, original_rest, split, &truth);
  std::vector<int> face_open_frame(cut ? cut->num_faces() : 0, -1);
  double cut_advance = cut ? s.cut->advance_mm.At(0).x() : 0.0;
  // Opens the cut up to `advance` (mm along its path): new faces get this frame, the truth is
  // rebuilt on the new topology. Returns whether faces opened.
  const auto advance_cut = [&](double advance, int frame) {
    const std::vector<bool> was_open = cut->FaceOpen();
    cut_advance = advance;
    if (!cut->Advance(advance)) return false;
    const std::vector<bool> now_open = cut->FaceOpen();
    for (size_t f = 0; f < now_open.size(); ++f)
      if (now_open[f] && !was_open[f]) face_open_frame[f] = frame;
    Rebuild(s, original_rest, cut->ComputeSplit(), &truth);
    return true;
  };
  if (cut) {
    const std::vector<bool> open = cut->FaceOpen();
    for (size_t f = 0; f < open.size(); ++f)
      if (open[f]) face_open_frame[f] = 0;
  }
  std::optional<VesselEmbedding> vessel_embedding;
  if (s.vessel)
    vessel_embedding = EmbedNodes(original_rest, s.truth.mesh.tetrahedra, s.vessel->nodes);
  std::vector<double> tear_stress, tear_advance;  // per frame, with a tear
  std::vector<bool> internal_tet(s.truth.labels.size());
  for (int t = 0; t < s.truth.labels.size(); ++t) internal_tet[t] = s.truth.labels[t] == 2;

  const render::RasterCamera raster_camera = render::ToRasterCamera(s.camera);
  TissueTextureOptions texture_options;
  texture_options.seed = options.seed;
  const TissueTexture texture(texture_options);
  std::vector<Eigen::Vector3f> background;
  VideoWriter video;
  const std::string video_path = dir + "/video.mp4";
  if (options.write_video) {
    background = MakeBackground(texture, options.width, options.height);
    VideoWriterOptions video_options;
    video_options.crf = options.crf;
    video_options.encode_threads = 1;
    video.Open(video_path, options.width, options.height, options.fps, video_options);
  }
  render::RenderTarget target(raster_camera, options.supersampling);
  render::ShadingOptions shading;

  for (int frame = 0; frame < options.frames; ++frame) {
    const double t = static_cast<double>(frame) / (options.frames - 1);
    if (cut && !s.tear) advance_cut(s.cut->advance_mm.At(t).x(), frame);
    const auto solve_frame = [&]() {
      RowMatX3d targets = truth.x;
      for (int v = 0; v < truth.x.rows(); ++v)
        if (truth.grip_of[v] >= 0)
          targets.row(v) =
              s.grips[truth.grip_of[v]].Target(truth.rest.row(v).transpose(), t).transpose();
      const QuasiStaticSummary solve = truth.solver->Solve(targets, &truth.x);
      summary.newton_iterations += solve.iterations;
      return solve.converged;
    };
    bool converged = solve_frame();
    if (s.tear) {
      // The crack advances by steps while the stress ahead of its tip exceeds the strength (at
      // most max_steps_per_frame: a bounded crack speed), re-solving after each step.
      const TearSpec& tear = *s.tear;
      double stress = 0;
      for (int step = 0;; ++step) {
        const Eigen::Vector3d tip = tear.notch_tip + (cut_advance - tear.notch_mm) * crack_dir;
        stress = MeanLargestPrincipalStress(
            truth, ProcessZone(truth, tip, crack_dir, tear.process_zone_mm), s.truth_material);
        if (stress <= tear.strength_pa || step >= tear.max_steps_per_frame ||
            cut_advance + tear.step_mm > tear.max_length_mm + 1e-9)
          break;
        if (advance_cut(cut_advance + tear.step_mm, frame)) converged = solve_frame();
      }
      tear_stress.push_back(stress);
      tear_advance.push_back(cut_advance);
    }
    if (!converged) ++summary.unconverged_frames;
    const Eigen::VectorXd ratios = truth.energy->VolumeRatios(truth.x);
    double volume = 0, rest_volume = 0;
    for (int k = 0; k < truth.tets.rows(); ++k) {
      const double v0 = SignedVolume(truth.rest.row(truth.tets(k, 0)).transpose(),
                                     truth.rest.row(truth.tets(k, 1)).transpose(),
                                     truth.rest.row(truth.tets(k, 2)).transpose(),
                                     truth.rest.row(truth.tets(k, 3)).transpose());
      rest_volume += v0;
      volume += v0 * ratios[k];
    }
    summary.volume_ratio.push_back(volume / rest_volume);
    if (cut) summary.opening_mm.push_back(LargestSeparation(truth));
    summary.max_volume_change =
        std::max(summary.max_volume_change, std::abs(volume / rest_volume - 1));

    // Surfaces of this frame; the mask is the union of everything registered.
    const RowMatX3i faces = BoundaryFaces(truth.tets);
    cv::Mat mask = render::RenderMask(raster_camera, truth.x, faces);
    std::vector<SurfaceMesh> thin_meshes;
    std::vector<std::string> thin_names;
    if (s.membrane) {
      thin_meshes.push_back(CompactSurface(truth.x, MidSurfaceFaces(truth, s.membrane->mid_z_mm)));
      thin_names.push_back(s.membrane->name);
    }
    SurfaceMesh tube;
    if (s.vessel) {
      tube = TubeSurface(EmbeddedPositions(truth, *vessel_embedding),
                         VesselPieces(*s.vessel, cut ? &s.cut->surface : nullptr, cut_advance),
                         s.vessel->radius_mm);
      thin_meshes.push_back(tube);
      thin_names.push_back(s.vessel->name);
      cv::bitwise_or(mask, render::RenderMask(raster_camera, tube.vertices, tube.faces), mask);
    }
    WritePng(gt + "/masks/" + FrameName(frame, "png"), mask);
    const bool save_surface = frame % options.surface_every_k == 0 || frame == options.frames - 1;
    if (save_surface) {
      WriteSurfaceMesh(gt + "/surface/" + FrameName(frame, "obj"), CompactSurface(truth.x, faces));
      if (has_thin)
        WriteObjGroups(gt + "/thin/" + FrameName(frame, "obj"), thin_meshes, thin_names,
                       "internal structures");
      if (s.has_internal_structure)
        WriteSurfaceMesh(gt + "/internal/" + FrameName(frame, "obj"),
                         CompactSurface(truth.x, BoundaryFaces(truth.tets, internal_tet)));
    }
    if (options.write_video) {
      target.ClearWith([&](double u, double v) {
        const int iu = std::clamp(static_cast<int>(std::lround(u)), 0, options.width - 1);
        const int iv = std::clamp(static_cast<int>(std::lround(v)), 0, options.height - 1);
        return background[static_cast<size_t>(iv) * options.width + iu];
      });
      const RowMatX3d normals = render::VertexNormals(truth.x, faces);
      target.Draw(truth.x, faces, normals, [&](const render::Fragment& f) {
        const Eigen::Vector3d rest =
            f.barycentric[0] * truth.rest.row(faces(f.face, 0)).transpose() +
            f.barycentric[1] * truth.rest.row(faces(f.face, 1)).transpose() +
            f.barycentric[2] * truth.rest.row(faces(f.face, 2)).transpose();
        return render::ShadeBlinnPhong(texture.Albedo(rest), f, shading);
      });
      if (s.vessel)  // dark red, seen only where a cut opens the organ above it
        target.Draw(tube.vertices, tube.faces, render::VertexNormals(tube.vertices, tube.faces),
                    [&](const render::Fragment& f) {
                      return render::ShadeBlinnPhong(Eigen::Vector3f(0.45f, 0.05f, 0.08f), f,
                                                     shading);
                    });
      cv::Mat image = target.ResolveBgr();
      if (options.occluder) DrawOccluder(&image, t, options.seed);
      if (options.blur_sigma_px > 0)
        cv::GaussianBlur(image, image, cv::Size(), options.blur_sigma_px);
      if (options.noise_sigma > 0) {
        cv::Mat noise(image.size(), CV_32FC3);
        cv::RNG rng(options.seed * 1000003ULL + static_cast<uint64_t>(frame));
        rng.fill(noise, cv::RNG::NORMAL, 0.0, options.noise_sigma);
        cv::Mat noisy;
        image.convertTo(noisy, CV_32FC3);
        noisy += noise;
        noisy.convertTo(image, CV_8UC3);  // saturating
      }
      video.Write(image);
    }
    if (options.progress) options.progress(frame + 1, options.frames);
  }
  if (options.write_video) video.Close();
  summary.final_truth_vertices = static_cast<int>(truth.x.rows());

  // Cut ground truth and the opening at the last frame.
  nlohmann::json cut_json = {{"cut", nullptr}};
  if (cut) {
    const RowMatX3i cut_faces = cut->FaceTriangles();
    const std::vector<double> progress = cut->FaceProgress();
    SurfaceMesh cut_surface;
    cut_surface.vertices = original_rest;
    cut_surface.faces = cut_faces;
    Eigen::VectorXi old_to_new;
    RemoveUnreferencedVertices(&cut_surface, &old_to_new);
    WriteSurfaceMesh(gt + "/cut_surface.obj", cut_surface);
    for (int f : face_open_frame) {
      if (f < 0) continue;
      summary.cut_first_frame =
          summary.cut_first_frame < 0 ? f : std::min(summary.cut_first_frame, f);
      summary.cut_last_frame = std::max(summary.cut_last_frame, f);
    }
    // Separation of the copies of each split vertex, binned along the cut path.
    double opened_length = 0;
    const std::vector<bool> open = cut->FaceOpen();
    for (size_t f = 0; f < open.size(); ++f)
      if (open[f]) opened_length = std::max(opened_length, progress[f]);
    const double bin_mm = 5.0;
    const int bins = std::max(1, static_cast<int>(std::ceil(opened_length / bin_mm)));
    std::vector<double> bin_opening(bins, 0.0);
    for (const auto& [origin, sep] : CopySeparations(truth)) {
      summary.max_cut_opening_mm = std::max(summary.max_cut_opening_mm, sep);
      const double p = s.cut->surface.progress_mm(original_rest.row(origin).transpose());
      if (!std::isfinite(p)) continue;
      const int b = std::clamp(static_cast<int>(p / bin_mm), 0, bins - 1);
      bin_opening[b] = std::max(bin_opening[b], sep);
    }
    int open_bins = 0;
    for (double o : bin_opening) open_bins += o > 2.0;
    summary.cut_open_fraction = opened_length > 0 ? static_cast<double>(open_bins) / bins : 0.0;
    nlohmann::json face_frames = nlohmann::json::array();
    for (int f : face_open_frame) face_frames.push_back(f);
    nlohmann::json opening = nlohmann::json::array();
    for (double o : summary.opening_mm) opening.push_back(o);
    cut_json["cut"] = {
        {"surface", "cut_surface.obj"},
        {"open_frames", {summary.cut_first_frame, summary.cut_last_frame}},
        {"description", s.cut->description},
        {"precut", s.cut->precut},
        {"length_mm", s.cut->length_mm},
        {"coordinates", "rest pose = world frame at frame 0 (model frame of scene.json)"},
        {"face_open_frame", face_frames},
        {"opening_mm", opening},
        {"final_opening",
         {{"fraction_of_length_over_2mm", summary.cut_open_fraction},
          {"max_separation_mm", summary.max_cut_opening_mm},
          {"bin_mm", bin_mm}}}};
    if (s.tear)
      cut_json["cut"]["tear"] = {
          {"model",
           "crack from the notch tip perpendicular (in the sheet plane) to the largest principal "
           "stress at the tip; advances one step while the mean largest principal Cauchy stress "
           "of the tetrahedra within process_zone_mm ahead of the tip exceeds strength_pa"},
          {"notch_mm", s.tear->notch_mm},
          {"notch_tip", {s.tear->notch_tip.x(), s.tear->notch_tip.y(), s.tear->notch_tip.z()}},
          {"direction", {crack_dir.x(), crack_dir.y(), crack_dir.z()}},
          {"strength_pa", s.tear->strength_pa},
          {"step_mm", s.tear->step_mm},
          {"max_steps_per_frame", s.tear->max_steps_per_frame},
          {"max_length_mm", s.tear->max_length_mm},
          {"process_zone_mm", s.tear->process_zone_mm},
          {"tip_stress_pa", tear_stress},
          {"advance_mm", tear_advance}};
  }
  WriteJson(gt + "/cut.json", cut_json);

  // Registration inputs: coarse model, internal structure at rest, scene file.
  Scene scene;
  scene.description = "arreg synth " + s.name + ": " + s.description;
  if (s.has_model) {
    WriteTetMesh(dir + "/model.vtk", s.model.mesh);
    scene.model_mesh_path = dir + "/model.vtk";
  }
  if (s.has_internal_structure) {
    std::vector<bool> model_internal(s.truth.labels.size());
    for (int k = 0; k < s.truth.labels.size(); ++k) model_internal[k] = s.truth.labels[k] == 2;
    WriteSurfaceMesh(
        dir + "/internal.obj",
        CompactSurface(original_rest, BoundaryFaces(s.truth.mesh.tetrahedra, model_internal)));
    InternalStructure internal;
    internal.name = "internal";
    internal.mesh_path = dir + "/internal.obj";
    internal.color_rgb = Eigen::Vector3d(1.0, 0.85, 0.1);
    scene.internal_structures.push_back(internal);
  }
  scene.camera = s.camera;
  scene.video_path = video_path;
  scene.ground_truth_path = gt;
  scene.material.youngs_modulus_pa = s.model_youngs_modulus_pa;
  scene.material.poisson_ratio = s.model_poisson_ratio;
  nlohmann::json thin_meta = nlohmann::json::array();
  if (s.membrane) {  // a shell on the coarse mid-surface, held along the supports
    WriteSurfaceMesh(dir + "/membrane.obj", s.membrane->model_mid_surface);
    ThinStructure shell;
    shell.name = s.membrane->name;
    shell.type = ThinStructureType::kShell;
    shell.mesh_path = dir + "/membrane.obj";
    shell.thickness_mm = s.membrane->thickness_mm;
    shell.material = scene.material;
    shell.fixed_vertices = s.membrane->model_fixed_vertices;
    shell.color = Eigen::Vector3d(0.3, 0.8, 1.0);
    scene.thin_structures.push_back(shell);
    thin_meta.push_back({{"name", shell.name},
                         {"type", "shell"},
                         {"thickness_mm", shell.thickness_mm},
                         {"model_triangles", s.membrane->model_mid_surface.num_faces()}});
  }
  if (s.vessel) {  // a centreline tree inside the organ, tied to it
    WriteCentreline(dir + "/vessel.obj", *s.vessel, s.vessel->model_spacing_mm);
    ThinStructure vessel;
    vessel.name = s.vessel->name;
    vessel.type = ThinStructureType::kVessel;
    vessel.centreline_path = dir + "/vessel.obj";
    vessel.radius_mm = s.vessel->radius_mm;
    vessel.material = scene.material;
    vessel.attach = ThinAttachment::kModel;
    vessel.color = Eigen::Vector3d(0.9, 0.15, 0.2);
    scene.thin_structures.push_back(vessel);
    thin_meta.push_back({{"name", vessel.name},
                         {"type", "vessel"},
                         {"radius_mm", vessel.radius_mm},
                         {"truth_nodes", s.vessel->nodes.rows()}});
  }

  nlohmann::json volume = nlohmann::json::array();
  for (double r : summary.volume_ratio) volume.push_back(r);
  WriteJson(
      gt + "/meta.json",
      {{"units", "mm"},
       {"frames", options.frames},
       {"surface_every_k", options.surface_every_k},
       {"width", options.width},
       {"height", options.height},
       {"fps", options.fps},
       {"seed", options.seed},
       {"scenario", s.name},
       {"description", s.description},
       {"version", kVersion},
       {"generator",
        {{"amplitude", options.amplitude},
         {"zoom", options.zoom},
         {"nominal_stretch", s.nominal_stretch},
         {"fine_cell_mm", options.fine_cell_mm},
         {"kidney_cell_mm", options.kidney_cell_mm},
         {"noise_sigma", options.noise_sigma},
         {"blur_sigma_px", options.blur_sigma_px},
         {"occluder", options.occluder},
         {"supersampling", options.supersampling},
         {"crf", options.crf},
         {"video", options.write_video}}},
       {"truth",
        {{"material", "compressible neo-Hookean (Bonet-Wood), quasi-static Newton"},
         {"youngs_modulus_pa", s.truth_material.youngs_modulus_pa},
         {"poisson_ratio", s.truth_material.poisson_ratio},
         {"tetrahedra", summary.truth_tetrahedra},
         {"vertices", summary.truth_vertices},
         {"vertices_after_cut", summary.final_truth_vertices},
         {"newton_iterations", summary.newton_iterations},
         {"unconverged_frames", summary.unconverged_frames},
         {"volume_ratio", volume}}},
       {"model", {{"tetrahedra", summary.model_tetrahedra}, {"vertices", summary.model_vertices}}},
       {"thin_structures", thin_meta},
       {"mask",
        "union silhouette of everything registered (gt/surface and gt/thin) rasterised with the "
        "scene camera; the occluder is not part of it"}});
  // Written last: a scene file means the folder is complete (without --no-video
  // the video it names is absent).
  WriteScene(dir + "/scene.json", scene);
  summary.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return summary;
}

}  // namespace arreg::synth
