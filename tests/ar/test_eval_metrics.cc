// Dice, point-to-triangle distances and Hausdorff parts on cases with known answers.
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <random>

#include "ar/eval/dice.h"
#include "ar/eval/hausdorff.h"
#include "ar/eval/html.h"
#include "core/error.h"

namespace arreg::eval {
namespace {

// Unit-free square [x0, x0 + side] x [y0, y0 + side] at height z, two triangles.
SurfaceMesh Square(double x0, double y0, double z, double side = 1.0) {
  SurfaceMesh m;
  m.vertices.resize(4, 3);
  m.vertices << x0, y0, z, x0 + side, y0, z, x0 + side, y0 + side, z, x0, y0 + side, z;
  m.faces.resize(2, 3);
  m.faces << 0, 1, 2, 0, 2, 3;
  return m;
}

// Icosphere of the given radius: icosahedron subdivided `levels` times, vertices on the sphere.
SurfaceMesh Icosphere(double radius, int levels) {
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  std::vector<Eigen::Vector3d> v = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0},
                                    {0, -1, t}, {0, 1, t}, {0, -1, -t}, {0, 1, -t},
                                    {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
  std::vector<Eigen::Vector3i> f = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                                    {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                                    {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                                    {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
  for (auto& p : v) p.normalize();
  for (int level = 0; level < levels; ++level) {
    std::map<std::pair<int, int>, int> midpoint;
    const auto mid = [&](int a, int b) {
      const auto key = std::minmax(a, b);
      auto it = midpoint.find(key);
      if (it != midpoint.end()) return it->second;
      v.push_back((v[a] + v[b]).normalized());
      return midpoint[key] = static_cast<int>(v.size()) - 1;
    };
    std::vector<Eigen::Vector3i> next;
    for (const auto& tri : f) {
      const int ab = mid(tri[0], tri[1]), bc = mid(tri[1], tri[2]), ca = mid(tri[2], tri[0]);
      next.push_back({tri[0], ab, ca});
      next.push_back({tri[1], bc, ab});
      next.push_back({tri[2], ca, bc});
      next.push_back({ab, bc, ca});
    }
    f = next;
  }
  SurfaceMesh m;
  m.vertices.resize(v.size(), 3);
  for (size_t i = 0; i < v.size(); ++i) m.vertices.row(i) = radius * v[i].transpose();
  m.faces.resize(f.size(), 3);
  for (size_t i = 0; i < f.size(); ++i) m.faces.row(i) = f[i].transpose();
  return m;
}

TEST(Dice, OverlappingRectanglesGiveTheExactFraction) {
  cv::Mat a = cv::Mat::zeros(80, 100, CV_8U), b = cv::Mat::zeros(80, 100, CV_8U);
  a(cv::Rect(10, 10, 40, 30)).setTo(255);  // 1200 px
  b(cv::Rect(30, 20, 40, 30)).setTo(255);  // 1200 px, overlap 20 x 20 = 400 px
  const DiceCounts d = ComputeDice(a, b);
  EXPECT_EQ(d.area_a, 1200);
  EXPECT_EQ(d.area_b, 1200);
  EXPECT_EQ(d.intersection, 400);
  EXPECT_DOUBLE_EQ(d.dice, 1.0 / 3.0);
  EXPECT_DOUBLE_EQ(ComputeDice(a, a).dice, 1.0);
  cv::Mat far = cv::Mat::zeros(80, 100, CV_8U);
  far(cv::Rect(80, 60, 10, 10)).setTo(1);  // any non-zero value is inside
  EXPECT_DOUBLE_EQ(ComputeDice(a, far).dice, 0.0);
  EXPECT_DOUBLE_EQ(ComputeDice(cv::Mat::zeros(5, 5, CV_8U), cv::Mat::zeros(5, 5, CV_8U)).dice, 1.0);
}

TEST(Dice, RejectsMasksOfDifferentSizeOrType) {
  EXPECT_THROW(ComputeDice(cv::Mat::zeros(5, 5, CV_8U), cv::Mat::zeros(5, 6, CV_8U)), Error);
  EXPECT_THROW(ComputeDice(cv::Mat::zeros(5, 5, CV_8U), cv::Mat::zeros(5, 5, CV_32F)), Error);
  EXPECT_THROW(OverlapImage(cv::Mat::zeros(5, 5, CV_8U), cv::Mat::zeros(5, 6, CV_8U)), Error);
}

// The overlap image colours exactly the pixels the Dice counts: both, truth only, model only.
TEST(Dice, OverlapImageColoursThePixelsTheDiceCounts) {
  cv::Mat truth = cv::Mat::zeros(80, 100, CV_8U), model = cv::Mat::zeros(80, 100, CV_8U);
  truth(cv::Rect(10, 10, 40, 30)).setTo(255);
  model(cv::Rect(30, 20, 40, 30)).setTo(1);
  const cv::Mat image = OverlapImage(truth, model);
  ASSERT_EQ(image.type(), CV_8UC3);
  ASSERT_EQ(image.size(), truth.size());
  int both = 0, truth_only = 0, model_only = 0, neither = 0;
  for (int y = 0; y < image.rows; ++y)
    for (int x = 0; x < image.cols; ++x) {
      const cv::Vec3b p = image.at<cv::Vec3b>(y, x);
      both += p == kOverlapBoth;
      truth_only += p == kOverlapTruthOnly;
      model_only += p == kOverlapModelOnly;
      neither += p == cv::Vec3b(0, 0, 0);
    }
  const DiceCounts d = ComputeDice(truth, model);
  EXPECT_EQ(both, d.intersection);
  EXPECT_EQ(truth_only, d.area_a - d.intersection);
  EXPECT_EQ(model_only, d.area_b - d.intersection);
  EXPECT_EQ(both + truth_only + model_only + neither, 80 * 100);
  EXPECT_EQ(both, 400);
  EXPECT_EQ(truth_only, 800);
}

TEST(Silhouette, SquareFacingTheCameraCoversTheExpectedPixels) {
  PinholeCamera camera;
  camera.width = 100, camera.height = 80;
  camera.fx = camera.fy = 100;
  camera.cx = 49.5, camera.cy = 39.5;
  // 2 x 2 mm at 10 mm: u in [39.5, 59.5], v in [29.5, 49.5] -> pixel centres 40..59 x 30..49.
  SurfaceMesh square = Square(-1, -1, 10, 2);
  const cv::Mat silhouette = RenderSilhouette(camera, square);
  cv::Mat expected = cv::Mat::zeros(80, 100, CV_8U);
  expected(cv::Rect(40, 30, 20, 20)).setTo(255);
  const DiceCounts d = ComputeDice(silhouette, expected);
  EXPECT_EQ(d.area_a, 400);
  EXPECT_DOUBLE_EQ(d.dice, 1.0);
}

TEST(Silhouette, LensDistortionMovesTheVerticesToTheirDistortedPixels) {
  PinholeCamera camera;
  camera.width = 200, camera.height = 200;
  camera.fx = camera.fy = 150;
  camera.cx = camera.cy = 99.5;
  camera.distortion.k1 = -0.2;  // barrel: corners pulled towards the centre
  const SurfaceMesh square = Square(-4, -4, 10, 8);
  const RowMatX3d points = PointsForRaster(camera, square.vertices);
  for (int v = 0; v < 4; ++v) {
    const Eigen::Vector3d p = points.row(v).transpose();
    const Eigen::Vector2d raster_pixel(camera.fx * p.x() / p.z() + camera.cx,
                                       camera.fy * p.y() / p.z() + camera.cy);
    EXPECT_LT((raster_pixel - camera.Project(square.vertices.row(v).transpose())).norm(), 1e-9);
  }
  // The distorted silhouette is smaller than the undistorted one.
  PinholeCamera ideal = camera;
  ideal.distortion = Distortion();
  EXPECT_LT(cv::countNonZero(RenderSilhouette(camera, square)),
            cv::countNonZero(RenderSilhouette(ideal, square)));
}

TEST(ClosestPointOnTriangle, MatchesADenseSearchOverTheTriangle) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-2.0, 2.0);
  for (int trial = 0; trial < 200; ++trial) {
    const Eigen::Vector3d a(u(rng), u(rng), u(rng)), b(u(rng), u(rng), u(rng)),
        c(u(rng), u(rng), u(rng)), p(u(rng), u(rng), u(rng));
    const Eigen::Vector3d q = ClosestPointOnTriangle(p, a, b, c);
    // q lies in the triangle: barycentric coordinates in [0, 1].
    const Eigen::Vector3d n = (b - a).cross(c - a);
    const double area2 = n.squaredNorm();
    const double wa = (c - b).cross(q - b).dot(n) / area2, wb = (a - c).cross(q - c).dot(n) / area2;
    EXPECT_GE(wa, -1e-9);
    EXPECT_GE(wb, -1e-9);
    EXPECT_GE(1 - wa - wb, -1e-9);
    EXPECT_NEAR(std::abs((q - a).dot(n)) / std::sqrt(area2), 0.0, 1e-9);
    double best = std::numeric_limits<double>::infinity();
    const int n_steps = 200;
    for (int i = 0; i <= n_steps; ++i)
      for (int j = 0; i + j <= n_steps; ++j) {
        const Eigen::Vector3d s =
            a + (b - a) * (double(i) / n_steps) + (c - a) * (double(j) / n_steps);
        best = std::min(best, (s - p).norm());
      }
    const double d = (q - p).norm();
    EXPECT_LE(d, best + 1e-12);
    EXPECT_GT(d, best - 0.03);  // grid spacing bound
  }
}

TEST(ClosestPointOnTriangle, DegenerateTrianglesFallBackToTheSegment) {
  const Eigen::Vector3d a(0, 0, 0), b(1, 0, 0), c(2, 0, 0), p(1.5, 1, 0);
  EXPECT_LT((ClosestPointOnTriangle(p, a, b, c) - Eigen::Vector3d(1.5, 0, 0)).norm(), 1e-12);
  EXPECT_LT((ClosestPointOnTriangle(p, a, a, a) - a).norm(), 1e-12);
}

TEST(TriangleDistanceQuery, AgreesWithBruteForce) {
  const SurfaceMesh sphere = Icosphere(10.0, 3);
  const TriangleDistanceQuery query(sphere.vertices, sphere.faces);
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-15.0, 15.0);
  for (int trial = 0; trial < 300; ++trial) {
    const Eigen::Vector3d p(u(rng), u(rng), u(rng));
    double brute = std::numeric_limits<double>::infinity();
    for (int f = 0; f < sphere.num_faces(); ++f)
      brute = std::min(
          brute, (ClosestPointOnTriangle(p, sphere.vertices.row(sphere.faces(f, 0)).transpose(),
                                         sphere.vertices.row(sphere.faces(f, 1)).transpose(),
                                         sphere.vertices.row(sphere.faces(f, 2)).transpose()) -
                  p)
                     .norm());
    const auto r = query.Closest(p);
    EXPECT_DOUBLE_EQ(r.distance, brute);
    EXPECT_NEAR((r.closest_point - p).norm(), r.distance, 1e-12);
  }
}

TEST(Hausdorff, ParallelSquaresThreeApartAreThreeEverywhere) {
  const HausdorffResult h = ComputeHausdorff(Square(0, 0, 0), Square(0, 0, 3));
  EXPECT_NEAR(h.mean_model_to_gt, 3.0, 1e-12);
  EXPECT_NEAR(h.mean_gt_to_model, 3.0, 1e-12);
  EXPECT_NEAR(h.max_model_to_gt, 3.0, 1e-12);
  EXPECT_NEAR(h.max_gt_to_model, 3.0, 1e-12);
  EXPECT_NEAR(h.max, 3.0, 1e-12);
  EXPECT_EQ(h.samples_model, 4 + 20000);  // vertices + the minimum random count (area 1)
}

TEST(Hausdorff, ShiftedSquaresGiveTheAnalyticDirectedParts) {
  // B is A moved by (0.5, 0, 3). From A, points with x < 0.5 see B's edge:
  // d(x) = sqrt(9 + (0.5 - x)^2), else 3; both directions are symmetric.
  const HausdorffResult h = ComputeHausdorff(Square(0, 0, 0), Square(0.5, 0, 3));
  const double max_expected = std::sqrt(9.25);
  EXPECT_NEAR(h.max_model_to_gt, max_expected, 1e-12);
  EXPECT_NEAR(h.max_gt_to_model, max_expected, 1e-12);
  // Mean: 0.5 * 3 + integral_0^0.5 sqrt(9 + s^2) ds.
  const double s = 0.5;
  const double integral = 0.5 * (s * std::sqrt(9 + s * s) + 9 * std::asinh(s / 3.0));
  const double mean_expected = 1.5 + integral;
  EXPECT_NEAR(h.mean_model_to_gt, mean_expected, 1e-3 * mean_expected);
  EXPECT_NEAR(h.mean_gt_to_model, mean_expected, 1e-3 * mean_expected);
}

TEST(Hausdorff, SphereAgainstScaledSphere) {
  // Inscribed polyhedra of radius 10 and 12 (same triangulation). The outer
  // vertices see the inner vertices radially (the tangent plane of the
  // circumsphere supports the polyhedron): directed max outer->inner is 2 exactly.
  const SurfaceMesh inner = Icosphere(10.0, 4);
  SurfaceMesh outer = inner;
  outer.vertices *= 1.2;
  const HausdorffResult h = ComputeHausdorff(outer, inner);
  EXPECT_NEAR(h.max_model_to_gt, 2.0, 1e-9);
  EXPECT_LE(h.max_gt_to_model, 2.0 + 1e-9);
  // Fine triangulation: every distance is within 1 % of the radial gap.
  EXPECT_NEAR(h.mean_model_to_gt, 2.0, 0.02);
  EXPECT_NEAR(h.mean_gt_to_model, 2.0, 0.02);
  EXPECT_GT(h.max_gt_to_model, 1.98);
  EXPECT_DOUBLE_EQ(h.max, std::max(h.max_model_to_gt, h.max_gt_to_model));
  for (int v = 0; v < outer.num_vertices(); ++v)
    EXPECT_NEAR(h.model_vertex_distances[v], 2.0, 1e-9);
}

TEST(SampleSurface, IsDeterministicAndAreaUniform) {
  // Two squares of area 1 and 9: random samples split about 1 : 9.
  SurfaceMesh two = Square(0, 0, 0);
  const SurfaceMesh big = Square(5, 0, 0, 3);
  two.vertices.conservativeResize(8, 3);
  two.vertices.bottomRows(4) = big.vertices;
  two.faces.conservativeResize(4, 3);
  two.faces.bottomRows(2) = big.faces.array() + 4;
  SurfaceSamplingOptions o;
  o.samples_per_area = 1000;  // 10000 random samples
  o.min_random_samples = 0;
  const RowMatX3d s1 = SampleSurface(two, o), s2 = SampleSurface(two, o);
  ASSERT_EQ(s1.rows(), 8 + 10000);
  EXPECT_EQ(s1, s2);
  int on_small = 0;
  for (int i = 8; i < s1.rows(); ++i) on_small += s1(i, 0) <= 1.0;
  EXPECT_NEAR(on_small / 10000.0, 0.1, 0.015);
  o.seed = 2;
  EXPECT_NE(SampleSurface(two, o), s1);
  o.max_random_samples = -1;
  EXPECT_THROW(o.Check(), Error);
}

TEST(Html, Base64MatchesTheRfc4648Vectors) {
  const auto enc = [](const std::string& s) {
    return Base64Encode(std::vector<unsigned char>(s.begin(), s.end()));
  };
  EXPECT_EQ(enc(""), "");
  EXPECT_EQ(enc("f"), "Zg==");
  EXPECT_EQ(enc("fo"), "Zm8=");
  EXPECT_EQ(enc("foo"), "Zm9v");
  EXPECT_EQ(enc("foob"), "Zm9vYg==");
  EXPECT_EQ(enc("fooba"), "Zm9vYmE=");
  EXPECT_EQ(enc("foobar"), "Zm9vYmFy");
  EXPECT_EQ(HtmlEscape("a<b & \"c\""), "a&lt;b &amp; &quot;c&quot;");
}

TEST(Html, PlotHasOneSeriesGroupPerSeriesAndAPointPerSample) {
  PlotSeries a{"run", "#1f77b4", false, {{0, 0.5}, {1, 0.7}, {2, 0.9}}};
  PlotSeries b{"baseline", "#d62728", true, {{0, 0.4}, {2, 0.6}}};
  const std::string svg = SvgLinePlot("plot-x", "Dice", "frame", "Dice", {a, b}, 0.0, 1.0);
  const auto count = [&](const std::string& what) {
    size_t n = 0;
    for (size_t pos = svg.find(what); pos != std::string::npos; pos = svg.find(what, pos + 1)) ++n;
    return n;
  };
  EXPECT_EQ(count("<g class=\"series\""), 2u);
  EXPECT_EQ(count("<circle"), 5u);
  EXPECT_EQ(count("<polyline"), 2u);
  EXPECT_NE(svg.find("id=\"plot-x\""), std::string::npos);
}

}  // namespace
}  // namespace arreg::eval
