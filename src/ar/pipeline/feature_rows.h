// What the run keeps per feature and per internal structure: the rows tracking, lifting, the
// springs, the cut detector and the cut handler read and write.
#pragma once

#include <Eigen/Core>
#include <unordered_map>
#include <vector>

#include "ar/pipeline/frame_observer.h"
#include "core/mesh.h"
#include "mechanics/embedding.h"

namespace arreg::pipeline {

// One row per feature the run has taken on: frame 0's, then those re-detected and joined later
// (rows are only added; a lost feature keeps its row). Row r of every member is feature r.
struct FeatureRows {
  std::vector<FeatureView> views;
  std::unordered_map<int, int> row_of_id;  // tracker id -> row
  RowMatX2d pixels;                        // where the tracker has it [px]
  // The attachment point in the rest configuration [mm]: what the cut detector compares with.
  RowMatX3d rest_mm;
  RowMatX3d anchors_mm;                 // where its spring holds the model now [mm]
  RowMatX3d targets_mm;                 // its lifted target [mm]
  std::vector<char> tracked;            // tracked this frame
  std::vector<char> alive;              // its spring acts (the overlay's flag)
  mechanics::EmbeddedPoints embedding;  // in the organ's tetrahedra (rest barycentric)
  std::vector<int> thin_spring;         // its ThinSystem spring when on a shell, else -1

  int size() const { return static_cast<int>(views.size()); }
  // Grows every member but `views` and `row_of_id` to n rows; new rows are tracked, not alive,
  // on no shell, with zero coordinates.
  void Resize(int n) {
    const Eigen::Index old = pixels.rows();
    pixels.conservativeResize(n, 2);
    rest_mm.conservativeResize(n, 3);
    anchors_mm.conservativeResize(n, 3);
    targets_mm.conservativeResize(n, 3);
    for (Eigen::Index r = old; r < n; ++r) {
      pixels.row(r).setZero();
      rest_mm.row(r).setZero();
      anchors_mm.row(r).setZero();
      targets_mm.row(r).setZero();
    }
    tracked.resize(n, 1);
    alive.resize(n, 0);
    embedding.Resize(n);
    thin_spring.resize(n, -1);
  }
};

// The internal structures (tumour, vessels) embedded in the organ's tetrahedra.
struct EmbeddedStructures {
  std::vector<SurfaceMesh> surfaces;                 // current configuration
  std::vector<RowMatX3d> rest_mm;                    // rest vertices per structure
  std::vector<mechanics::EmbeddedPoints> embedding;  // per structure
  // The structures as loaded, in the rest frame: each cut splits them anew along the whole
  // crack. Without them (nullptr) a cut deletes their triangles crossing S.
  const std::vector<SurfaceMesh>* original = nullptr;
};

}  // namespace arreg::pipeline
