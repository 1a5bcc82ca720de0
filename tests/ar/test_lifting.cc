// Lifting of 2D features to 3D targets (thesis 7.4.2): BVH ray casts against brute force,
// exact plane and surface lifting, and the intercept-theorem update (eq. 7.1).
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "ar/lift/lifting.h"
#include "core/camera.h"
#include "core/error.h"

namespace arreg::lift {
namespace {

// Height field z = z0 + a sin(x / 17) cos(y / 11) over [x0, x1] x [y0, y1], n x n quads.
SurfaceMesh MakeBumpyPatch(double x0, double x1, double y0, double y1, double z0, double a, int n) {
  SurfaceMesh s;
  s.vertices.resize((n + 1) * (n + 1), 3);
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) {
      const double x = x0 + (x1 - x0) * i / n, y = y0 + (y1 - y0) * j / n;
      s.vertices.row(j * (n + 1) + i) << x, y, z0 + a * std::sin(x / 17.0) * std::cos(y / 11.0);
    }
  s.faces.resize(2 * n * n, 3);
  int f = 0;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const int v = j * (n + 1) + i;
      s.faces.row(f++) << v, v + 1, v + n + 2;
      s.faces.row(f++) << v, v + n + 2, v + n + 1;
    }
  return s;
}

// A camera at the origin looking along +z (world = camera frame), 640 x 480, f = 800 px.
PinholeCamera FrontCamera() {
  PinholeCamera c;
  c.width = 640;
  c.height = 480;
  c.fx = c.fy = 800.0;
  c.cx = 319.5;
  c.cy = 239.5;
  return c;
}

TEST(TriangleBvh, HitsEqualBruteForceOnRandomRays) {
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> u(-50.0, 50.0);
  // A random triangle soup (overlapping, all orientations) plus a bumpy patch.
  SurfaceMesh patch = MakeBumpyPatch(-40, 40, -30, 30, 20, 6, 30);
  const int soup = 600;
  RowMatX3d vertices(patch.num_vertices() + 3 * soup, 3);
  RowMatX3i faces(patch.num_faces() + soup, 3);
  vertices.topRows(patch.num_vertices()) = patch.vertices;
  faces.topRows(patch.num_faces()) = patch.faces;
  for (int t = 0; t < soup; ++t) {
    const Eigen::Vector3d c(u(rng), u(rng), u(rng));
    for (int k = 0; k < 3; ++k) {
      const int v = patch.num_vertices() + 3 * t + k;
      vertices.row(v) = (c + 0.1 * Eigen::Vector3d(u(rng), u(rng), u(rng))).transpose();
      faces(patch.num_faces() + t, k) = v;
    }
  }
  for (int leaf : {1, 4, 16}) {
    TriangleBvh bvh;
    TriangleBvhOptions o;
    o.max_leaf_triangles = leaf;
    bvh.Build(vertices, faces, o);
    for (int pass = 0; pass < 2; ++pass) {
      int hits = 0;
      for (int r = 0; r < 1500; ++r) {
        Ray ray;
        ray.origin_in_world = Eigen::Vector3d(u(rng), u(rng), u(rng) - 80.0);
        // Every third ray axis-aligned: zero direction components stress the slab test.
        ray.direction_in_world = r % 3 == 0 ? Eigen::Vector3d(0, 0, 1)
                                            : Eigen::Vector3d(u(rng), u(rng), u(rng)).normalized();
        RayHit a, b;
        const bool ha = bvh.Intersect(ray, &a), hb = bvh.IntersectBruteForce(ray, &b);
        ASSERT_EQ(ha, hb) << "ray " << r;
        if (!ha) continue;
        ++hits;
        EXPECT_EQ(a.face, b.face);
        EXPECT_DOUBLE_EQ(a.t, b.t);
        EXPECT_LT((a.point_mm - b.point_mm).norm(), 1e-12);
        EXPECT_NEAR(a.barycentric.sum(), 1.0, 1e-12);
      }
      EXPECT_GT(hits, 150) << "too few hits to compare";
      // Deform (same connectivity) and refit; the comparison must still hold.
      for (int v = 0; v < vertices.rows(); ++v)
        vertices(v, 2) += 3.0 * std::sin(vertices(v, 0) / 9.0);
      bvh.Refit(vertices);
    }
  }
}

TEST(TriangleBvh, RejectsBadFaces) {
  RowMatX3d v(3, 3);
  v << 0, 0, 0, 1, 0, 0, 0, 1, 0;
  RowMatX3i f(1, 3);
  f << 0, 1, 3;
  TriangleBvh bvh;
  EXPECT_THROW(bvh.Build(v, f), Error);
}

TEST(FitPlane, RecoversAPlaneAndRejectsCollinearPoints) {
  std::mt19937 rng(4);
  std::uniform_real_distribution<double> u(-20, 20);
  const Eigen::Vector3d n = Eigen::Vector3d(0.2, -0.4, 1.0).normalized();
  const Eigen::Vector3d q(3, 4, 100);
  RowMatX3d pts(50, 3);
  for (int i = 0; i < 50; ++i) {
    Eigen::Vector3d p(u(rng), u(rng), 0);
    p -= n * n.dot(p);
    pts.row(i) = (q + p).transpose();
  }
  const Plane plane = FitPlane(pts);
  EXPECT_NEAR(std::abs(plane.normal.dot(n)), 1.0, 1e-12);
  EXPECT_NEAR(plane.normal.dot(plane.point_mm - q), 0.0, 1e-9);
  RowMatX3d line(4, 3);
  line << 0, 0, 0, 1, 1, 1, 2, 2, 2, 3, 3, 3;
  EXPECT_THROW(FitPlane(line), Error);
}

TEST(FeatureLifter, PlaneLiftingReturnsThePointOnThePlane) {
  PinholeCamera camera = FrontCamera();
  camera.distortion.k1 = -0.2;  // the ray must undo the distortion
  camera.distortion.p1 = 0.001;
  camera.LookAt(Eigen::Vector3d(10, -5, -20), Eigen::Vector3d(0, 0, 120),
                Eigen::Vector3d(0, -1, 0));
  Plane plane;
  plane.normal = Eigen::Vector3d(0.1, 0.3, -1.0).normalized();
  plane.point_mm = Eigen::Vector3d(0, 0, 120);
  std::mt19937 rng(8);
  std::uniform_real_distribution<double> u(-25, 25);
  const int n = 40;
  RowMatX3d truth(n, 3);
  RowMatX2d pixels(n, 2);
  for (int i = 0; i < n; ++i) {
    Eigen::Vector3d p(u(rng), u(rng), 0);
    p -= plane.normal * plane.normal.dot(p);
    truth.row(i) = (plane.point_mm + p).transpose();
    pixels.row(i) = camera.Project(truth.row(i).transpose()).transpose();
  }
  FeatureLifterOptions o;
  o.target = LiftTarget::kPlane;
  FeatureLifter lifter(o);
  const std::vector<FeatureAttachment> att = lifter.Attach(camera, pixels, nullptr, plane);
  for (int i = 0; i < n; ++i) {
    ASSERT_TRUE(att[i].attached);
    EXPECT_LT((att[i].point_mm - truth.row(i).transpose()).norm(), 1e-9) << i;
  }
  // Next frame: the points slide in the plane; the targets follow exactly.
  const Eigen::Vector3d shift =
      Eigen::Vector3d(3, -2, 0) - plane.normal * plane.normal.dot(Eigen::Vector3d(3, -2, 0));
  for (int i = 0; i < n; ++i)
    pixels.row(i) = camera.Project(truth.row(i).transpose() + shift).transpose();
  const LiftSummary s = lifter.Update(camera, pixels, {}, nullptr);
  EXPECT_EQ(s.plane_hits, n);
  for (int i = 0; i < n; ++i)
    EXPECT_LT((lifter.targets_mm().row(i).transpose() - truth.row(i).transpose() - shift).norm(),
              1e-9);
}

TEST(FeatureLifter, SurfaceLiftingReturnsTheSurfacePoint) {
  const PinholeCamera camera = FrontCamera();
  const SurfaceMesh patch = MakeBumpyPatch(-30, 30, -20, 20, 100, 5, 24);
  std::mt19937 rng(6);
  std::uniform_int_distribution<int> face(0, patch.num_faces() - 1);
  std::uniform_real_distribution<double> w(0.05, 0.9);
  const int n = 60;
  RowMatX3d truth(n, 3);
  RowMatX2d pixels(n + 1, 2);
  std::vector<int> faces(n);
  for (int i = 0; i < n; ++i) {
    faces[i] = face(rng);
    double a = w(rng), b = w(rng) * (1 - a);
    const Eigen::Vector3d p = (1 - a - b) * patch.vertices.row(patch.faces(faces[i], 0)) +
                              a * patch.vertices.row(patch.faces(faces[i], 1)) +
                              b * patch.vertices.row(patch.faces(faces[i], 2));
    truth.row(i) = p.transpose();
    pixels.row(i) = camera.Project(p).transpose();
  }
  pixels.row(n) << 5, 5;  // the top-left corner sees past the patch
  FeatureLifter lifter;   // surface variant, plane fitted to the hits
  const std::vector<FeatureAttachment> att = lifter.Attach(camera, pixels, &patch, std::nullopt);
  for (int i = 0; i < n; ++i) {
    ASSERT_TRUE(att[i].attached) << i;
    EXPECT_LT((att[i].point_mm - truth.row(i).transpose()).norm(), 1e-9) << i;
    EXPECT_NEAR(att[i].ray_distance_mm, truth.row(i).norm(), 1e-9);
    // The attachment is on the triangle it was sampled from (the patch is a height field seen
    // from above, so the ray meets it once).
    EXPECT_EQ(att[i].face, faces[i]);
  }
  EXPECT_FALSE(att[n].attached);
  EXPECT_EQ(lifter.status()[n], LiftStatus::kNotAttached);
  // Fitted plane: near z = 100 (the bumps average out), facing the camera.
  EXPECT_GT(std::abs(lifter.plane().normal.z()), 0.95);
}

// Eq. 7.1 with a fronto-parallel plane: a feature moving off the silhouette keeps its camera
// depth and moves laterally by (pixel motion) x depth / f.
TEST(FeatureLifter, InterceptTheoremKeepsDepthOffTheSilhouette) {
  const PinholeCamera camera = FrontCamera();
  const SurfaceMesh patch = MakeBumpyPatch(-20, 20, -20, 20, 90, 4, 16);
  Plane plane;
  plane.point_mm = Eigen::Vector3d(0, 0, 120);
  plane.normal = Eigen::Vector3d(0, 0, 1);
  RowMatX2d pixels(3, 2);
  pixels << 330, 250, 300, 230, 340, 260;
  for (SurfaceUpdate update :
       {SurfaceUpdate::kInterceptTheorem, SurfaceUpdate::kRayCastWithFallback}) {
    FeatureLifterOptions o;
    o.surface_update = update;
    FeatureLifter lifter(o);
    const std::vector<FeatureAttachment> att = lifter.Attach(camera, pixels, &patch, plane);
    for (const auto& a : att) ASSERT_TRUE(a.attached);
    RowMatX3d start = lifter.targets_mm();
    // Move every feature 12 px per frame to the right for 20 frames: 240 px at ~90 mm is
    // ~27 mm, well past the patch's edge at x = 20 mm.
    RowMatX2d moved = pixels;
    for (int k = 1; k <= 20; ++k) {
      moved.col(0).array() += 12.0;
      lifter.Update(camera, moved, {}, &patch.vertices);
      for (int i = 0; i < 3; ++i) {
        const Eigen::Vector3d p = lifter.targets_mm().row(i).transpose();
        // On the new ray: reprojects onto the tracked pixel.
        EXPECT_LT((camera.Project(p) - moved.row(i).transpose()).norm(), 1e-6);
        const LiftStatus st = lifter.status()[i];
        if (st == LiftStatus::kIntercept) {
          // Depth carried: the camera z of the last surface target.
          EXPECT_NEAR(p.z(), start(i, 2), 1e-9) << "frame " << k;
        } else {
          ASSERT_EQ(st, LiftStatus::kSurfaceHit);
          EXPECT_EQ(update, SurfaceUpdate::kRayCastWithFallback);
          start(i, 2) = p.z();  // the next intercept carries this depth
        }
      }
    }
    // All three are past the patch now: the cast cannot hit, the intercept has taken over.
    for (int i = 0; i < 3; ++i) {
      EXPECT_EQ(lifter.status()[i], LiftStatus::kIntercept);
      EXPECT_GT(lifter.targets_mm()(i, 0), 20.0);
      // Lateral motion consistent with the pixels: x = (u - cx) z / f.
      EXPECT_NEAR(lifter.targets_mm()(i, 0), (moved(i, 0) - camera.cx) * start(i, 2) / camera.fx,
                  1e-9);
    }
  }
}

TEST(FeatureLifter, RayCastFollowsTheDeformedSurfaceAndKeepsLostTargets) {
  const PinholeCamera camera = FrontCamera();
  SurfaceMesh patch = MakeBumpyPatch(-30, 30, -30, 30, 100, 0, 10);
  FeatureLifterOptions o;
  o.surface_update = SurfaceUpdate::kRayCastWithFallback;
  FeatureLifter lifter(o);
  RowMatX2d pixels(2, 2);
  pixels << 320, 240, 360, 200;
  Plane plane;
  plane.point_mm = Eigen::Vector3d(0, 0, 100);
  const std::vector<FeatureAttachment> att = lifter.Attach(camera, pixels, &patch, plane);
  ASSERT_TRUE(att[0].attached && att[1].attached);
  // Two hits cannot define a plane: without one, Attach says so.
  EXPECT_THROW(FeatureLifter(o).Attach(camera, pixels, &patch, std::nullopt), Error);
  RowMatX3d deformed = patch.vertices;
  deformed.col(2).array() += 4.0;  // the model moves 4 mm away
  const RowMatX3d before = lifter.targets_mm();
  const LiftSummary s = lifter.Update(camera, pixels, {1, 0}, &deformed);
  EXPECT_EQ(s.surface_hits, 1);
  EXPECT_EQ(s.lost, 1);
  EXPECT_NEAR(lifter.targets_mm()(0, 2), 104.0, 1e-9);
  EXPECT_EQ(lifter.status()[1], LiftStatus::kLost);
  EXPECT_EQ(lifter.targets_mm().row(1), before.row(1));
  // A hit that jumps in depth beyond the limit is rejected in favour of eq. 7.1.
  deformed.col(2).array() += 30.0;
  lifter.Update(camera, pixels, {}, &deformed);
  EXPECT_EQ(lifter.status()[0], LiftStatus::kIntercept);
  EXPECT_NEAR(lifter.targets_mm()(0, 2), 104.0, 1e-9);
}

// Features that join later are cast against the surface as it stands then, appended after the
// first ones, and carried by eq. 7.1 from their own first frame: a feature whose pixel stays put
// keeps its target while the plane moves nothing.
TEST(FeatureLifter, FeaturesAttachedLaterHitTheCurrentSurface) {
  const PinholeCamera camera = FrontCamera();
  SurfaceMesh patch = MakeBumpyPatch(-30, 30, -30, 30, 100, 2, 10);
  FeatureLifter lifter;  // surface targets, eq. 7.1 updates
  RowMatX2d pixels(3, 2);
  pixels << 320, 240, 360, 200, 290, 270;
  lifter.Attach(camera, pixels, &patch, std::nullopt);
  RowMatX3d moved = patch.vertices;
  moved.col(2).array() += 6.0;  // the model now lies 6 mm farther
  RowMatX2d later(2, 2);
  later << 330, 250, 2000, 240;  // the second ray misses the patch
  const std::vector<FeatureAttachment> more =
      lifter.AttachMore(RaysThroughPixels(camera, later), &moved);
  ASSERT_EQ(more.size(), 2u);
  ASSERT_TRUE(more[0].attached);
  EXPECT_FALSE(more[1].attached);
  EXPECT_EQ(lifter.targets_mm().rows(), 5);
  EXPECT_EQ(lifter.status()[3], LiftStatus::kSurfaceHit);
  EXPECT_EQ(lifter.status()[4], LiftStatus::kNotAttached);
  // On the moved surface (its triangle, at the returned weights), on the ray.
  const Eigen::Vector3d p = more[0].point_mm;
  Eigen::Vector3d on_face = Eigen::Vector3d::Zero();
  for (int k = 0; k < 3; ++k)
    on_face += more[0].barycentric(k) * moved.row(patch.faces(more[0].face, k)).transpose();
  EXPECT_LT((p - on_face).norm(), 1e-9);
  EXPECT_NEAR(p.z(), 106.0 + 2 * std::sin(p.x() / 17.0) * std::cos(p.y() / 11.0), 0.1);
  const Eigen::Vector2d px = camera.Project(p);
  EXPECT_NEAR(px.x(), 330.0, 1e-6);
  EXPECT_NEAR(px.y(), 250.0, 1e-6);
  // Next frame, same pixels: every attached target stays where it is.
  RowMatX2d all(5, 2);
  all << pixels, later;
  const RowMatX3d before = lifter.targets_mm();
  lifter.Update(camera, all, {}, nullptr);
  for (int r : {0, 1, 2, 3}) EXPECT_LT((lifter.targets_mm().row(r) - before.row(r)).norm(), 1e-9);
  EXPECT_EQ(lifter.status()[4], LiftStatus::kNotAttached);
}

// A flat slab, front face at z = 100, back at 108, seen from the origin: a body that thins about
// its mid-plane (front 101, back 107) recedes by 1 mm in front. Eq. 7.1 alone keeps the targets
// at the plane's depth; with follow_model_thinning they move along their rays by the change of
// the half-thickness along each ray, which puts them on the new front face exactly (the slab's
// faces are parallel), and a second frame with the same state moves them no further.
TEST(FeatureLifter, FollowModelThinningPutsTargetsOnTheRecedingFrontFace) {
  const PinholeCamera camera = FrontCamera();
  const SurfaceMesh front = MakeBumpyPatch(-40, 40, -40, 40, 100, 0, 8);
  const SurfaceMesh back = MakeBumpyPatch(-40, 40, -40, 40, 108, 0, 8);
  SurfaceMesh slab;
  const int nv = static_cast<int>(front.vertices.rows());
  slab.vertices.resize(2 * nv, 3);
  slab.vertices << front.vertices, back.vertices;
  slab.faces.resize(2 * front.faces.rows(), 3);
  slab.faces << front.faces, back.faces.array() + nv;
  RowMatX2d pixels(3, 2);
  pixels << 320, 240, 500, 100, 150, 400;  // on the axis and up to 26 degrees off it
  RowMatX3d thinned = slab.vertices;
  thinned.topRows(nv).col(2).array() += 1.0;
  thinned.bottomRows(nv).col(2).array() -= 1.0;
  for (const bool follow : {false, true}) {
    FeatureLifterOptions o;
    o.follow_model_thinning = follow;
    FeatureLifter lifter(o);
    const std::vector<FeatureAttachment> att = lifter.Attach(camera, pixels, &slab, std::nullopt);
    for (const FeatureAttachment& a : att) ASSERT_TRUE(a.attached);
    for (int frame = 0; frame < 2; ++frame) {
      lifter.Update(camera, pixels, {}, &thinned);
      for (int r = 0; r < 3; ++r) {
        EXPECT_NEAR(lifter.targets_mm()(r, 2), follow ? 101.0 : 100.0, 1e-9) << r;
        const Eigen::Vector2d px = camera.Project(lifter.targets_mm().row(r).transpose());
        EXPECT_NEAR((px - pixels.row(r).transpose()).norm(), 0.0, 1e-6);
        EXPECT_EQ(lifter.status()[r], LiftStatus::kIntercept);
      }
    }
  }
  // A back face tilted by 45 degrees (a ray leaving through a side, not a slab's back): the chord
  // is no thickness, so its change moves no target.
  SurfaceMesh wedge = slab;
  wedge.vertices.bottomRows(nv).col(2) += wedge.vertices.bottomRows(nv).col(0);
  wedge.vertices.bottomRows(nv).col(2).array() += 40.0;
  RowMatX3d wedge_thinned = wedge.vertices;
  wedge_thinned.topRows(nv).col(2).array() += 1.0;
  wedge_thinned.bottomRows(nv).col(2).array() -= 1.0;
  {
    FeatureLifterOptions o;
    o.follow_model_thinning = true;
    FeatureLifter lifter(o);
    lifter.Attach(camera, pixels, &wedge, std::nullopt);
    lifter.Update(camera, pixels, {}, &wedge_thinned);
    for (int r = 0; r < 3; ++r) EXPECT_NEAR(lifter.targets_mm()(r, 2), 100.0, 1e-9) << r;
  }
  // Without the surface it cannot measure the thickness.
  FeatureLifterOptions o;
  o.follow_model_thinning = true;
  FeatureLifter lifter(o);
  lifter.Attach(camera, pixels, &slab, std::nullopt);
  EXPECT_THROW(lifter.Update(camera, pixels, {}, nullptr), Error);
}

TEST(FeatureLifterOptions, CheckNamesTheField) {
  FeatureLifterOptions o;
  o.max_depth_jump_mm = -1;
  try {
    o.Check();
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("max_depth_jump_mm"), std::string::npos);
  }
}

TEST(FeatureLifterOptions, FollowModelThinningNeedsTheInterceptUpdate) {
  FeatureLifterOptions o;
  o.follow_model_thinning = true;
  o.surface_update = SurfaceUpdate::kRayCastWithFallback;
  try {
    o.Check();
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("follow_model_thinning"), std::string::npos);
  }
}

}  // namespace
}  // namespace arreg::lift
