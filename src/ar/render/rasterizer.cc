#include "ar/render/rasterizer.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/error.h"

namespace arreg::render {

void RasterCamera::Check() const {
  ARREG_CHECK_INPUT(width > 0 && height > 0, "", "camera.width/height",
                    "image size must be positive, got ", width, "x", height);
  ARREG_CHECK_INPUT(fx > 0 && fy > 0, "", "camera.fx/fy", "focal lengths must be positive");
  ARREG_CHECK_INPUT(near_mm > 0, "", "camera.near_mm", "near plane must be positive");
}

RasterCamera ToRasterCamera(const PinholeCamera& camera) {
  RasterCamera raster;
  raster.width = camera.width;
  raster.height = camera.height;
  raster.fx = camera.fx;
  raster.fy = camera.fy;
  raster.cx = camera.cx;
  raster.cy = camera.cy;
  raster.camera_from_world = camera.camera_from_world;
  return raster;
}

RenderTarget::RenderTarget(const RasterCamera& camera, int supersampling)
    : camera_(camera), ss_(supersampling) {
  camera.Check();
  ARREG_CHECK_INPUT(supersampling >= 1 && supersampling <= 8, "", "supersampling",
                    "must be in [1, 8], got ", supersampling);
  sw_ = camera.width * ss_;
  sh_ = camera.height * ss_;
  depth_.assign(static_cast<size_t>(sw_) * sh_, std::numeric_limits<float>::infinity());
  id_.assign(depth_.size(), 0);
  color_.assign(depth_.size(), Eigen::Vector3f::Zero());
}

void RenderTarget::Clear(const Eigen::Vector3f& background_rgb) {
  std::fill(depth_.begin(), depth_.end(), std::numeric_limits<float>::infinity());
  std::fill(id_.begin(), id_.end(), 0);
  std::fill(color_.begin(), color_.end(), background_rgb);
}

void RenderTarget::ClearWith(const std::function<Eigen::Vector3f(double, double)>& background_rgb) {
  Clear(Eigen::Vector3f::Zero());
  for (int sy = 0; sy < sh_; ++sy)
    for (int sx = 0; sx < sw_; ++sx)
      color_[Index(sx, sy)] = background_rgb((sx + 0.5) / ss_ - 0.5, (sy + 0.5) / ss_ - 0.5);
}

namespace {

// Clips a camera-space triangle against z >= near (Sutherland-Hodgman); each
// output vertex carries its barycentric coordinates in the input triangle.
int ClipNear(const Eigen::Vector3d in[3], double near, Eigen::Vector3d out[4],
             Eigen::Vector3d out_bary[4]) {
  int n = 0;
  for (int i = 0; i < 3; ++i) {
    const int j = (i + 1) % 3;
    const bool in_i = in[i].z() >= near, in_j = in[j].z() >= near;
    Eigen::Vector3d bi = Eigen::Vector3d::Zero(), bj = Eigen::Vector3d::Zero();
    bi[i] = 1;
    bj[j] = 1;
    if (in_i) {
      out[n] = in[i];
      out_bary[n++] = bi;
    }
    if (in_i != in_j) {
      const double t = (near - in[i].z()) / (in[j].z() - in[i].z());
      out[n] = in[i] + t * (in[j] - in[i]);
      out_bary[n++] = bi + t * (bj - bi);
    }
  }
  return n;
}

// Antisymmetric tie rule: of the two triangles sharing an edge, exactly one owns
// samples lying on it.
inline bool OwnsEdge(double dx, double dy) { return dy > 0 || (dy == 0 && dx < 0); }

}  // namespace

int64_t RenderTarget::Draw(const RowMatX3d& vertices_in_world, const RowMatX3i& faces,
                           const RowMatX3d& normals, const FragmentShader& shader,
                           const DrawOptions& options) {
  ARREG_CHECK_INPUT(normals.rows() == 0 || normals.rows() == vertices_in_world.rows(), "",
                    "normals", "need one normal per vertex (", vertices_in_world.rows(), "), got ",
                    normals.rows());
  ARREG_CHECK_INPUT(options.opacity > 0 && options.opacity <= 1, "", "DrawOptions.opacity",
                    "must be in (0, 1]");
  const int nv = static_cast<int>(vertices_in_world.rows());
  std::vector<Eigen::Vector3d> p_cam(nv), n_cam(normals.rows() ? nv : 0);
  const Eigen::Matrix3d rotation = camera_.camera_from_world.linear();
  for (int i = 0; i < nv; ++i) {
    p_cam[i] = camera_.camera_from_world * Eigen::Vector3d(vertices_in_world.row(i).transpose());
    if (normals.rows()) n_cam[i] = (rotation * normals.row(i).transpose()).normalized();
  }
  int64_t written = 0;
  for (int f = 0; f < faces.rows(); ++f) {
    Eigen::Vector3d tri[3], nrm[3];
    for (int k = 0; k < 3; ++k) {
      const int v = faces(f, k);
      ARREG_CHECK_INPUT(v >= 0 && v < nv, "", "faces", "face ", f, " has vertex index ", v,
                        " outside [0, ", nv, ")");
      tri[k] = p_cam[v];
    }
    const Eigen::Vector3d face_normal = (tri[1] - tri[0]).cross(tri[2] - tri[0]);
    if (face_normal.squaredNorm() == 0) continue;
    const bool front = face_normal.dot(tri[0]) < 0;
    if (options.cull_back_faces && !front) continue;
    for (int k = 0; k < 3; ++k)
      nrm[k] = normals.rows() ? n_cam[faces(f, k)] : face_normal.normalized();
    Eigen::Vector3d clipped[4], bary[4];
    const int n = ClipNear(tri, camera_.near_mm, clipped, bary);
    for (int t = 1; t + 1 < n; ++t) {
      const Eigen::Vector3d sub[3] = {clipped[0], clipped[t], clipped[t + 1]};
      const double sub_bary[3][3] = {{bary[0][0], bary[0][1], bary[0][2]},
                                     {bary[t][0], bary[t][1], bary[t][2]},
                                     {bary[t + 1][0], bary[t + 1][1], bary[t + 1][2]}};
      Eigen::Vector3d sub_normals[3];
      for (int k = 0; k < 3; ++k)
        sub_normals[k] =
            sub_bary[k][0] * nrm[0] + sub_bary[k][1] * nrm[1] + sub_bary[k][2] * nrm[2];
      DrawTriangleInCamera(sub, sub_normals, sub_bary, f, front, shader, options, &written);
    }
  }
  return written;
}

void RenderTarget::DrawTriangleInCamera(const Eigen::Vector3d p[3], const Eigen::Vector3d n[3],
                                        const double bary_of_vertex[3][3], int face,
                                        bool front_facing, const FragmentShader& shader,
                                        const DrawOptions& options, int64_t* written) {
  // Screen positions in sample units: sample (i, j) is centred at (i, j).
  double sx[3], sy[3], inv_z[3];
  for (int k = 0; k < 3; ++k) {
    inv_z[k] = 1.0 / p[k].z();
    const double u = camera_.fx * p[k].x() * inv_z[k] + camera_.cx;
    const double v = camera_.fy * p[k].y() * inv_z[k] + camera_.cy;
    sx[k] = (u + 0.5) * ss_ - 0.5;
    sy[k] = (v + 0.5) * ss_ - 0.5;
  }
  int order[3] = {0, 1, 2};
  double area = (sx[1] - sx[0]) * (sy[2] - sy[0]) - (sy[1] - sy[0]) * (sx[2] - sx[0]);
  if (area == 0 || !std::isfinite(area)) return;
  if (area < 0) {
    std::swap(order[1], order[2]);
    area = -area;
  }
  const double ax = sx[order[0]], ay = sy[order[0]];
  const double bx = sx[order[1]], by = sy[order[1]];
  const double cx = sx[order[2]], cy = sy[order[2]];
  const int x0 = std::max(0, static_cast<int>(std::ceil(std::min({ax, bx, cx}))));
  const int x1 = std::min(sw_ - 1, static_cast<int>(std::floor(std::max({ax, bx, cx}))));
  const int y0 = std::max(0, static_cast<int>(std::ceil(std::min({ay, by, cy}))));
  const int y1 = std::min(sh_ - 1, static_cast<int>(std::floor(std::max({ay, by, cy}))));
  if (x0 > x1 || y0 > y1) return;
  const bool own_ab = OwnsEdge(bx - ax, by - ay), own_bc = OwnsEdge(cx - bx, cy - by),
             own_ca = OwnsEdge(ax - cx, ay - cy);
  const float alpha = options.opacity;
  Fragment frag;
  frag.face = face;
  frag.front_facing = front_facing;
  for (int y = y0; y <= y1; ++y) {
    for (int x = x0; x <= x1; ++x) {
      // Edge functions; e_bc is the weight of a, e_ca of b, e_ab of c.
      const double e_ab = (bx - ax) * (y - ay) - (by - ay) * (x - ax);
      const double e_bc = (cx - bx) * (y - by) - (cy - by) * (x - bx);
      const double e_ca = (ax - cx) * (y - cy) - (ay - cy) * (x - cx);
      if (e_ab < 0 || e_bc < 0 || e_ca < 0) continue;
      if ((e_ab == 0 && !own_ab) || (e_bc == 0 && !own_bc) || (e_ca == 0 && !own_ca)) continue;
      double b[3];
      b[order[0]] = e_bc / area;
      b[order[1]] = e_ca / area;
      b[order[2]] = e_ab / area;
      const double iz = b[0] * inv_z[0] + b[1] * inv_z[1] + b[2] * inv_z[2];
      const double z = 1.0 / iz;
      const size_t idx = Index(x, y);
      if (options.depth_test && z >= depth_[idx]) continue;
      double w[3];
      for (int k = 0; k < 3; ++k) w[k] = b[k] * inv_z[k] * z;
      frag.x = x;
      frag.y = y;
      frag.point_in_camera = w[0] * p[0] + w[1] * p[1] + w[2] * p[2];
      frag.normal_in_camera = (w[0] * n[0] + w[1] * n[1] + w[2] * n[2]).normalized();
      for (int c = 0; c < 3; ++c)
        frag.barycentric[c] =
            w[0] * bary_of_vertex[0][c] + w[1] * bary_of_vertex[1][c] + w[2] * bary_of_vertex[2][c];
      const Eigen::Vector3f rgb = shader ? shader(frag) : Eigen::Vector3f::Ones();
      if (alpha >= 1.0f)
        color_[idx] = rgb;
      else
        color_[idx] = alpha * rgb + (1.0f - alpha) * color_[idx];
      if (options.depth_write) {
        depth_[idx] = static_cast<float>(z);
        id_[idx] = options.id;
      }
      ++*written;
    }
  }
}

cv::Mat RenderTarget::ResolveBgr() const {
  cv::Mat out(camera_.height, camera_.width, CV_8UC3);
  const float norm = 1.0f / (ss_ * ss_);
  for (int v = 0; v < camera_.height; ++v) {
    auto* row = out.ptr<cv::Vec3b>(v);
    for (int u = 0; u < camera_.width; ++u) {
      Eigen::Vector3f sum = Eigen::Vector3f::Zero();
      for (int j = 0; j < ss_; ++j)
        for (int i = 0; i < ss_; ++i) sum += color_[Index(u * ss_ + i, v * ss_ + j)];
      sum *= norm;
      for (int c = 0; c < 3; ++c)
        row[u][2 - c] =
            static_cast<uchar>(std::lround(255.0f * std::min(1.0f, std::max(0.0f, sum[c]))));
    }
  }
  return out;
}

cv::Mat RenderTarget::ResolveMask(int id) const {
  cv::Mat out(camera_.height, camera_.width, CV_8U);
  for (int v = 0; v < camera_.height; ++v) {
    auto* row = out.ptr<uchar>(v);
    for (int u = 0; u < camera_.width; ++u) {
      int hits = 0;
      for (int j = 0; j < ss_; ++j)
        for (int i = 0; i < ss_; ++i) {
          const int sid = id_[Index(u * ss_ + i, v * ss_ + j)];
          hits += id < 0 ? (sid > 0) : (sid == id);
        }
      row[u] = 2 * hits > ss_ * ss_ ? 255 : 0;
    }
  }
  return out;
}

cv::Mat RenderMask(const RasterCamera& camera, const RowMatX3d& vertices_in_world,
                   const RowMatX3i& faces) {
  RenderTarget target(camera, 1);
  target.Clear(Eigen::Vector3f::Zero());
  target.Draw(vertices_in_world, faces, RowMatX3d(), nullptr);
  return target.ResolveMask();
}

Eigen::Vector3f ShadeBlinnPhong(const Eigen::Vector3f& albedo, const Fragment& fragment,
                                const ShadingOptions& options) {
  // Light and eye coincide at the camera centre, so the half vector is the view direction.
  const Eigen::Vector3d to_eye = -fragment.point_in_camera.normalized();
  Eigen::Vector3d normal = fragment.normal_in_camera;
  if (options.two_sided && normal.dot(to_eye) < 0) normal = -normal;
  const double n_dot_l = std::max(0.0, normal.dot(to_eye));
  const double spec = n_dot_l > 0 ? std::pow(n_dot_l, options.shininess) : 0.0;
  return albedo * (options.ambient + options.diffuse * static_cast<float>(n_dot_l)) +
         Eigen::Vector3f::Constant(options.specular * static_cast<float>(spec));
}

RowMatX3d VertexNormals(const RowMatX3d& vertices, const RowMatX3i& faces) {
  RowMatX3d normals;
  VertexNormals(vertices, faces, &normals);
  return normals;
}

void VertexNormals(const RowMatX3d& vertices, const RowMatX3i& faces, RowMatX3d* normals) {
  normals->setZero(vertices.rows(), 3);
  for (int f = 0; f < faces.rows(); ++f) {
    const Eigen::Vector3d a = vertices.row(faces(f, 0)), b = vertices.row(faces(f, 1)),
                          c = vertices.row(faces(f, 2));
    const Eigen::Vector3d n = (b - a).cross(c - a);  // length = 2 x area
    for (int k = 0; k < 3; ++k) normals->row(faces(f, k)) += n.transpose();
  }
  for (int i = 0; i < normals->rows(); ++i) {
    const double len = normals->row(i).norm();
    if (len > 0) normals->row(i) /= len;
  }
}

void ShadeVertices(const RowMatX3d& vertices, const RowMatX3d& normals,
                   const Eigen::Isometry3d& camera_from_world, const Eigen::Vector3f& albedo,
                   const ShadingOptions& options,
                   Eigen::Matrix<float, Eigen::Dynamic, 3, Eigen::RowMajor>* rgb) {
  const Eigen::Matrix3d r = camera_from_world.linear();
  rgb->resize(vertices.rows(), 3);
  Fragment f;
  f.front_facing = true;
  for (int v = 0; v < vertices.rows(); ++v) {
    f.point_in_camera = camera_from_world * vertices.row(v).transpose();
    const Eigen::Vector3d n = r * normals.row(v).transpose();
    f.normal_in_camera = n.squaredNorm() > 0 ? n.normalized() : Eigen::Vector3d(0, 0, -1);
    rgb->row(v) = ShadeBlinnPhong(albedo, f, options).transpose();
  }
}

}  // namespace arreg::render
