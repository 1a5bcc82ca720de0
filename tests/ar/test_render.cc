// Tests of the software rasterizer against analytic pixel counts and geometry.
#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/core.hpp>

#include "ar/render/rasterizer.h"

namespace arreg::render {
namespace {

RasterCamera TestCamera() {
  RasterCamera c;
  c.width = 64;
  c.height = 48;
  c.fx = c.fy = 100;
  c.cx = 31.5;
  c.cy = 23.5;
  return c;
}

// Axis-aligned square of half-size `a` at depth `z`, facing the camera.
void Square(double a, double z, double x0, RowMatX3d* v, RowMatX3i* f) {
  v->resize(4, 3);
  *v << x0 - a, -a, z, x0 + a, -a, z, x0 + a, a, z, x0 - a, a, z;
  f->resize(2, 3);
  *f << 0, 2, 1, 0, 3, 2;
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
    for (int x = 0; x < camera.width; ++x) {
      int sign = 0;
      bool inside = true;
      for (int k = 0; k < 3; ++k) {
        const int j = (k + 1) % 3;
        const double e = (px[j] - px[k]) * (y - py[k]) - (py[j] - py[k]) * (x - px[k]);
        const int s = e > 0 ? 1 : -1;
        if (sign == 0) sign = s;
        inside = inside && s == sign;
      }
      expected += inside;
    }
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

}  // namespace
}  // namespace arreg::render
