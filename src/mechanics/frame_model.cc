#include "mechanics/frame_model.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "mechanics/so3.h"

namespace arreg::mechanics {

namespace {

using internal::Concat;

// Clamps the negative eigenvalues of a symmetric 3x3 matrix to zero. A matrix
// whose principal minors are all non-negative is PSD already (no eigensolve).
Eigen::Matrix3d PositivePart(const Eigen::Matrix3d& m) {
  const double m01 = m(0, 0) * m(1, 1) - m(0, 1) * m(0, 1);
  const double m02 = m(0, 0) * m(2, 2) - m(0, 2) * m(0, 2);
  const double m12 = m(1, 1) * m(2, 2) - m(1, 2) * m(1, 2);
  if (m(0, 0) >= 0 && m(1, 1) >= 0 && m(2, 2) >= 0 && m01 >= 0 && m02 >= 0 && m12 >= 0 &&
      m.determinant() >= 0)
    return m;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig;
  eig.computeDirect(m);
  const Eigen::Vector3d values = eig.eigenvalues().cwiseMax(0.0);
  return eig.eigenvectors() * values.asDiagonal() * eig.eigenvectors().transpose();
}

// Second-order rotation block of f(phi) = P : (Exp(phi) B) at phi = 0:
// d2/dphi_k dphi_l = P : ((S_k S_l + S_l S_k) / 2) B = sym(Q) - tr(Q) I, Q = B P^T.
Eigen::Matrix3d RotationCurvature(const Eigen::Matrix3d& q) {
  return 0.5 * (q + q.transpose()) - q.trace() * Eigen::Matrix3d::Identity();
}

}  // namespace

FrameModel::FrameModel(const GeneralisedState& state, std::vector<int> frame_nodes,
                       const std::vector<FrameSample>& samples, const Material& material,
                       const FrameModelOptions& options)
    : frame_nodes_(std::move(frame_nodes)), material_(material), options_(options) {
  material_.Check();
  mu_ = material_.LameMuKpa();
  lambda_ = material_.LameLambdaKpa();
  for (size_t i = 0; i < frame_nodes_.size(); ++i) {
    const int node = frame_nodes_[i];
    if (node < 0 || node >= state.num_nodes() || !state.is_frame(node))
      throw Error("", Concat("frame_nodes[", i, "]"), "not a frame node of the state");
  }
  sample_begin_.push_back(0);
  for (size_t s = 0; s < samples.size(); ++s) {
    const FrameSample& sample = samples[s];
    const std::string where = Concat("samples[", s, "]");
    if (!(sample.volume_mm3 > 0)) throw Error("", where, "volume must be positive");
    const size_t k = sample.frames.size();
    if (k == 0 || sample.weights.size() != k || sample.weight_gradients.size() != k)
      throw Error("", where, "one weight and weight gradient per frame, at least one frame");
    double sum_w = 0;
    Eigen::Vector3d sum_g = Eigen::Vector3d::Zero();
    for (size_t j = 0; j < k; ++j) {
      sum_w += sample.weights[j];
      sum_g += sample.weight_gradients[j];
      const int f = sample.frames[j];
      if (f < 0 || f >= num_frames()) throw Error("", where, "frame index out of range");
      for (size_t m = 0; m < j; ++m)
        if (sample.frames[m] == f) throw Error("", where, "a frame listed twice");
    }
    if (std::abs(sum_w - 1) > 1e-8 || sum_g.norm() > 1e-8 * (1 + sample.weight_gradients[0].norm()))
      throw Error("", where, "weights are not a partition of unity");
    rest_position_.push_back(sample.rest_position);
    volume_.push_back(sample.volume_mm3);
    for (size_t j = 0; j < k; ++j) {
      const int node = frame_nodes_[sample.frames[j]];
      const Eigen::Matrix3d& rest_rotation = state.rest_rotation(node);
      const Eigen::Vector3d offset =
          sample.rest_position - state.rest_positions().row(node).transpose();
      const Eigen::Vector3d& g = sample.weight_gradients[j];
      pair_node_.push_back(node);
      pair_weight_.push_back(sample.weights[j]);
      pair_gradient_.push_back(g);
      pair_offset_.push_back(rest_rotation.transpose() * offset);
      pair_c_.push_back(rest_rotation.transpose() *
                        (offset * g.transpose() + sample.weights[j] * Eigen::Matrix3d::Identity()));
    }
    sample_begin_.push_back(static_cast<int>(pair_node_.size()));
  }
}

void FrameModel::AppendStencils(std::vector<std::vector<int>>* stencils) const {
  for (int s = 0; s < num_samples(); ++s)
    stencils->emplace_back(pair_node_.begin() + sample_begin_[s],
                           pair_node_.begin() + sample_begin_[s + 1]);
}

Eigen::Matrix3d FrameModel::DeformationGradient(const GeneralisedState& state, int s) const {
  Eigen::Matrix3d f = Eigen::Matrix3d::Zero();
  for (int p = sample_begin_[s]; p < sample_begin_[s + 1]; ++p) {
    const int node = pair_node_[p];
    f.noalias() += state.positions().row(node).transpose() * pair_gradient_[p].transpose();
    f.noalias() += state.rotation(node) * pair_c_[p];
  }
  return f;
}

Eigen::Vector3d FrameModel::SamplePosition(const GeneralisedState& state, int s) const {
  Eigen::Vector3d x = Eigen::Vector3d::Zero();
  for (int p = sample_begin_[s]; p < sample_begin_[s + 1]; ++p) {
    const int node = pair_node_[p];
    x += pair_weight_[p] *
         (state.positions().row(node).transpose() + state.rotation(node) * pair_offset_[p]);
  }
  return x;
}

double FrameModel::EnergyDensity(const Eigen::Matrix3d& f) const {
  const Eigen::Matrix3d e = 0.5 * (f.transpose() * f - Eigen::Matrix3d::Identity());
  const double tr = e.trace();
  return mu_ * e.squaredNorm() + 0.5 * lambda_ * tr * tr;
}

void FrameModel::Stress(const Eigen::Matrix3d& f, Eigen::Matrix3d* s, Eigen::Matrix3d* p) const {
  const Eigen::Matrix3d e = 0.5 * (f.transpose() * f - Eigen::Matrix3d::Identity());
  *s = 2 * mu_ * e + lambda_ * e.trace() * Eigen::Matrix3d::Identity();
  *p = f * *s;
}

double FrameModel::Value(const GeneralisedState& state) const {
  double energy = 0;
  for (int s = 0; s < num_samples(); ++s)
    energy += volume_[s] * EnergyDensity(DeformationGradient(state, s));
  return energy;
}

void FrameModel::AddGradient(const GeneralisedState& state, Eigen::VectorXd* gradient) const {
  for (int s = 0; s < num_samples(); ++s) {
    Eigen::Matrix3d stress, pk1;
    Stress(DeformationGradient(state, s), &stress, &pk1);
    pk1 *= volume_[s];
    for (int p = sample_begin_[s]; p < sample_begin_[s + 1]; ++p) {
      const int node = pair_node_[p];
      const int offset = state.dof_offset(node);
      // dF = dx g^T gives P : dF = dx . P g; dF = [phi]x B gives P : [phi]x B = phi . 2 axial(P
      // B^T).
      gradient->segment<3>(offset) += pk1 * pair_gradient_[p];
      const Eigen::Matrix3d b = state.rotation(node) * pair_c_[p];
      gradient->segment<3>(offset + 3) += 2 * Axial(pk1 * b.transpose());
    }
  }
}

void FrameModel::AddHessian(const GeneralisedState& state, double scale, HessianSink* sink) const {
  using Matrix9d = Eigen::Matrix<double, 9, 9>;
  using Matrix96d = Eigen::Matrix<double, 9, 6>;
  // J_j = d vec(F) / d(x_j, phi_j) (9 x 6, vec column-major) per frame of the
  // sample, and H_F = d2 psi / dF2 (9 x 9); the (i, j) block is J_i^T H_F J_j.
  std::vector<Matrix96d> jacobian, product;
  std::vector<Eigen::Matrix3d> b;
  const double r = std::sqrt(0.5);
  for (int s = 0; s < num_samples(); ++s) {
    const int begin = sample_begin_[s], k = sample_begin_[s + 1] - begin;
    const Eigen::Matrix3d f = DeformationGradient(state, s);
    Eigen::Matrix3d stress, pk1;
    Stress(f, &stress, &pk1);
    // Material: 2 mu sym(F^T dF) : sym(F^T dF) + lambda (F : dF)^2 (PSD), via
    // the Mandel rows of vec(dF) -> sym(F^T dF).
    Eigen::Matrix<double, 6, 9> mandel = Eigen::Matrix<double, 6, 9>::Zero();
    for (int row = 0; row < 3; ++row) {
      for (int p = 0; p < 3; ++p) mandel(p, row + 3 * p) = f(row, p);
      // (p, q) = (0, 1), (0, 2), (1, 2): sqrt(1/2) (F_rp dF_rq + F_rq dF_rp).
      const int pairs[3][2] = {{0, 1}, {0, 2}, {1, 2}};
      for (int m = 0; m < 3; ++m) {
        const int p = pairs[m][0], q = pairs[m][1];
        mandel(3 + m, row + 3 * q) += r * f(row, p);
        mandel(3 + m, row + 3 * p) += r * f(row, q);
      }
    }
    const Eigen::Map<const Eigen::Matrix<double, 9, 1>> f_vec(f.data());
    // Small fixed sizes: coefficient-wise (lazy) products beat Eigen's GEMM path.
    Matrix9d hf = 2 * mu_ * mandel.transpose().lazyProduct(mandel);
    hf.noalias() += lambda_ * f_vec * f_vec.transpose();
    // Geometric: S : sym(dF^T dF) = vec(dF)^T (S kron I3) vec(dF); PSD when S is.
    const Eigen::Matrix3d geometric_stress =
        options_.project_hessian ? PositivePart(stress) : stress;
    for (int c = 0; c < 3; ++c)
      for (int d = 0; d < 3; ++d)
        hf.block<3, 3>(3 * c, 3 * d).diagonal().array() += geometric_stress(c, d);
    jacobian.resize(k);
    product.resize(k);
    b.resize(k);
    for (int j = 0; j < k; ++j) {
      const int p = begin + j;
      b[j] = state.rotation(pair_node_[p]) * pair_c_[p];
      Matrix96d& jac = jacobian[j];
      jac.setZero();
      for (int a = 0; a < 3; ++a) {
        // x_a: dF = e_a g^T.
        for (int c = 0; c < 3; ++c) jac(a + 3 * c, a) = pair_gradient_[p][c];
        // phi_a: dF = [e_a]x B.
        const Eigen::Matrix3d dphi = Skew(Eigen::Vector3d::Unit(a)) * b[j];
        jac.col(3 + a) = Eigen::Map<const Eigen::Matrix<double, 9, 1>>(dphi.data());
      }
      product[j].noalias() = hf.lazyProduct(jac);
    }
    const double factor = scale * volume_[s];
    Eigen::Matrix<double, 6, 6> block;
    for (int i = 0; i < k; ++i)
      for (int j = i; j < k; ++j) {
        block.noalias() = jacobian[i].transpose().lazyProduct(product[j]);
        if (i == j) {
          // Second-order part of Exp: P : ((S_a S_b + S_b S_a) / 2) B.
          const Eigen::Matrix3d curvature = RotationCurvature(b[i] * pk1.transpose());
          block.bottomRightCorner<3, 3>() +=
              options_.project_hessian ? PositivePart(curvature) : curvature;
        }
        sink->AddBlock(pair_node_[begin + i], pair_node_[begin + j], block, factor);
      }
  }
}

void FrameModel::AddNodeInertia(const GeneralisedState& state,
                                std::vector<NodeInertia>* inertia) const {
  const double density = material_.DensityKgPerMm3();
  for (int s = 0; s < num_samples(); ++s) {
    double positive = 0;
    for (int p = sample_begin_[s]; p < sample_begin_[s + 1]; ++p)
      positive += std::max(pair_weight_[p], 0.0);
    const double mass = density * volume_[s];
    const double cube = std::cbrt(volume_[s]);
    for (int p = sample_begin_[s]; p < sample_begin_[s + 1]; ++p) {
      const double share = mass * std::max(pair_weight_[p], 0.0) / positive;
      const Eigen::Vector3d& l = pair_offset_[p];
      NodeInertia& node = (*inertia)[pair_node_[p]];
      node.mass_kg += share;
      node.body_inertia +=
          share * (l.squaredNorm() * Eigen::Matrix3d::Identity() - l * l.transpose() +
                   cube * cube / 6 * Eigen::Matrix3d::Identity());
    }
  }
}

double FrameModel::total_mass_kg() const {
  double volume = 0;
  for (double v : volume_) volume += v;
  return material_.DensityKgPerMm3() * volume;
}

FrameGravity::FrameGravity(const FrameModel* model, const Eigen::Vector3d& gravity_mm_s2,
                           bool project_hessian)
    : model_(model), gravity_(gravity_mm_s2), project_hessian_(project_hessian) {}

void FrameGravity::AppendStencils(std::vector<std::vector<int>>* stencils) const {
  for (int node : model_->frame_nodes()) stencils->push_back({node});
}

double FrameGravity::Value(const GeneralisedState& state) const {
  const double density = model_->material().DensityKgPerMm3();
  double energy = 0;
  for (int s = 0; s < model_->num_samples(); ++s)
    energy -=
        density * model_->sample_volume_mm3(s) * gravity_.dot(model_->SamplePosition(state, s));
  return energy;
}

void FrameGravity::AddGradient(const GeneralisedState& state, Eigen::VectorXd* gradient) const {
  const double density = model_->material().DensityKgPerMm3();
  for (int s = 0; s < model_->num_samples(); ++s) {
    const double mass = density * model_->sample_volume_mm3(s);
    for (int p = model_->sample_begin(s); p < model_->sample_begin(s + 1); ++p) {
      const int node = model_->pair_node(p);
      const double mw = mass * model_->pair_weight(p);
      const Eigen::Vector3d r = state.rotation(node) * model_->pair_offset(p);
      gradient->segment<3>(state.dof_offset(node)) -= mw * gravity_;
      // d(Exp(phi) r) = phi x r, so dE = -m w g . (phi x r) = -m w phi . (r x g).
      gradient->segment<3>(state.dof_offset(node) + 3) -= mw * r.cross(gravity_);
    }
  }
}

void FrameGravity::AddHessian(const GeneralisedState& state, double scale,
                              HessianSink* sink) const {
  const double density = model_->material().DensityKgPerMm3();
  // The energy is linear in x and in each R; only each frame's rotation block
  // (from the second-order part of Exp) is non-zero: -m w (sym(r g^T) - g.r I).
  std::vector<Eigen::Matrix3d> block(state.num_nodes(), Eigen::Matrix3d::Zero());
  for (int s = 0; s < model_->num_samples(); ++s) {
    const double mass = density * model_->sample_volume_mm3(s);
    for (int p = model_->sample_begin(s); p < model_->sample_begin(s + 1); ++p) {
      const int node = model_->pair_node(p);
      const Eigen::Vector3d r = state.rotation(node) * model_->pair_offset(p);
      block[node] -= mass * model_->pair_weight(p) * RotationCurvature(r * gravity_.transpose());
    }
  }
  Eigen::Matrix<double, 6, 6> h = Eigen::Matrix<double, 6, 6>::Zero();
  for (int node : model_->frame_nodes()) {
    h.bottomRightCorner<3, 3>() = project_hessian_ ? PositivePart(block[node]) : block[node];
    sink->AddBlock(node, node, h, scale);
  }
}

std::vector<int> AddFrameNodes(const RowMatX3d& frame_positions, GeneralisedState* state) {
  std::vector<int> nodes;
  for (int i = 0; i < frame_positions.rows(); ++i)
    nodes.push_back(
        state->AddFrameNode(frame_positions.row(i).transpose(), Eigen::Matrix3d::Identity()));
  return nodes;
}

}  // namespace arreg::mechanics
