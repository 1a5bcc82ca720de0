#include "ar/synth/progressive_cut.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <numeric>

#include "ar/synth/shapes.h"
#include "core/error.h"
#include "core/mesh_ops.h"

namespace arreg::synth {

void ProgressiveCutOptions::Check() const {
  ARREG_CHECK_INPUT(snap_fraction >= 0 && snap_fraction < 0.5, "", "snap_fraction",
                    "must be in [0, 0.5)");
  ARREG_CHECK_INPUT(min_volume_fraction_after_snap > 0 && min_volume_fraction_after_snap < 1, "",
                    "min_volume_fraction_after_snap", "must be in (0, 1)");
  ARREG_CHECK_INPUT(snap_reference_mm >= 0, "", "snap_reference_mm", "must be >= 0");
}

namespace {
Eigen::Vector3d Centroid(const RowMatX3d& x, const RowMatX4i& tets, int t) {
  return 0.25 * (x.row(tets(t, 0)) + x.row(tets(t, 1)) + x.row(tets(t, 2)) + x.row(tets(t, 3)))
                    .transpose();
}
double TetVolume(const RowMatX3d& x, const RowMatX4i& tets, int t) {
  return SignedVolume(x.row(tets(t, 0)).transpose(), x.row(tets(t, 1)).transpose(),
                      x.row(tets(t, 2)).transpose(), x.row(tets(t, 3)).transpose());
}
}  // namespace

ProgressiveCut::ProgressiveCut(TetMesh* rest_mesh, const CutSurfaceSpec& spec,
                               const ProgressiveCutOptions& options)
    : tets_(rest_mesh->tetrahedra), num_vertices_(rest_mesh->num_vertices()) {
  options.Check();
  ARREG_CHECK_INPUT(spec.level_set && spec.progress_mm, "", "cut",
                    "level_set and progress_mm are required");
  RowMatX3d& x = rest_mesh->vertices;
  const int nt = static_cast<int>(tets_.rows());
  side_.resize(nt);
  for (int t = 0; t < nt; ++t) side_[t] = spec.level_set(Centroid(x, tets_, t)) < 0 ? -1 : 1;
  // Interior faces by sorted vertex triple.
  std::map<std::array<int, 3>, std::pair<int, int>> first;  // key -> (tet, local)
  for (int t = 0; t < nt; ++t) {
    for (int k = 0; k < 4; ++k) {
      std::array<int, 3> key = TetFace(tets_, t, k);
      std::sort(key.begin(), key.end());
      auto it = first.find(key);
      if (it == first.end()) {
        first.emplace(key, std::make_pair(t, k));
        continue;
      }
      int a = it->second.first, la = it->second.second, b = t, lb = k;
      Face face;
      const bool is_cut_candidate = side_[a] != side_[b];
      if (is_cut_candidate && side_[a] > 0) {
        std::swap(a, b);
        std::swap(la, lb);
      }
      face.tet_a = a;
      face.tet_b = b;
      face.local_a = la;
      const auto tri = TetFace(tets_, a, la);
      for (int i = 0; i < 3; ++i) {
        for (int c = 0; c < 4; ++c) {
          if (tets_(a, c) == tri[i]) face.corner_a[i] = c;
          if (tets_(b, c) == tri[i]) face.corner_b[i] = c;
        }
      }
      face.progress_mm = std::numeric_limits<double>::infinity();
      if (is_cut_candidate) {
        const Eigen::Vector3d centre =
            (x.row(tri[0]) + x.row(tri[1]) + x.row(tri[2])).transpose() / 3.0;
        face.progress_mm = spec.progress_mm(centre);
      }
      if (std::isfinite(face.progress_mm))
        faces_.push_back(face);
      else
        closed_interior_.push_back(face);
      first.erase(it);
    }
  }
  std::sort(faces_.begin(), faces_.end(), [](const Face& p, const Face& q) {
    return std::make_pair(p.tet_a, p.local_a) < std::make_pair(q.tet_a, q.local_a);
  });
  // Snap the cut faces' vertices onto the surface, undoing snaps that crush elements.
  if (options.snap_fraction > 0) {
    std::vector<std::vector<int>> incident(num_vertices_);
    for (int t = 0; t < nt; ++t)
      for (int k = 0; k < 4; ++k) incident[tets_(t, k)].push_back(t);
    std::vector<int> candidates;
    for (const Face& f : faces_)
      for (int i = 0; i < 3; ++i) candidates.push_back(tets_(f.tet_a, f.corner_a[i]));
    std::sort(candidates.begin(), candidates.end());
    candidates.erase(std::unique(candidates.begin(), candidates.end()), candidates.end());
    for (int v : candidates) {
      const Eigen::Vector3d p = x.row(v).transpose();
      const double phi = spec.level_set(p);
      if (phi == 0) continue;
      // Newton projection onto the zero set (gradient by central differences).
      Eigen::Vector3d moved = p;
      bool ok_projection = true;
      for (int iter = 0; iter < 20; ++iter) {
        const double value = spec.level_set(moved);
        if (std::abs(value) < 1e-12) break;
        const double h = 1e-5;
        Eigen::Vector3d grad;
        for (int c = 0; c < 3; ++c) {
          const Eigen::Vector3d e = h * Eigen::Vector3d::Unit(c);
          grad[c] = (spec.level_set(moved + e) - spec.level_set(moved - e)) / (2 * h);
        }
        if (grad.squaredNorm() < 1e-20) {
          ok_projection = false;
          break;
        }
        moved -= value * grad / grad.squaredNorm();
      }
      if (!ok_projection || std::abs(spec.level_set(moved)) > 1e-9) continue;
      double shortest = std::numeric_limits<double>::infinity();
      for (int t : incident[v])
        for (int k = 0; k < 4; ++k)
          if (tets_(t, k) != v)
            shortest = std::min(shortest, (x.row(tets_(t, k)) - p.transpose()).norm());
      if (options.snap_reference_mm > 0) shortest = options.snap_reference_mm;
      if ((moved - p).norm() > options.snap_fraction * shortest) continue;
      std::vector<double> before;
      for (int t : incident[v]) before.push_back(TetVolume(x, tets_, t));
      x.row(v) = moved.transpose();
      bool ok = true;
      for (size_t i = 0; i < incident[v].size() && ok; ++i)
        ok = TetVolume(x, tets_, incident[v][i]) >=
             options.min_volume_fraction_after_snap * before[i];
      if (ok)
        ++snapped_;
      else
        x.row(v) = p.transpose();
    }
  }
}

bool ProgressiveCut::Advance(double advance_mm) {
  bool changed = false;
  for (Face& f : faces_)
    if (!f.open && f.progress_mm <= advance_mm) f.open = changed = true;
  return changed;
}

int ProgressiveCut::num_open_faces() const {
  int n = 0;
  for (const Face& f : faces_) n += f.open;
  return n;
}

ProgressiveCut::Split ProgressiveCut::ComputeSplit() const {
  const int nt = static_cast<int>(tets_.rows());
  // Union-find over tetrahedron corners: corners of one vertex joined through
  // closed faces end up as the same split vertex.
  std::vector<int> parent(4 * nt);
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](int c) {
    while (parent[c] != c) c = parent[c] = parent[parent[c]];
    return c;
  };
  auto join = [&](const Face& f) {
    for (int i = 0; i < 3; ++i) {
      const int ra = find(4 * f.tet_a + f.corner_a[i]), rb = find(4 * f.tet_b + f.corner_b[i]);
      if (ra != rb) parent[std::max(ra, rb)] = std::min(ra, rb);
    }
  };
  for (const Face& f : closed_interior_) join(f);
  for (const Face& f : faces_)
    if (!f.open) join(f);
  // Corners of a vertex that are not face-connected still share a root when
  // they are joined through other closed faces; roots are the smallest corner.
  Split split;
  split.tetrahedra.resize(nt, 4);
  std::vector<int> id_of_root(4 * nt, -1);
  std::vector<bool> vertex_used(num_vertices_, false);
  split.origin.resize(num_vertices_);
  std::iota(split.origin.begin(), split.origin.end(), 0);
  for (int c = 0; c < 4 * nt; ++c) {
    const int root = find(c);
    if (id_of_root[root] < 0) {
      const int v = tets_(root / 4, root % 4);
      if (!vertex_used[v]) {
        vertex_used[v] = true;
        id_of_root[root] = v;
      } else {
        id_of_root[root] = static_cast<int>(split.origin.size());
        split.origin.push_back(v);
      }
    }
    split.tetrahedra(c / 4, c % 4) = id_of_root[root];
  }
  return split;
}

RowMatX3i ProgressiveCut::FaceTriangles() const {
  RowMatX3i out(faces_.size(), 3);
  for (size_t i = 0; i < faces_.size(); ++i) {
    // TetFace of tet_a is outward of the negative side, i.e. towards the positive side.
    const auto tri = TetFace(tets_, faces_[i].tet_a, faces_[i].local_a);
    out.row(i) << tri[0], tri[1], tri[2];
  }
  return out;
}

std::vector<double> ProgressiveCut::FaceProgress() const {
  std::vector<double> out;
  for (const Face& f : faces_) out.push_back(f.progress_mm);
  return out;
}

std::vector<bool> ProgressiveCut::FaceOpen() const {
  std::vector<bool> out;
  for (const Face& f : faces_) out.push_back(f.open);
  return out;
}

}  // namespace arreg::synth
