#include "ar/synth/scenarios.h"

#include <cmath>
#include <limits>
#include <random>

#include "core/error.h"

namespace arreg::synth {

Eigen::Vector3d Timeline::At(double t) const {
  if (keys.empty()) return Eigen::Vector3d::Zero();
  if (t <= keys.front().first) return keys.front().second;
  for (size_t i = 1; i < keys.size(); ++i) {
    if (t <= keys[i].first) {
      const double span = keys[i].first - keys[i - 1].first;
      const double s = span > 0 ? (t - keys[i - 1].first) / span : 1.0;
      return keys[i - 1].second + s * (keys[i].second - keys[i - 1].second);
    }
  }
  return keys.back().second;
}

void ScenarioOptions::Check() const {
  ARREG_CHECK_INPUT(fine_cell_mm >= 1 && fine_cell_mm <= 10, "", "fine_cell_mm",
                    "must be in [1, 10] mm, got ", fine_cell_mm);
  ARREG_CHECK_INPUT(kidney_cell_mm >= 1 && kidney_cell_mm <= 6, "", "kidney_cell_mm",
                    "must be in [1, 6] mm, got ", kidney_cell_mm);
  ARREG_CHECK_INPUT(membrane_cell_mm >= 2 && membrane_cell_mm <= 10, "", "membrane_cell_mm",
                    "must be in [2, 10] mm, got ", membrane_cell_mm);
  ARREG_CHECK_INPUT(amplitude > 0 && amplitude <= 1.5, "", "amplitude", "must be in (0, 1.5], got ",
                    amplitude);
  ARREG_CHECK_INPUT(zoom >= 0.5 && zoom <= 4, "", "zoom", "must be in [0.5, 4], got ", zoom);
  ARREG_CHECK_INPUT(seed <= (uint64_t(1) << 53), "", "seed", "must be <= 2^53");
  ARREG_CHECK_INPUT(width >= 32 && height >= 32 && width <= 4096 && height <= 4096, "", "size",
                    "image size must be within 32..4096 px, got ", width, "x", height);
}

const std::vector<ScenarioInfo>& ListScenarios() {
  static const std::vector<ScenarioInfo> kList = {
      {"band-stretch",
       "silicone band 100 x 100 x 8 mm on a 40 mm stem, stretched to 186 % and released; no cut"},
      {"band-precut-side",
       "band with a 40 mm slit from the left side at mid-height, pulled up to 186 % and held "
       "there (the top partly leaves the view)"},
      {"band-precut-middle",
       "band with a 40 mm slit in the middle, pulled up to 166 % and held there"},
      {"band-cut-v",
       "soft band pulled outwards and up by its side edges (width 148 %), cut vertically from the "
       "top while filmed (50 mm), then torn (75 mm) while pulled to 180 %: opens into a V"},
      {"band-cut-s",
       "10x stiffer 12 mm band stretched upwards, S-shaped horizontal cut (55 mm), then torn (85 "
       "mm)"},
      {"kidney-cut",
       "kidney-like organ 100 x 27 x 55 mm with an internal structure 55 x 11 x 27 mm, cut across "
       "its long axis through part of the structure, then stretched along the axis"},
      {"membrane-cut",
       "thin sheet (80-100 x 50-70 mm, 1-2 mm thick, from the seed) held along two opposite "
       "edges, pulled and twisted by one of them, cut by scissors from its free edge while pulled"},
      {"membrane-tear",
       "the same sheet with an 8 mm notch in its free edge, pulled until it tears from the notch "
       "tip (the crack advances while the largest principal stress ahead of it exceeds the "
       "strength)"},
      {"vessel-cut",
       "kidney-like organ with an embedded vessel tree (trunk from the hilum, three branches), "
       "cut across one branch, then stretched along its axis"},
  };
  return kList;
}

namespace {

constexpr double kEps = 1e-6;
constexpr double kInf = std::numeric_limits<double>::infinity();

std::string Describe(const std::string& name) {
  for (const auto& info : ListScenarios())
    if (info.name == name) return info.description;
  return "";
}

// Uniform numbers in [0, 1) from the seed (same sequence on every platform: the standard
// distributions are implementation-defined, the Mersenne twister is not).
class SeedDraws {
 public:
  SeedDraws(uint64_t seed, uint64_t stream) : rng_(seed * 0x9E3779B97F4A7C15ULL + stream) {}
  double Next() { return static_cast<double>(rng_() >> 11) * 0x1.0p-53; }
  double In(double lo, double hi) { return lo + (hi - lo) * Next(); }

 private:
  std::mt19937_64 rng_;
};

PinholeCamera MakeCamera(const ScenarioOptions& o, const Eigen::Vector3d& eye,
                         const Eigen::Vector3d& target, const Eigen::Vector3d& up) {
  const double fov_x_deg = 2 * std::atan(std::tan(M_PI / 6) / o.zoom) * 180 / M_PI;
  PinholeCamera camera = PinholeCamera::FromFieldOfView(o.width, o.height, fov_x_deg);
  camera.LookAt(eye, target, up);
  return camera;
}

Timeline Keys(std::vector<std::pair<double, Eigen::Vector3d>> keys) {
  return Timeline{std::move(keys)};
}
Eigen::Vector3d Y(double v) { return Eigen::Vector3d(0, v, 0); }
Eigen::Vector3d X(double v) { return Eigen::Vector3d(v, 0, 0); }

// Band 100 x 100 x thickness on a 40 x 20 mm stem below it (x right, y up, z towards the camera).
Scenario MakeBand(const std::string& name, double thickness_mm, double youngs_pa,
                  const ScenarioOptions& o) {
  Scenario s;
  s.name = name;
  s.description = Describe(name);
  const std::vector<Eigen::AlignedBox3d> boxes = {
      Eigen::AlignedBox3d(Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(100, 100, thickness_mm)),
      Eigen::AlignedBox3d(Eigen::Vector3d(30, -20, 0), Eigen::Vector3d(70, 0, thickness_mm))};
  BoxUnionMeshOptions fine;
  const int layers = std::max(2, static_cast<int>(std::ceil(thickness_mm / 4.0 - 1e-9)));
  fine.cell_mm = Eigen::Vector3d(o.fine_cell_mm, o.fine_cell_mm, thickness_mm / layers);
  fine.tets_per_cell = 6;
  s.truth = MeshBoxUnion(boxes, fine);
  BoxUnionMeshOptions coarse;
  coarse.cell_mm = Eigen::Vector3d(10, 10, thickness_mm);
  coarse.tets_per_cell = 5;
  s.model = MeshBoxUnion(boxes, coarse);
  s.truth_material.youngs_modulus_pa = youngs_pa;
  s.model_youngs_modulus_pa = youngs_pa;
  s.grips.push_back({"stem",
                     [](const Eigen::Vector3d& p) { return p.y() <= -20 + kEps; },
                     Keys({{0.0, Eigen::Vector3d::Zero()}}),
                     {}});
  return s;
}

Grip TopGrip(Timeline t) {
  return {"top", [](const Eigen::Vector3d& p) { return p.y() >= 100 - kEps; }, std::move(t), {}};
}

Scenario BandStretch(const ScenarioOptions& o) {
  Scenario s = MakeBand("band-stretch", 8, 1.0e5, o);
  const double lift = 86 * o.amplitude;
  s.grips.push_back(TopGrip(Keys({{0.0, Y(0)}, {0.5, Y(lift)}, {1.0, Y(0)}})));
  s.nominal_stretch = 1 + lift / 100;
  s.camera = MakeCamera(o, {95, 20, 260}, {50, 80, 4}, {0, 1, 0});
  return s;
}

Scenario BandPrecut(const ScenarioOptions& o, bool side) {
  Scenario s = MakeBand(side ? "band-precut-side" : "band-precut-middle", 8, 1.0e5, o);
  // Thesis 7.7.1, figure 7.12: the precut bands are shown and evaluated under strains of 186 %
  // (cut from the side; "part of the object is not visible at the end of the video") and 166 %
  // (cut in the middle). The pull reaches that strain at t = 0.6 and is held to the last frame.
  const double lift = (side ? 86 : 66) * o.amplitude;
  s.grips.push_back(TopGrip(Keys({{0.0, Y(0)}, {0.6, Y(lift)}, {1.0, Y(lift)}})));
  s.nominal_stretch = 1 + lift / 100;
  CutSchedule cut;
  cut.surface.level_set = [](const Eigen::Vector3d& p) { return p.y() - 50; };
  if (side) {
    cut.surface.progress_mm = [](const Eigen::Vector3d& p) { return p.x() <= 40 ? p.x() : kInf; };
    cut.description = "slit y = 50 mm, x in [0, 40] mm, through the thickness";
  } else {
    cut.surface.progress_mm = [](const Eigen::Vector3d& p) {
      return std::abs(p.x() - 50) <= 20 ? std::abs(p.x() - 50) : kInf;
    };
    cut.description = "slit y = 50 mm, x in [30, 70] mm, through the thickness";
  }
  cut.advance_mm = Keys({{0.0, X(1e9)}});
  cut.length_mm = 40;
  cut.precut = true;
  s.cut = cut;
  s.camera = MakeCamera(o, {95, 20, 240}, {50, 65, 4}, {0, 1, 0});
  return s;
}

Scenario BandCutV(const ScenarioOptions& o) {
  Scenario s = MakeBand("band-cut-v", 8, 1.0e5, o);
  // Thesis 7.7.2, v-example: the band fixed at its stem is stretched "in its length and width",
  // cut vertically "almost at the maximal level of elongation before tearing", then torn until
  // it "resembles the letter v". The side edges are pulled outwards (width 148 %, then 180 %
  // during the tear) and up (116 %, then 124 %), so the two halves splay into the arms of a V
  // (opening ~80 mm at the top). 1.125 times these pulls and the truth's Newton solve no longer
  // converges in every frame (100 frames).
  const double a = 24 * o.amplitude, b = 40 * o.amplitude;
  const double ha = 16 * o.amplitude, hb = 24 * o.amplitude;
  const auto side = [](double sign, double dx, double dy) {
    return Eigen::Vector3d(sign * dx, dy, 0);
  };
  s.grips.push_back({"left",
                     [](const Eigen::Vector3d& p) { return p.x() <= kEps && p.y() >= 0; },
                     Keys({{0.0, side(-1, 0, 0)},
                           {0.25, side(-1, a, ha)},
                           {0.65, side(-1, a, ha)},
                           {0.9, side(-1, b, hb)}}),
                     {}});
  s.grips.push_back({"right",
                     [](const Eigen::Vector3d& p) { return p.x() >= 100 - kEps && p.y() >= 0; },
                     Keys({{0.0, side(1, 0, 0)},
                           {0.25, side(1, a, ha)},
                           {0.65, side(1, a, ha)},
                           {0.9, side(1, b, hb)}}),
                     {}});
  s.nominal_stretch = 1 + 2 * b / 100;
  CutSchedule cut;
  cut.surface.level_set = [](const Eigen::Vector3d& p) { return p.x() - 50; };
  cut.surface.progress_mm = [](const Eigen::Vector3d& p) {
    return 100 - p.y() <= 75 ? 100 - p.y() : kInf;
  };
  cut.advance_mm = Keys({{0.0, X(0)}, {0.3, X(0)}, {0.6, X(50)}, {0.7, X(50)}, {0.9, X(75)}});
  cut.length_mm = 75;
  cut.description = "vertical cut x = 50 mm from the top edge: 50 mm cut, then torn to 75 mm";
  s.cut = cut;
  s.camera = MakeCamera(o, {80, 5, 230}, {50, 45, 4}, {0, 1, 0});
  return s;
}

Scenario BandCutS(const ScenarioOptions& o) {
  Scenario s = MakeBand("band-cut-s", 12, 1.0e6, o);
  const double a = 20 * o.amplitude, b = 45 * o.amplitude;
  s.grips.push_back(TopGrip(Keys({{0.0, Y(0)}, {0.2, Y(a)}, {0.6, Y(a)}, {0.85, Y(b)}})));
  s.nominal_stretch = 1 + b / 100;
  CutSchedule cut;
  cut.surface.level_set = [](const Eigen::Vector3d& p) {
    return p.y() - 50 - 7 * std::sin(2 * M_PI * p.x() / 80);
  };
  cut.surface.progress_mm = [](const Eigen::Vector3d& p) { return p.x() <= 85 ? p.x() : kInf; };
  cut.advance_mm = Keys({{0.0, X(0)}, {0.2, X(0)}, {0.5, X(55)}, {0.6, X(55)}, {0.85, X(85)}});
  cut.length_mm = 85;
  cut.description =
      "S-shaped cut y = 50 + 7 sin(2 pi x / 80) mm from the left edge: 55 mm, torn to 85 mm";
  s.cut = cut;
  s.camera = MakeCamera(o, {85, 15, 250}, {50, 60, 6}, {0, 1, 0});
  return s;
}

Scenario KidneyCut(const ScenarioOptions& o) {
  Scenario s;
  s.name = "kidney-cut";
  s.description = Describe(s.name);
  KidneyShape shape;
  KidneyMeshOptions fine;
  fine.cell_size_mm = o.kidney_cell_mm;
  fine.facet_size_mm = o.kidney_cell_mm;
  s.truth = MeshKidney(shape, fine);
  KidneyMeshOptions coarse;
  coarse.cell_size_mm = 7.0;
  coarse.facet_size_mm = 7.0;
  coarse.facet_distance_mm = 1.0;
  s.model = MeshKidney(shape, coarse);
  s.has_internal_structure = true;
  s.truth_material.youngs_modulus_pa = 2.0e4;
  s.model_youngs_modulus_pa = 2.0e4;
  const double a = 18 * o.amplitude;
  s.grips.push_back({"left",
                     [](const Eigen::Vector3d& p) { return p.x() <= -42; },
                     Keys({{0.0, X(0)}, {0.5, X(0)}, {1.0, X(-a)}}),
                     {}});
  s.grips.push_back({"right",
                     [](const Eigen::Vector3d& p) { return p.x() >= 42; },
                     Keys({{0.0, X(0)}, {0.5, X(0)}, {1.0, X(a)}}),
                     {}});
  s.nominal_stretch = 1 + 2 * a / 84;
  CutSchedule cut;
  cut.surface.level_set = [](const Eigen::Vector3d& p) { return p.x() - 8; };
  cut.surface.progress_mm = [](const Eigen::Vector3d& p) {
    return 31 - p.z() <= 40 ? std::max(0.0, 31 - p.z()) : kInf;
  };
  cut.advance_mm = Keys({{0.0, X(0)}, {0.1, X(0)}, {0.45, X(40)}});
  cut.length_mm = 40;
  cut.description = "plane x = 8 mm across the long axis, from the top down to z = -9 mm";
  s.cut = cut;
  s.camera = MakeCamera(o, {20, -70, 160}, {0, 0, 8}, {0, 1, 0});
  return s;
}

// Sheet x in [0, L], y in [0, W], z in [0, thickness] (z towards the camera), held along its
// left and right edges; the right support pulls along x and twists about the sheet's x axis
// (so the free edges y = 0 and y = W leave the plane). Sizes, thickness, pull and twist come
// from the seed. Truth: 2 tetrahedron layers through the thickness (the vertex layer between
// them is the mid-surface), in-plane cells of about half --cell; model: a shell mesh of
// --membrane-cell (5 mm).
struct MembraneDraw {
  double length = 90, width = 60, thickness = 1.5, pull = 12, twist_rad = 0.3;
};

MembraneDraw DrawMembrane(uint64_t seed, double amplitude) {
  SeedDraws draw(seed, 35);
  MembraneDraw m;
  m.length = 80 + 5 * std::floor(draw.In(0, 5));  // 80..100 mm in 5 mm steps
  m.width = 50 + 5 * std::floor(draw.In(0, 5));   // 50..70 mm
  m.thickness = draw.In(1.0, 2.0);
  m.pull = m.length * draw.In(0.12, 0.18) * amplitude;  // 112-118 % stretch at amplitude 1
  m.twist_rad = (draw.Next() < 0.5 ? -1 : 1) * draw.In(10, 20) * M_PI / 180 * amplitude;
  return m;
}

Scenario MakeMembrane(const std::string& name, const MembraneDraw& m, const ScenarioOptions& o) {
  Scenario s;
  s.name = name;
  s.description = Describe(name);
  s.has_model = false;
  const double cell = 0.5 * o.fine_cell_mm;
  BoxUnionMeshOptions fine;
  fine.cell_mm =
      Eigen::Vector3d(m.length / std::max(1.0, std::round(m.length / cell)),
                      m.width / std::max(1.0, std::round(m.width / cell)), m.thickness / 2);
  fine.tets_per_cell = 6;
  s.truth = MeshBoxUnion({Eigen::AlignedBox3d(Eigen::Vector3d::Zero(),
                                              Eigen::Vector3d(m.length, m.width, m.thickness))},
                         fine);
  s.truth_material.youngs_modulus_pa = 1.0e5;
  s.model_youngs_modulus_pa = 1.0e5;
  MembraneSpec spec;
  spec.thickness_mm = m.thickness;
  spec.mid_z_mm = m.thickness / 2;
  const int nx = std::max(1, static_cast<int>(std::round(m.length / o.membrane_cell_mm))),
            ny = std::max(1, static_cast<int>(std::round(m.width / o.membrane_cell_mm)));
  SurfaceMesh& mid = spec.model_mid_surface;
  mid.vertices.resize((nx + 1) * (ny + 1), 3);
  for (int j = 0; j <= ny; ++j)
    for (int i = 0; i <= nx; ++i) {
      mid.vertices.row(j * (nx + 1) + i) << m.length * i / nx, m.width * j / ny, spec.mid_z_mm;
      // The model holds the static support only: the pulled one moves by an amount the
      // registration is not told (a grasper), so it is free and follows its features.
      if (i == 0) spec.model_fixed_vertices.push_back(j * (nx + 1) + i);
    }
  mid.faces.resize(2 * nx * ny, 3);
  for (int j = 0, f = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) {
      const int a = j * (nx + 1) + i, b = a + 1, c = a + nx + 1, d = c + 1;
      if ((i + j) % 2 == 0) {  // alternating diagonals: no preferred direction
        mid.faces.row(f++) << a, b, d;
        mid.faces.row(f++) << a, d, c;
      } else {
        mid.faces.row(f++) << a, b, c;
        mid.faces.row(f++) << b, d, c;
      }
    }
  s.membrane = spec;
  const double length = m.length, width = m.width, mid_z = spec.mid_z_mm;
  s.grips.push_back({"left",
                     [](const Eigen::Vector3d& p) { return p.x() <= kEps; },
                     Keys({{0.0, Eigen::Vector3d::Zero()}}),
                     {}});
  // The pull reaches 60 % in the first 30 % of the video, the rest while the sheet is cut or torn;
  // the twist is applied during the first 30 %.
  const Timeline pull = Keys({{0.0, X(0)}, {0.3, X(0.6 * m.pull)}, {1.0, X(m.pull)}});
  const double twist = m.twist_rad;
  Grip right{
      "right", [length](const Eigen::Vector3d& p) { return p.x() >= length - kEps; }, pull, {}};
  right.motion = [pull, twist, width, mid_z](const Eigen::Vector3d& p, double t) {
    const double angle = twist * std::min(1.0, t / 0.3);
    const Eigen::Vector3d axis_point(0, width / 2, mid_z);
    const Eigen::Vector3d q =
        axis_point + Eigen::AngleAxisd(angle, Eigen::Vector3d::UnitX()) * (p - axis_point);
    return Eigen::Vector3d(q + pull.At(t));
  };
  s.grips.push_back(right);
  s.nominal_stretch = 1 + m.pull / m.length;
  s.camera = MakeCamera(o, {0.5 * length + 25, 0.5 * width - 45, 135},
                        {0.5 * length + 0.5 * m.pull, 0.5 * width, 0}, {0, 1, 0});
  return s;
}

// A straight cut path from `start` along `dir` (unit, in the sheet plane): level set the signed
// distance to the line, progress the distance along it, up to `length_mm`.
CutSurfaceSpec StraightPath(const Eigen::Vector3d& start, const Eigen::Vector3d& dir,
                            const Eigen::Vector3d& plane_normal, double length_mm) {
  const Eigen::Vector3d normal = dir.cross(plane_normal).normalized();
  CutSurfaceSpec spec;
  spec.level_set = [start, normal](const Eigen::Vector3d& p) { return (p - start).dot(normal); };
  spec.progress_mm = [start, dir, length_mm](const Eigen::Vector3d& p) {
    const double along = (p - start).dot(dir);
    return along <= length_mm ? std::max(0.0, along) : kInf;
  };
  return spec;
}

Scenario MembraneCut(const ScenarioOptions& o) {
  const MembraneDraw m = DrawMembrane(o.seed, o.amplitude);
  Scenario s = MakeMembrane("membrane-cut", m, o);
  SeedDraws draw(o.seed, 36);
  const double x0 = m.length * draw.In(0.4, 0.6);
  const double angle = draw.In(-12, 12) * M_PI / 180;  // from the perpendicular to the pull
  const double depth = m.width * draw.In(0.5, 0.65);
  const Eigen::Vector3d dir(std::sin(angle), std::cos(angle), 0);
  CutSchedule cut;
  cut.surface = StraightPath(Eigen::Vector3d(x0, 0, 0), dir, Eigen::Vector3d::UnitZ(), depth);
  cut.options.snap_reference_mm = 0.5 * o.fine_cell_mm;  // in-plane cell, not the thickness
  cut.advance_mm = Keys({{0.0, X(0)}, {0.3, X(0)}, {0.8, X(depth)}});
  cut.length_mm = depth;
  char text[160];
  std::snprintf(text, sizeof(text),
                "straight scissor cut from the free edge y = 0 at x = %.1f mm, %.1f degrees from "
                "the y axis, %.1f mm long, through the thickness",
                x0, angle * 180 / M_PI, depth);
  cut.description = text;
  s.cut = cut;
  return s;
}

Scenario MembraneTear(const ScenarioOptions& o) {
  const MembraneDraw m = DrawMembrane(o.seed, o.amplitude);
  Scenario s = MakeMembrane("membrane-tear", m, o);
  SeedDraws draw(o.seed, 37);
  TearSpec tear;
  tear.notch_mm = 8;
  tear.notch_dir = Eigen::Vector3d::UnitY();
  tear.notch_tip = Eigen::Vector3d(m.length * draw.In(0.4, 0.6), tear.notch_mm, 0);
  // Strength relative to the modulus: the notched sheet tears during the second phase of the
  // pull at the nominal amplitude (docs/synth.md); the crack speed is bounded by one truth cell
  // per frame and the tear stops 15 % of the width short of the far edge.
  tear.strength_pa = 0.12 * s.truth_material.youngs_modulus_pa;
  tear.step_mm = 0.5 * o.fine_cell_mm;
  tear.max_length_mm = 0.85 * m.width;
  s.tear = tear;
  CutSchedule cut;  // the notch; the crack path is set by the generator (TearPath)
  cut.surface = TearPath(tear, tear.notch_dir);
  cut.options.snap_reference_mm = 0.5 * o.fine_cell_mm;  // in-plane cell, not the thickness
  cut.advance_mm = Keys({{0.0, X(tear.notch_mm)}});
  cut.length_mm = tear.notch_mm;
  cut.precut = true;
  cut.description = "8 mm notch from the free edge y = 0, torn from its tip by stress";
  s.cut = cut;
  return s;
}

// Vessel tree in the kidney: trunk from the hilum, three branches (towards both poles and the
// top), ends jittered by the seed; resampled every ~1 mm.
VesselSpec MakeVesselTree(const KidneyShape& shape, uint64_t seed) {
  SeedDraws draw(seed, 38);
  const auto jitter = [&](double x, double y, double z) {
    return Eigen::Vector3d(x + draw.In(-3, 3), y + draw.In(-1.5, 1.5), z + draw.In(-3, 3));
  };
  const Eigen::Vector3d hilum(0, 0, -14), fork(0, 0, -4);
  const std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> segments = {
      {hilum, fork},
      {fork, jitter(30, 2, 12)},
      {fork, jitter(-30, -2, 12)},
      {fork, jitter(0, 0, 18)}};
  VesselSpec v;
  std::vector<Eigen::Vector3d> nodes = {hilum, fork};
  for (size_t k = 0; k < segments.size(); ++k) {
    const auto& [a, b] = segments[k];
    const int n = std::max(1, static_cast<int>(std::ceil((b - a).norm() / 1.0)));
    std::vector<int> line = {k == 0 ? 0 : 1};
    for (int i = 1; i <= n; ++i) {
      if (k == 0 && i == n) {
        line.push_back(1);
        break;
      }
      nodes.push_back(a + (b - a) * (static_cast<double>(i) / n));
      line.push_back(static_cast<int>(nodes.size()) - 1);
    }
    v.polylines.push_back(line);
  }
  v.nodes.resize(static_cast<Eigen::Index>(nodes.size()), 3);
  for (size_t i = 0; i < nodes.size(); ++i) {
    ARREG_ASSERT(shape.Label(nodes[i]) > 0, "vessel node ", i, " outside the organ");
    v.nodes.row(static_cast<Eigen::Index>(i)) = nodes[i].transpose();
  }
  return v;
}

Scenario VesselCut(const ScenarioOptions& o) {
  Scenario s = KidneyCut(o);
  s.name = "vessel-cut";
  s.description = Describe(s.name);
  s.has_internal_structure = false;  // the vessel tree is the structure of interest here
  s.vessel = MakeVesselTree(KidneyShape(), o.seed);
  s.cut->description =
      "plane x = 8 mm across the long axis, from the top down to z = -9 mm, through the branch "
      "towards +x";
  return s;
}

}  // namespace

CutSurfaceSpec TearPath(const TearSpec& tear, const Eigen::Vector3d& crack_dir) {
  // Notch (straight, from the free edge to notch_tip) then the crack, straight from the tip:
  // the level set is the signed distance to the notch line before the tip and to the crack line
  // after it (both zero at the tip, continuous for a crack turning by less than 90 degrees).
  const Eigen::Vector3d n_dir = tear.notch_dir.normalized();
  const Eigen::Vector3d c_dir = crack_dir.normalized();
  const Eigen::Vector3d tip = tear.notch_tip, plane = tear.plane_normal.normalized();
  const Eigen::Vector3d n_normal = n_dir.cross(plane).normalized();
  Eigen::Vector3d c_normal = c_dir.cross(plane).normalized();
  const double notch = tear.notch_mm, max_length = tear.max_length_mm;
  CutSurfaceSpec spec;
  spec.level_set = [=](const Eigen::Vector3d& p) {
    return (p - tip).dot(n_dir) <= 0 ? (p - tip).dot(n_normal) : (p - tip).dot(c_normal);
  };
  spec.progress_mm = [=](const Eigen::Vector3d& p) {
    const double before = (p - tip).dot(n_dir);
    if (before <= 0) return std::max(0.0, notch + before);
    const double along = notch + (p - tip).dot(c_dir);
    return along <= std::max(max_length, notch) ? std::max(notch, along) : kInf;
  };
  return spec;
}

Scenario BuildScenario(const std::string& name, const ScenarioOptions& options) {
  options.Check();
  if (name == "band-stretch") return BandStretch(options);
  if (name == "band-precut-side") return BandPrecut(options, true);
  if (name == "band-precut-middle") return BandPrecut(options, false);
  if (name == "band-cut-v") return BandCutV(options);
  if (name == "band-cut-s") return BandCutS(options);
  if (name == "kidney-cut") return KidneyCut(options);
  if (name == "membrane-cut") return MembraneCut(options);
  if (name == "membrane-tear") return MembraneTear(options);
  if (name == "vessel-cut") return VesselCut(options);
  throw Error("", "scenario '" + name + "'", "unknown scenario (see arreg synth --list)");
}

}  // namespace arreg::synth
