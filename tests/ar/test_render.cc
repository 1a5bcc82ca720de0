// Tests of the software rasterizer against analytic pixel counts and geometry.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <random>

#include "ar/pipeline/overlay.h"
#include "ar/render/coverage_layer.h"
#include "ar/render/rasterizer.h"
#include "core/error.h"
#include "core/mesh_generators.h"
#include "core/mesh_ops.h"
#include "core/scene.h"

namespace arreg::render {
namespace {

// width x height pixels, principal point at the image centre.
RasterCamera TestCamera(int width = 64, int height = 48) {
  RasterCamera c;
  c.width = width;
  c.height = height;
  c.fx = c.fy = 100;
  c.cx = 0.5 * (width - 1);
  c.cy = 0.5 * (height - 1);
  return c;
}

// A camera of width x height pixels and focal length f (px), principal point at the image
// centre, at `eye` looking at the origin with +y up.
PinholeCamera CameraAt(int width, int height, double f, const Eigen::Vector3d& eye) {
  PinholeCamera camera;
  camera.width = width;
  camera.height = height;
  camera.fx = camera.fy = f;
  camera.cx = 0.5 * (width - 1);
  camera.cy = 0.5 * (height - 1);
  camera.LookAt(eye, Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(0, 1, 0));
  return camera;
}

// Axis-aligned square of half-size `a` at depth `z`, facing the camera.
void Square(double a, double z, double x0, RowMatX3d* v, RowMatX3i* f) {
  v->resize(4, 3);
  *v << x0 - a, -a, z, x0 + a, -a, z, x0 + a, a, z, x0 - a, a, z;
  f->resize(2, 3);
  *f << 0, 2, 1, 0, 3, 2;
}

// True when (x, y) is strictly on the same side of the three edges of the
// triangle (px, py) (either orientation), by the signs of the edge functions.
bool InsideTriangle(const double px[3], const double py[3], double x, double y) {
  int sign = 0;
  for (int k = 0; k < 3; ++k) {
    const int n = (k + 1) % 3;
    const double e = (px[n] - px[k]) * (y - py[k]) - (py[n] - py[k]) * (x - px[k]);
    const int s = e > 0 ? 1 : -1;
    if (sign == 0) sign = s;
    if (s != sign) return false;
  }
  return true;
}

TEST(Rasterizer, SquareMaskHasTheAnalyticPixelCount) {
  const RasterCamera camera = TestCamera();
  RowMatX3d v;
  RowMatX3i f;
  // Half-width 10.25 px around cx = 31.5: u in [21.25, 41.75] holds pixel centres 22..41
  // (20 columns); v in [13.25, 33.75] holds 14..33 (20 rows). The shared diagonal
  // must be counted once.
  Square(10.25, 100, 0, &v, &f);
  const cv::Mat mask = RenderMask(camera, v, f);
  EXPECT_EQ(cv::countNonZero(mask), 400);
  EXPECT_EQ(mask.at<uchar>(14, 22), 255);
  EXPECT_EQ(mask.at<uchar>(13, 22), 0);
  EXPECT_EQ(mask.at<uchar>(14, 21), 0);
  EXPECT_EQ(mask.at<uchar>(33, 41), 255);
  EXPECT_EQ(mask.at<uchar>(34, 41), 0);
}

TEST(Rasterizer, TriangleMaskMatchesPointInTriangleCount) {
  const RasterCamera camera = TestCamera();
  RowMatX3d v(3, 3);
  v << -0.203, -0.117, 1, 0.211, -0.033, 1, 0.017, 0.197, 1;  // depth 1: u = 100 x + 31.5
  RowMatX3i f(1, 3);
  f << 0, 1, 2;
  const cv::Mat mask = RenderMask(camera, v, f);
  int expected = 0;
  double px[3], py[3];
  for (int k = 0; k < 3; ++k) {
    px[k] = 100 * v(k, 0) + 31.5;
    py[k] = 100 * v(k, 1) + 23.5;
  }
  for (int y = 0; y < camera.height; ++y)
    for (int x = 0; x < camera.width; ++x) expected += InsideTriangle(px, py, x, y);
  EXPECT_GT(expected, 100);
  EXPECT_EQ(cv::countNonZero(mask), expected);
}

TEST(Rasterizer, NearerSurfaceWinsInEitherDrawOrder) {
  const RasterCamera camera = TestCamera();
  RowMatX3d far_v, near_v;
  RowMatX3i far_f, near_f;
  Square(20, 100, 0, &far_v, &far_f);
  Square(5, 50, 0, &near_v, &near_f);
  const Eigen::Vector3f red(1, 0, 0), green(0, 1, 0);
  for (int order = 0; order < 2; ++order) {
    RenderTarget target(camera);
    target.Clear(Eigen::Vector3f::Zero());
    auto draw_far = [&] { target.Draw(far_v, far_f, {}, [&](const Fragment&) { return red; }); };
    auto draw_near = [&] {
      target.Draw(near_v, near_f, {}, [&](const Fragment&) { return green; });
    };
    if (order == 0) {
      draw_far();
      draw_near();
    } else {
      draw_near();
      draw_far();
    }
    EXPECT_EQ(target.color(31, 23), green) << "order " << order;
    EXPECT_NEAR(target.depth(31, 23), 50.0f, 1e-4);
    EXPECT_EQ(target.color(15, 23), red) << "order " << order;  // outside the near square
    EXPECT_EQ(target.color(5, 23), Eigen::Vector3f::Zero()) << "order " << order;  // outside both
  }
}

TEST(Rasterizer, FragmentsLieOnTheSurfaceAndProjectToTheirPixel) {
  RasterCamera camera = TestCamera();
  camera.camera_from_world.translation() << 0.3, -0.2, 5.0;
  // A slanted quad: z varies with x, so affine interpolation would be wrong.
  RowMatX3d v(4, 3);
  v << -1, -1, 0, 1, -1, 4, 1, 1, 4, -1, 1, 0;
  RowMatX3i f(2, 3);
  f << 0, 1, 2, 0, 2, 3;
  RenderTarget target(camera);
  target.Clear(Eigen::Vector3f::Zero());
  double max_pixel_error = 0, max_plane_error = 0, max_bary_error = 0;
  int fragments = 0;
  target.Draw(v, f, {}, [&](const Fragment& frag) {
    const Eigen::Vector3d p = frag.point_in_camera;
    max_pixel_error =
        std::max({max_pixel_error, std::abs(camera.fx * p.x() / p.z() + camera.cx - frag.x),
                  std::abs(camera.fy * p.y() / p.z() + camera.cy - frag.y)});
    const Eigen::Vector3d world = camera.camera_from_world.inverse() * p;
    max_plane_error = std::max(max_plane_error, std::abs(world.z() - 2 * (world.x() + 1)));
    // The barycentric coordinates reproduce the world point from the face's vertices.
    Eigen::Vector3d from_bary = Eigen::Vector3d::Zero();
    for (int k = 0; k < 3; ++k)
      from_bary += frag.barycentric[k] * v.row(f(frag.face, k)).transpose();
    max_bary_error = std::max(max_bary_error, (from_bary - world).norm());
    ++fragments;
    return Eigen::Vector3f(1, 1, 1);
  });
  EXPECT_GT(fragments, 200);
  EXPECT_LT(max_pixel_error, 1e-9);
  EXPECT_LT(max_plane_error, 1e-9);
  EXPECT_LT(max_bary_error, 1e-9);
}

TEST(Rasterizer, ClipsAtTheNearPlane) {
  RasterCamera camera = TestCamera();
  camera.near_mm = 1.0;
  RowMatX3d v(3, 3);
  v << -1, 0.5, -2, 1, 0.5, -2, 0, 0.5, 10;  // two vertices behind the camera
  RowMatX3i f(1, 3);
  f << 0, 1, 2;
  RenderTarget target(camera);
  target.Clear(Eigen::Vector3f::Zero());
  double min_z = 1e9;
  const int64_t n = target.Draw(v, f, {}, [&](const Fragment& frag) {
    min_z = std::min(min_z, frag.point_in_camera.z());
    return Eigen::Vector3f(1, 1, 1);
  });
  EXPECT_GT(n, 0);
  EXPECT_GE(min_z, 1.0 - 1e-9);
}

TEST(Rasterizer, SupersamplingAveragesEdgeCoverage) {
  const RasterCamera camera = TestCamera();
  RowMatX3d v;
  RowMatX3i f;
  Square(10.25, 100, 0, &v, &f);
  RenderTarget target(camera, 3);
  target.Clear(Eigen::Vector3f::Zero());
  target.Draw(v, f, {}, [](const Fragment&) { return Eigen::Vector3f(1, 1, 1); });
  const cv::Mat bgr = target.ResolveBgr();
  // Column 21 spans u in [20.5, 21.5]; samples at 21 - 1/3, 21, 21 + 1/3: only the last
  // lies right of the edge u = 21.25, so the pixel is one third covered.
  EXPECT_EQ(bgr.at<cv::Vec3b>(20, 21)[0], 85);
  EXPECT_EQ(bgr.at<cv::Vec3b>(20, 30)[0], 255);
  EXPECT_EQ(cv::countNonZero(target.ResolveMask()), 400);
}

TEST(Rasterizer, OpacityBlendsOverWhatIsDrawn) {
  const RasterCamera camera = TestCamera();
  RowMatX3d far_v, near_v;
  RowMatX3i far_f, near_f;
  Square(20, 100, 0, &far_v, &far_f);
  Square(20, 50, 0, &near_v, &near_f);
  RenderTarget target(camera);
  target.Clear(Eigen::Vector3f::Zero());
  target.Draw(far_v, far_f, {}, [](const Fragment&) { return Eigen::Vector3f(1, 0, 0); });
  DrawOptions translucent;
  translucent.opacity = 0.25f;
  translucent.depth_write = false;
  target.Draw(
      near_v, near_f, {}, [](const Fragment&) { return Eigen::Vector3f(0, 1, 0); }, translucent);
  EXPECT_NEAR(target.color(31, 23)[0], 0.75f, 1e-6);
  EXPECT_NEAR(target.color(31, 23)[1], 0.25f, 1e-6);
  EXPECT_NEAR(target.depth(31, 23), 100.0f, 1e-4);
}

TEST(Rasterizer, BlinnPhongIsBrightestFacingTheLight) {
  Fragment facing, oblique;
  facing.point_in_camera = oblique.point_in_camera = Eigen::Vector3d(0, 0, 10);
  facing.normal_in_camera = Eigen::Vector3d(0, 0, -1);
  oblique.normal_in_camera = Eigen::Vector3d(0, std::sin(1.0), -std::cos(1.0));
  const ShadingOptions o;
  const Eigen::Vector3f albedo(0.5f, 0.5f, 0.5f);
  const Eigen::Vector3f a = ShadeBlinnPhong(albedo, facing, o);
  const Eigen::Vector3f b = ShadeBlinnPhong(albedo, oblique, o);
  EXPECT_NEAR(a[0], 0.5 * (o.ambient + o.diffuse) + o.specular, 1e-6);
  EXPECT_NEAR(b[0],
              0.5 * (o.ambient + o.diffuse * std::cos(1.0)) +
                  o.specular * std::pow(std::cos(1.0), o.shininess),
              1e-5);
}

// --- CoverageLayer (the overlay's one-sample-per-pixel rasterizer with analytic edge coverage).

using RowMatX3f = Eigen::Matrix<float, Eigen::Dynamic, 3, Eigen::RowMajor>;

RowMatX3f Uniform(int rows, const Eigen::Vector3f& rgb) {
  RowMatX3f c(rows, 3);
  c.rowwise() = rgb.transpose();
  return c;
}

// Fraction of pixel (x, y) inside the triangle (pixel coordinates), from 32 x 32 samples.
double ExactCoverage(const double px[3], const double py[3], int x, int y) {
  int hits = 0;
  for (int j = 0; j < 32; ++j)
    for (int i = 0; i < 32; ++i)
      hits += InsideTriangle(px, py, x - 0.5 + (i + 0.5) / 32, y - 0.5 + (j + 0.5) / 32);
  return hits / 1024.0;
}

TEST(CoverageLayer, TriangleCoverageMatchesTheAnalyticArea) {
  const RasterCamera camera = TestCamera(128, 96);
  CoverageLayer layer(camera);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> ux(5, 122), uy(5, 90);
  double worst_area_error = 0, worst_mean_pixel_error = 0, worst_pixel_error = 0;
  for (int trial = 0; trial < 20; ++trial) {
    double px[3], py[3];
    RowMatX3d v(3, 3);
    for (int k = 0; k < 3; ++k) {
      px[k] = ux(rng);
      py[k] = uy(rng);
      v.row(k) << (px[k] - camera.cx) / camera.fx, (py[k] - camera.cy) / camera.fy, 1.0;
    }
    const double area =
        0.5 * std::abs((px[1] - px[0]) * (py[2] - py[0]) - (py[1] - py[0]) * (px[2] - px[0]));
    if (area < 200) continue;  // slivers: the corner approximation dominates
    RowMatX3i f(1, 3);
    f << 0, 1, 2;
    layer.Clear({0, 0, camera.width, camera.height});
    layer.Draw(v, f, Uniform(3, Eigen::Vector3f(1, 1, 1)), CoverageDrawOptions());
    worst_area_error = std::max(worst_area_error, std::abs(layer.CoveredArea() - area) / area);
    // Pixel by pixel against a 32 x 32 supersampled coverage, over the edge pixels.
    double sum = 0;
    int edge_pixels = 0;
    for (int y = 0; y < camera.height; ++y)
      for (int x = 0; x < camera.width; ++x) {
        const double exact = ExactCoverage(px, py, x, y);
        const double error = std::abs(layer.alpha(x, y) - exact);
        if (exact > 0 && exact < 1) {
          sum += error;
          ++edge_pixels;
        }
        worst_pixel_error = std::max(worst_pixel_error, error);
      }
    worst_mean_pixel_error = std::max(worst_mean_pixel_error, sum / edge_pixels);
  }
  EXPECT_LT(worst_area_error, 0.01);        // total coverage = area within 1 %
  EXPECT_LT(worst_mean_pixel_error, 0.04);  // edge pixels: mean coverage error
  EXPECT_LT(worst_pixel_error, 0.35);       // worst pixel (acute corners)
}

TEST(CoverageLayer, MeshInteriorIsFullyCoveredWithoutCracks) {
  const RasterCamera camera = TestCamera();
  // A fan of 8 triangles around the centre of a square: interior edges use the fill rule.
  const double a = 10.3, z = 100;
  RowMatX3d v(9, 3);
  v.row(0) << 0.013, -0.021, z;
  for (int k = 0; k < 8; ++k) {
    const double t = k * M_PI / 4;
    const double r = a / std::max(std::abs(std::cos(t)), std::abs(std::sin(t)));
    v.row(1 + k) << r * std::cos(t) + 0.013, r * std::sin(t) - 0.021, z;
  }
  RowMatX3i f(8, 3);
  for (int k = 0; k < 8; ++k) f.row(k) << 0, 1 + k, 1 + (k + 1) % 8;
  CoverageLayer layer(camera);
  layer.Clear({0, 0, camera.width, camera.height});
  layer.Draw(v, f, Uniform(9, Eigen::Vector3f(1, 1, 1)), CoverageDrawOptions());
  // Square of side 2a px (fx = 1 px per unit at depth 100): its pixels at least one pixel
  // inside the border are covered exactly once.
  const double u0 = 31.5 + 0.013 - a, v0 = 23.5 - 0.021 - a;
  int interior = 0;
  for (int y = 0; y < camera.height; ++y)
    for (int x = 0; x < camera.width; ++x)
      if (x > u0 + 1 && x < u0 + 2 * a - 1 && y > v0 + 1 && y < v0 + 2 * a - 1) {
        ++interior;
        ASSERT_EQ(layer.alpha(x, y), 1.0f) << x << "," << y;
      }
  EXPECT_GT(interior, 300);
  EXPECT_NEAR(layer.CoveredArea(), 4 * a * a, 0.005 * 4 * a * a);
}

TEST(CoverageLayer, ColourAndDepthArePerspectiveCorrectInsideTheTriangle) {
  const RasterCamera camera = TestCamera(160, 120);
  // A triangle slanted in depth (z 40..160 mm) with one primary colour per corner.
  RowMatX3d v(3, 3);
  v << -30, -20, 40, 60, -10, 160, -5, 35, 90;
  RowMatX3i f(1, 3);
  f << 0, 1, 2;
  RowMatX3f rgb(3, 3);
  rgb << 1, 0, 0, 0, 1, 0, 0, 0, 1;
  CoverageLayer layer(camera);
  layer.Clear({0, 0, camera.width, camera.height});
  layer.Draw(v, f, rgb, CoverageDrawOptions());
  // Truth per pixel: the ray through the pixel centre meets the triangle's plane; the
  // barycentric coordinates of that 3D point weight the corner colours.
  const Eigen::Vector3d a = v.row(0), b = v.row(1), c = v.row(2);
  const Eigen::Vector3d n = (b - a).cross(c - a);
  int checked = 0;
  double worst_rgb = 0, worst_inv_depth = 0;
  for (int y = 0; y < camera.height; ++y)
    for (int x = 0; x < camera.width; ++x) {
      if (layer.alpha(x, y) != 1.0f) continue;  // the interior, where nothing is clamped
      const Eigen::Vector3d ray((x - camera.cx) / camera.fx, (y - camera.cy) / camera.fy, 1.0);
      const Eigen::Vector3d p = ray * (n.dot(a) / n.dot(ray));
      const double area = n.norm();
      const Eigen::Vector3d w((b - p).cross(c - p).norm() / area,
                              (c - p).cross(a - p).norm() / area,
                              (a - p).cross(b - p).norm() / area);
      ASSERT_NEAR(w.sum(), 1.0, 1e-9) << x << "," << y;  // p lies inside the triangle
      worst_rgb = std::max(worst_rgb, (layer.rgb(x, y).cast<double>() - w).cwiseAbs().maxCoeff());
      worst_inv_depth =
          std::max(worst_inv_depth, std::abs(layer.inverse_depth(x, y) * p.z() - 1.0));
      ++checked;
    }
  EXPECT_GT(checked, 1500);
  // The corners are snapped to 1/256 px, which moves the weights by up to ~(1/512 px) / (size of
  // the triangle, ~100 px); affine instead of perspective interpolation would be off by ~0.1.
  EXPECT_LT(worst_rgb, 1e-4);        // colours in [0, 1]
  EXPECT_LT(worst_inv_depth, 1e-4);  // relative
}

TEST(CoverageLayer, NearerSurfaceWinsInEitherDrawOrder) {
  const RasterCamera camera = TestCamera();
  RowMatX3d far_v, near_v;
  RowMatX3i far_f, near_f;
  Square(20, 100, 0, &far_v, &far_f);
  Square(5, 50, 0, &near_v, &near_f);
  const Eigen::Vector3f red(1, 0, 0), green(0, 1, 0);
  CoverageLayer layer(camera);
  for (int order = 0; order < 2; ++order) {
    layer.Clear({0, 0, camera.width, camera.height});
    for (int k = 0; k < 2; ++k) {
      if ((k == 0) == (order == 0))
        layer.Draw(far_v, far_f, Uniform(4, red), CoverageDrawOptions());
      else
        layer.Draw(near_v, near_f, Uniform(4, green), CoverageDrawOptions());
    }
    EXPECT_TRUE(layer.rgb(31, 23).isApprox(green, 1e-6f)) << "order " << order;
    EXPECT_NEAR(layer.inverse_depth(31, 23), 1.0f / 50, 1e-7);
    EXPECT_EQ(layer.alpha(31, 23), 1.0f);
    EXPECT_TRUE(layer.rgb(15, 23).isApprox(red, 1e-6f)) << "order " << order;
    EXPECT_EQ(layer.alpha(5, 23), 0.0f) << "order " << order;  // outside both
    // The near square's anti-aliased border blends with the far square behind it: the
    // pixel stays fully covered.
    EXPECT_EQ(layer.alpha(26, 23), 1.0f);
  }
}

TEST(CoverageLayer, ClearEmptiesWhatWasDrawnAndDrawsClipToTheRect) {
  const RasterCamera camera = TestCamera();
  RowMatX3d v;
  RowMatX3i f;
  Square(20, 100, 0, &v, &f);  // covers the whole 64 x 48 image but a border
  const RowMatX3f white = Uniform(4, Eigen::Vector3f(1, 1, 1));
  CoverageLayer layer(camera);
  layer.Clear({0, 0, camera.width, camera.height});
  layer.Draw(v, f, white, CoverageDrawOptions());
  EXPECT_NEAR(layer.CoveredArea(), 40.0 * 40.0, 1e-3);
  // The next frame's box is smaller: nothing of the last frame may remain, and nothing is
  // drawn outside the box.
  layer.Clear({20, 10, 30, 25});
  EXPECT_EQ(layer.CoveredArea(), 0.0);
  EXPECT_EQ(layer.alpha(31, 23), 0.0f);
  layer.Draw(v, f, white, CoverageDrawOptions());
  EXPECT_NEAR(layer.CoveredArea(), 10.0 * 15.0, 1e-3);
  for (int y = 0; y < camera.height; ++y)
    for (int x = 0; x < camera.width; ++x)
      ASSERT_EQ(layer.alpha(x, y), x >= 20 && x < 30 && y >= 10 && y < 25 ? 1.0f : 0.0f)
          << x << "," << y;
}

TEST(CoverageLayer, CullsBackFacesAndClipsAtTheNearPlane) {
  RasterCamera camera = TestCamera();
  RowMatX3d v;
  RowMatX3i f;
  Square(10, 100, 0, &v, &f);
  RowMatX3i reversed = f;
  reversed.col(1).swap(reversed.col(2));
  CoverageLayer layer(camera);
  layer.Clear({0, 0, camera.width, camera.height});
  CoverageDrawOptions cull;
  cull.cull_back_faces = true;
  const RowMatX3f white = Uniform(4, Eigen::Vector3f(1, 1, 1));
  EXPECT_GT(layer.Draw(v, f, white, cull), 300);
  layer.Clear({0, 0, camera.width, camera.height});
  EXPECT_EQ(layer.Draw(v, reversed, white, cull), 0);
  EXPECT_GT(layer.Draw(v, reversed, white, CoverageDrawOptions()), 300);  // two-sided

  camera.near_mm = 1.0;
  CoverageLayer clipped(camera);
  clipped.Clear({0, 0, camera.width, camera.height});
  RowMatX3d t(3, 3);
  t << -1, 0.5, -2, 1, 0.5, -2, 0, 0.5, 10;  // two vertices behind the camera
  RowMatX3i one(1, 3);
  one << 0, 1, 2;
  EXPECT_GT(clipped.Draw(t, one, Uniform(3, Eigen::Vector3f(1, 1, 1)), CoverageDrawOptions()), 0);
  float max_inverse_depth = 0;
  for (int y = 0; y < camera.height; ++y)
    for (int x = 0; x < camera.width; ++x)
      if (clipped.alpha(x, y) > 0)
        max_inverse_depth = std::max(max_inverse_depth, clipped.inverse_depth(x, y));
  EXPECT_GT(max_inverse_depth, 0.0f);
  EXPECT_LE(max_inverse_depth, 1.0f + 1e-5f);  // nothing nearer than the near plane
}

// The overlay's fast path (one sample per pixel, analytic edge coverage) against the reference
// rasterizer at 4 x 4 supersampling: a translucent organ over a textured frame with an
// internal structure inside it.
TEST(CoverageLayer, OverlayMatchesTheSupersampledReference) {
  const PinholeCamera camera = CameraAt(200, 160, 220, Eigen::Vector3d(30, -40, 160));
  SurfaceMesh organ = ExtractBoundary(MakeBoxTetMesh(Eigen::Vector3d(50, 40, 20), {5, 4, 2}));
  organ.vertices.rowwise() -= Eigen::RowVector3d(25, 20, 10);
  for (int i = 0; i < organ.vertices.rows(); ++i) {  // bulge it so that it is not flat-shaded
    const double x = organ.vertices(i, 0), y = organ.vertices(i, 1);
    organ.vertices(i, 2) += 6 * std::cos(x / 25 * M_PI / 2) * std::cos(y / 20 * M_PI / 2);
  }
  SurfaceMesh tumour = ExtractBoundary(MakeBoxTetMesh(Eigen::Vector3d(14, 10, 8), {1, 1, 1}));
  tumour.vertices.rowwise() -= Eigen::RowVector3d(7, 5, 4);
  cv::Mat frame(camera.height, camera.width, CV_8UC3);
  for (int y = 0; y < frame.rows; ++y)
    for (int x = 0; x < frame.cols; ++x)
      frame.at<cv::Vec3b>(y, x) = cv::Vec3b(60 + (x * 7 + y * 3) % 90, 40 + (x ^ y) % 60, 150);
  std::vector<pipeline::OverlayStructure> internal = {
      {&tumour.vertices, &tumour.faces, Eigen::Vector3d(1, 0.9, 0.1), 1.0, ""}};
  cv::Mat out[2];
  for (int k = 0; k < 2; ++k) {
    pipeline::RenderStageOptions o;
    o.style = pipeline::OverlayStyle::kTint;  // the surface fill is what the two paths share
    o.supersampling = k == 0 ? 1 : 4;
    pipeline::OverlayRenderer overlay(camera, o);
    out[k] = frame.clone();
    overlay.Render(organ.vertices, organ.faces, internal, pipeline::OverlayLayers(), &out[k]);
  }
  int drawn = 0, large = 0;
  double sum_abs = 0;
  for (int y = 0; y < frame.rows; ++y)
    for (int x = 0; x < frame.cols; ++x) {
      const cv::Vec3b f = frame.at<cv::Vec3b>(y, x), r = out[1].at<cv::Vec3b>(y, x),
                      t = out[0].at<cv::Vec3b>(y, x);
      if (f == r && f == t) continue;
      ++drawn;
      for (int c = 0; c < 3; ++c) {
        const int d = std::abs(int(t[c]) - int(r[c]));
        sum_abs += d;
        large += d > 24;
      }
    }
  ASSERT_GT(drawn, 3000);                   // the organ covers a good part of the image
  EXPECT_LT(sum_abs / (3.0 * drawn), 0.6);  // mean grey-level difference over the drawn pixels
  EXPECT_LT(large, 0.005 * drawn);          // large differences only at a few edge pixels
}

// Distance from p to the segment [a, b] (pixels).
double SegmentDistance(const cv::Point2d& p, const cv::Point2d& a, const cv::Point2d& b) {
  const cv::Point2d d = b - a;
  const double t = std::clamp((p - a).dot(d) / d.dot(d), 0.0, 1.0);
  return cv::norm(p - (a + t * d));
}

// The contour style on a box seen from a corner: silhouette pixels lie on the analytic
// silhouette (the convex hull of the projected corners), cut-edge pixels on the three edges
// that meet at the nearest corner (90 degree creases in view), none on the hidden edges or
// inside the faces, and both lines are complete.
TEST(Overlay, ContourLiesOnTheAnalyticSilhouetteAndCreases) {
  const PinholeCamera camera = CameraAt(240, 200, 260, Eigen::Vector3d(70, -90, 160));
  const Eigen::Vector3d size(50, 40, 30);
  SurfaceMesh box = ExtractBoundary(MakeBoxTetMesh(size, {5, 4, 3}));
  box.vertices.rowwise() -= 0.5 * size.transpose();
  const RasterCamera raster = ToRasterCamera(camera);
  std::vector<cv::Point2f> corners;
  std::vector<double> depth;
  std::vector<Eigen::Vector3d> world;
  for (int k = 0; k < 8; ++k) {
    const Eigen::Vector3d p(((k & 1) - 0.5) * size[0], (((k >> 1) & 1) - 0.5) * size[1],
                            (((k >> 2) & 1) - 0.5) * size[2]);
    const Eigen::Vector3d c = raster.camera_from_world * p;
    world.push_back(p);
    depth.push_back(c.z());
    corners.emplace_back(raster.fx * c.x() / c.z() + raster.cx,
                         raster.fy * c.y() / c.z() + raster.cy);
  }
  std::vector<cv::Point2f> hull;
  cv::convexHull(corners, hull);
  const int near = static_cast<int>(std::min_element(depth.begin(), depth.end()) - depth.begin());
  std::vector<std::pair<cv::Point2d, cv::Point2d>> creases;  // the three edges at `near`
  for (int bit = 0; bit < 3; ++bit) creases.push_back({corners[near], corners[near ^ (1 << bit)]});

  pipeline::RenderStageOptions o;  // the default style is the contour
  ASSERT_EQ(o.style, pipeline::OverlayStyle::kContour);
  o.legend = false;
  pipeline::OverlayRenderer overlay(camera, o);
  cv::Mat image(camera.height, camera.width, CV_8UC3, cv::Scalar(40, 40, 40));
  overlay.Render(box.vertices, box.faces, {}, pipeline::OverlayLayers(), &image);

  // Pixels more than half-way to the line colours (BGR): contour (51, 255, 25), cut (255, 217, 25).
  int contour_px = 0, cut_px = 0, other = 0;
  std::vector<cv::Point2d> contour_at, cut_at;
  for (int y = 0; y < image.rows; ++y)
    for (int x = 0; x < image.cols; ++x) {
      const cv::Vec3b p = image.at<cv::Vec3b>(y, x);
      const cv::Point2d q(x, y);
      const double to_hull = std::abs(cv::pointPolygonTest(hull, cv::Point2f(x, y), true));
      double to_crease = 1e9;
      for (const auto& e : creases)
        to_crease = std::min(to_crease, SegmentDistance(q, e.first, e.second));
      if (p[1] > 150 && p[0] < 120) {
        ++contour_px;
        contour_at.push_back(q);
        EXPECT_LE(to_hull, 1.5) << "contour pixel " << x << "," << y;
      } else if (p[0] > 150 && p[2] < 120) {
        ++cut_px;
        cut_at.push_back(q);
        EXPECT_LE(std::min(to_hull, to_crease), 1.5) << "cut-edge pixel " << x << "," << y;
      } else if (p != cv::Vec3b(40, 40, 40)) {
        ++other;
        EXPECT_LE(std::min(to_hull, to_crease), 2.5) << "drawn pixel " << x << "," << y;
      }
    }
  ASSERT_GT(contour_px, 300);
  ASSERT_GT(cut_px, 60);
  // Complete: every point of the silhouette and of the creases (their ends apart, where the
  // silhouette is drawn over them) has a pixel of its line within 1.5 px.
  const auto covered = [](const std::vector<cv::Point2d>& px, const cv::Point2d& p) {
    for (const cv::Point2d& q : px)
      if (cv::norm(q - p) <= 1.5) return true;
    return false;
  };
  for (size_t i = 0; i < hull.size(); ++i) {
    const cv::Point2d a = hull[i], b = hull[(i + 1) % hull.size()];
    const int n = static_cast<int>(cv::norm(b - a));
    for (int k = 0; k <= n; ++k)
      EXPECT_TRUE(covered(contour_at, a + (b - a) * (double(k) / std::max(n, 1))))
          << "silhouette gap near " << a + (b - a) * (double(k) / std::max(n, 1));
  }
  for (const auto& e : creases) {
    const double n = cv::norm(e.second - e.first);
    for (double s = 4; s <= n - 4; s += 1)
      EXPECT_TRUE(covered(cut_at, e.first + (e.second - e.first) * (s / n)))
          << "crease gap near " << e.first + (e.second - e.first) * (s / n);
  }
}

// The tint style leaves the outline undrawn: no pixel takes the contour colour.
TEST(Overlay, TintStyleDrawsNoContour) {
  const PinholeCamera camera = CameraAt(160, 120, 200, Eigen::Vector3d(0, 0, 150));
  SurfaceMesh box = ExtractBoundary(MakeBoxTetMesh(Eigen::Vector3d(40, 30, 20), {2, 2, 1}));
  box.vertices.rowwise() -= Eigen::RowVector3d(20, 15, 10);
  pipeline::RenderStageOptions o;
  o.style = pipeline::OverlayStyle::kTint;
  pipeline::OverlayRenderer overlay(camera, o);
  cv::Mat image(camera.height, camera.width, CV_8UC3, cv::Scalar(40, 40, 40));
  overlay.Render(box.vertices, box.faces, {}, pipeline::OverlayLayers(), &image);
  int tinted = 0, green = 0;
  for (int y = 0; y < image.rows; ++y)
    for (int x = 0; x < image.cols; ++x) {
      const cv::Vec3b p = image.at<cv::Vec3b>(y, x);
      tinted += p[2] > 60;  // the organ colour is mostly red
      green += p[1] > 150 && p[0] < 120;
    }
  EXPECT_GT(tinted, 1000);
  EXPECT_EQ(green, 0);
}

TEST(Overlay, RenderOptionsAreReadAndChecked) {
  Scene scene;
  scene.path = "scene.json";
  EXPECT_EQ(pipeline::ReadPipelineOptions(scene).render.style, pipeline::OverlayStyle::kContour);
  scene.render = {{"style", "tint"},
                  {"contour_width_px", 3},
                  {"legend", false},
                  {"cut_edge_angle_deg", 45},
                  {"contour_color", {1, 1, 0}}};
  const pipeline::RenderStageOptions o = pipeline::ReadPipelineOptions(scene).render;
  EXPECT_EQ(o.style, pipeline::OverlayStyle::kTint);
  EXPECT_EQ(o.contour_width_px, 3);
  EXPECT_FALSE(o.legend);
  EXPECT_TRUE(o.frame_counter);
  EXPECT_DOUBLE_EQ(o.cut_edge_angle_deg, 45);
  EXPECT_EQ(o.contour_color, Eigen::Vector3d(1, 1, 0));
  const auto error_of = [&](const nlohmann::json& render) {
    scene.render = render;
    try {
      pipeline::ReadPipelineOptions(scene);
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(error_of({{"style", "outline"}}).find("render.style"), std::string::npos);
  EXPECT_NE(error_of({{"contour_width_px", 0}}).find("render.contour_width_px"), std::string::npos);
  EXPECT_NE(error_of({{"cut_edge_angle_deg", 180}}).find("render.cut_edge_angle_deg"),
            std::string::npos);
  EXPECT_NE(error_of({{"cut_edge_color", {0, 2, 0}}}).find("render.cut_edge_color"),
            std::string::npos);
}

}  // namespace
}  // namespace arreg::render
