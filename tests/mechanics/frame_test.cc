// 6-DOF frame model (mechanics/frame_model.h): shape functions, derivatives
// against finite differences at rotations far from identity, rigid motions,
// zero modes, uniform stretch, lumped inertia.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <memory>
#include <random>

#include "core/error.h"
#include "core/mesh_generators.h"
#include "generalised_fd.h"
#include "mechanics/frame_model.h"
#include "mechanics/generalised_solver.h"
#include "mechanics/generalised_terms.h"
#include "mechanics/so3.h"
#include "mechanics/units.h"

namespace arreg::mechanics {
namespace {

constexpr double kPi = 3.14159265358979323846;

using testing::Gradient;
using testing::GradientAlong;
using testing::Hessian;
using testing::Perturbed;

// A soft tissue material (E = 3 kPa, nu = 0.45).
Material Tissue() { return Material{3000.0, 0.45, 1000.0}; }

// A model from a sampling: frame nodes added to a fresh state.
struct Model {
  GeneralisedState state;
  std::unique_ptr<FrameModel> model;
};

std::unique_ptr<Model> MakeModel(const FrameSampling& sampling, const FrameModelOptions& options,
                                 const Material& material = Tissue()) {
  auto m = std::make_unique<Model>();
  const std::vector<int> nodes = AddFrameNodes(sampling.frame_positions, &m->state);
  m->model = std::make_unique<FrameModel>(m->state, nodes, sampling.samples, material, options);
  return m;
}

FrameSampling HexSampling() { return SampleHexMesh(MakeBoxHexMesh({20, 10, 10}, {2, 1, 1}), 2); }
FrameSampling TetSampling() { return SampleTetMesh(MakeBoxTetMesh({20, 10, 10}, {2, 1, 1}), 4); }
// Meshless: the 12 frames of the 2x1x1 grid, 6x3x3 samples, MLS with
// support 16 mm (every sample sees 6 to 12 frames).
FrameSampling MlsSampling(int basis_order = 1) {
  const HexMesh frames = MakeBoxHexMesh({20, 10, 10}, {2, 1, 1});
  RowMatX3d positions;
  Eigen::VectorXd volumes;
  BoxCellCentres({20, 10, 10}, {6, 3, 3}, &positions, &volumes);
  MlsOptions options;
  options.support_radius_mm = 16;
  options.basis_order = basis_order;
  return SampleMls(frames.vertices, positions, volumes, options);
}

// Deforms every frame: random translations (amplitude mm) and each frame a
// different rotation about a random axis with an angle near `angle_rad`.
void Deform(GeneralisedState* state, double amplitude, double angle_rad, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int n = 0; n < state->num_nodes(); ++n) {
    state->mutable_positions().row(n) += amplitude * Eigen::RowVector3d(u(rng), u(rng), u(rng));
    const Eigen::Vector3d axis = Eigen::Vector3d(u(rng), u(rng), u(rng)).normalized();
    state->mutable_rotation(n) = ExpSO3((angle_rad + 0.1 * u(rng)) * axis) * state->rotation(n);
  }
}

void ExpectPartitionOfUnity(const FrameSampling& sampling) {
  for (const FrameSample& s : sampling.samples) {
    double sum_w = 0;
    Eigen::Vector3d sum_g = Eigen::Vector3d::Zero(), reproduced = Eigen::Vector3d::Zero();
    Eigen::Matrix3d identity = Eigen::Matrix3d::Zero();
    for (size_t j = 0; j < s.frames.size(); ++j) {
      const Eigen::Vector3d x = sampling.frame_positions.row(s.frames[j]).transpose();
      sum_w += s.weights[j];
      sum_g += s.weight_gradients[j];
      reproduced += s.weights[j] * x;
      identity += x * s.weight_gradients[j].transpose();
    }
    EXPECT_NEAR(sum_w, 1.0, 1e-12);
    EXPECT_LT(sum_g.norm(), 1e-12);
    EXPECT_LT((reproduced - s.rest_position).norm(), 1e-11);
    EXPECT_LT((identity - Eigen::Matrix3d::Identity()).norm(), 1e-11);
  }
}

TEST(FrameShapeFunctions, LinearCompletenessOfEveryKind) {
  ExpectPartitionOfUnity(TetSampling());
  ExpectPartitionOfUnity(HexSampling());
  ExpectPartitionOfUnity(MlsSampling());
}

TEST(FrameShapeFunctions, SampleVolumesAddUpToTheBody) {
  for (const FrameSampling& sampling : {TetSampling(), HexSampling(), MlsSampling()}) {
    double volume = 0;
    for (const FrameSample& s : sampling.samples) volume += s.volume_mm3;
    EXPECT_NEAR(volume, 2000.0, 1e-9);
  }
}

TEST(FrameShapeFunctions, MlsGradientMatchesFiniteDifferences) {
  const HexMesh frames = MakeBoxHexMesh({20, 10, 10}, {2, 1, 1});
  MlsOptions options;
  options.support_radius_mm = 16;
  const Eigen::Vector3d point(7.3, 4.1, 6.2);
  FrameSample s;
  EvaluateMls(frames.vertices, point, options, &s);
  const double h = 1e-5;
  for (int d = 0; d < 3; ++d) {
    FrameSample plus, minus;
    EvaluateMls(frames.vertices, point + h * Eigen::Vector3d::Unit(d), options, &plus);
    EvaluateMls(frames.vertices, point - h * Eigen::Vector3d::Unit(d), options, &minus);
    ASSERT_EQ(plus.frames, s.frames);
    ASSERT_EQ(minus.frames, s.frames);
    for (size_t j = 0; j < s.frames.size(); ++j)
      EXPECT_NEAR(s.weight_gradients[j][d], (plus.weights[j] - minus.weights[j]) / (2 * h), 1e-8);
  }
}

TEST(FrameShapeFunctions, BadInputThrows) {
  MlsOptions options;  // radius unset
  FrameSample s;
  EXPECT_THROW(
      EvaluateMls(MakeBoxHexMesh({1, 1, 1}, {1, 1, 1}).vertices, {0.5, 0.5, 0.5}, options, &s),
      Error);
  options.support_radius_mm = 0.1;  // no frame within reach
  EXPECT_THROW(
      EvaluateMls(MakeBoxHexMesh({1, 1, 1}, {1, 1, 1}).vertices, {0.5, 0.5, 0.5}, options, &s),
      Error);
  EXPECT_THROW(SampleTetMesh(MakeBoxTetMesh({1, 1, 1}, {1, 1, 1}), 3), Error);
  EXPECT_THROW(SampleHexMesh(MakeBoxHexMesh({1, 1, 1}, {1, 1, 1}), 4), Error);
}

// Central differences of the value against the gradient and of the gradient
// against the Hessian (exact Hessian: no projection), at a state with
// rotations near `angle_rad`, different per frame.
void CheckDerivatives(const FrameSampling& sampling, double angle_rad, unsigned seed) {
  FrameModelOptions options;
  options.project_hessian = false;
  auto m = MakeModel(sampling, options);
  Deform(&m->state, 1.0, angle_rad, seed);
  const FrameModel& term = *m->model;
  const Eigen::VectorXd g = Gradient(term, m->state);
  const Eigen::MatrixXd hessian = Hessian(term, m->state);
  EXPECT_LT((hessian - hessian.transpose()).norm(), 1e-12 * hessian.norm());
  const double h = 1e-6;
  Eigen::MatrixXd fd_hessian(g.size(), g.size());
  Eigen::VectorXd fd_gradient(g.size());
  for (int k = 0; k < g.size(); ++k) {
    const GeneralisedState plus = Perturbed(m->state, k, h), minus = Perturbed(m->state, k, -h);
    fd_gradient[k] = (term.Value(plus) - term.Value(minus)) / (2 * h);
    fd_hessian.col(k) =
        (GradientAlong(term, m->state, k, h) - GradientAlong(term, m->state, k, -h)) / (2 * h);
  }
  EXPECT_LT((fd_gradient - g).norm(), 1e-6 * g.norm()) << "angle " << angle_rad;
  EXPECT_LT((fd_hessian - hessian).norm(), 1e-6 * hessian.norm()) << "angle " << angle_rad;
}

TEST(FrameModel, DerivativesMatchFiniteDifferencesFarFromIdentity) {
  for (double angle : {0.0, 0.5 * kPi, 170.0 / 180.0 * kPi}) {
    CheckDerivatives(HexSampling(), angle, 1);
    CheckDerivatives(TetSampling(), angle, 2);
    CheckDerivatives(MlsSampling(), angle, 3);
    CheckDerivatives(MlsSampling(0), angle, 6);
  }
}

TEST(FrameGravity, DerivativesMatchFiniteDifferences) {
  auto m = MakeModel(HexSampling(), {});
  Deform(&m->state, 1.0, 0.5 * kPi, 4);
  const FrameGravity term(m->model.get(), {0, 0, -kStandardGravityMmPerS2}, false);
  const Eigen::VectorXd g = Gradient(term, m->state);
  const Eigen::MatrixXd hessian = Hessian(term, m->state);
  const double h = 1e-6;
  for (int k = 0; k < g.size(); ++k) {
    const GeneralisedState plus = Perturbed(m->state, k, h), minus = Perturbed(m->state, k, -h);
    EXPECT_NEAR((term.Value(plus) - term.Value(minus)) / (2 * h), g[k], 1e-6 * g.norm());
    const Eigen::VectorXd column =
        (GradientAlong(term, m->state, k, h) - GradientAlong(term, m->state, k, -h)) / (2 * h);
    EXPECT_LT((column - hessian.col(k)).norm(), 1e-6 * (1 + hessian.norm()));
  }
  // Total force on the frames = total weight.
  Eigen::Vector3d force = Eigen::Vector3d::Zero();
  for (int n = 0; n < m->state.num_nodes(); ++n) force -= g.segment<3>(m->state.dof_offset(n));
  EXPECT_LT(
      (force - m->model->total_mass_kg() * Eigen::Vector3d(0, 0, -kStandardGravityMmPerS2)).norm(),
      1e-12 * force.norm());
}

// A rigid motion of the whole model: every F is the rotation, the energy and
// every force and torque vanish (to rounding relative to a 1 % stretch).
TEST(FrameModel, RigidMotionsGiveNoEnergyForceOrTorque) {
  for (const FrameSampling& sampling : {HexSampling(), TetSampling(), MlsSampling()}) {
    auto m = MakeModel(sampling, {});
    GeneralisedState& state = m->state;
    // Reference scale: the gradient norm under a 1 % uniform stretch.
    GeneralisedState stretched = state;
    stretched.mutable_positions() *= 1.01;
    const double reference = Gradient(*m->model, stretched).norm();
    const double reference_energy = m->model->Value(stretched);
    for (double degrees : {90.0, 170.0}) {
      const Eigen::Matrix3d q =
          ExpSO3(degrees / 180.0 * kPi * Eigen::Vector3d(1, -2, 0.5).normalized());
      const Eigen::Vector3d t(31.0, -7.5, 12.0);
      GeneralisedState moved = state;
      for (int n = 0; n < moved.num_nodes(); ++n) {
        moved.mutable_positions().row(n) =
            (q * state.rest_positions().row(n).transpose() + t).transpose();
        moved.mutable_rotation(n) = q * state.rest_rotation(n);
      }
      for (int s = 0; s < m->model->num_samples(); ++s)
        EXPECT_LT((m->model->DeformationGradient(moved, s) - q).norm(), 1e-13);
      EXPECT_LT(std::abs(m->model->Value(moved)), 1e-12 * reference_energy) << degrees;
      EXPECT_LT(Gradient(*m->model, moved).norm(), 1e-12 * reference) << degrees;
    }
  }
}

// Eigenvalues of a symmetric matrix and how many are zero relative to the largest.
int CountZeroModes(const Eigen::MatrixXd& hessian, double* smallest_nonzero_ratio) {
  const Eigen::VectorXd values =
      Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(hessian).eigenvalues();
  const double largest = values.cwiseAbs().maxCoeff();
  int zero = 0;
  for (int k = 0; k < values.size(); ++k) zero += std::abs(values[k]) < 1e-10 * largest;
  *smallest_nonzero_ratio = zero < values.size() ? values[zero] / largest : 0;
  return zero;
}

// The frame-rotation mode phi_i = A x_i0 + b (no translation) of a state.
Eigen::VectorXd RotationMode(const GeneralisedState& state, const Eigen::Matrix3d& a,
                             const Eigen::Vector3d& b) {
  Eigen::VectorXd v = Eigen::VectorXd::Zero(state.num_dofs());
  for (int n = 0; n < state.num_nodes(); ++n)
    v.segment<3>(state.dof_offset(n) + 3) = a * state.rest_positions().row(n).transpose() + b;
  return v;
}

// At rest, Shepard weights (partition of unity only) give a free cluster
// exactly the 6 rigid zero modes. Linearly complete weights add, exactly, the
// frame-rotation modes phi_i = b and phi_i = alpha x_i0 (no translation:
// sum w_i (alpha x_i0) x (X - x_i0) = alpha X x X = 0), 10 in all for
// barycentric and linear MLS weights; trilinear weights also reproduce xy, xz,
// yz, adding phi_i = diag(a) x_i0. Clamping the frames of one face (translation
// and rotation) leaves the tetrahedral and MLS stiffness positive definite.
TEST(FrameModel, ZeroModesOfAFreeCluster) {
  struct Case {
    const char* name;
    FrameSampling sampling;
    int zero_modes;
  };
  for (const Case& c :
       {Case{"Shepard MLS", MlsSampling(0), 6}, Case{"tet 4-point", TetSampling(), 10},
        Case{"linear MLS", MlsSampling(1), 10}}) {
    auto m = MakeModel(c.sampling, {});
    const Eigen::MatrixXd hessian = Hessian(*m->model, m->state);
    double ratio = 0;
    const int zero = CountZeroModes(hessian, &ratio);
    std::printf("%-12s dofs %3d zero modes %2d, smallest non-zero / largest %.3e\n", c.name,
                static_cast<int>(hessian.rows()), zero, ratio);
    EXPECT_EQ(zero, c.zero_modes) << c.name;
    if (c.zero_modes == 10) {
      for (const Eigen::VectorXd& mode :
           {RotationMode(m->state, Eigen::Matrix3d::Zero(), {0.3, -0.2, 0.9}),
            RotationMode(m->state, Eigen::Matrix3d::Identity(), Eigen::Vector3d::Zero())})
        EXPECT_LT((hessian * mode).norm(), 1e-12 * hessian.norm() * mode.norm()) << c.name;
    }
    // Clamp the frames at x = 0 and keep the free rows and columns.
    std::vector<int> free;
    for (int n = 0; n < m->state.num_nodes(); ++n)
      if (m->state.rest_positions()(n, 0) > 0)
        for (int d = 0; d < 6; ++d) free.push_back(m->state.dof_offset(n) + d);
    Eigen::MatrixXd clamped(free.size(), free.size());
    for (size_t i = 0; i < free.size(); ++i)
      for (size_t j = 0; j < free.size(); ++j) clamped(i, j) = hessian(free[i], free[j]);
    EXPECT_EQ(CountZeroModes(clamped, &ratio), 0) << c.name;
    EXPECT_GT(ratio, 1e-7) << c.name;
  }
  // Trilinear hexahedra: phi_i = diag(a) x_i0 is a zero mode too, and it
  // vanishes at x = 0, so clamping one face does not remove phi_i = e_x x_i0.
  auto hex = MakeModel(HexSampling(), {});
  const Eigen::MatrixXd hessian = Hessian(*hex->model, hex->state);
  const Eigen::VectorXd mode =
      RotationMode(hex->state, Eigen::Vector3d(1, -2, 0.5).asDiagonal(), Eigen::Vector3d::Zero());
  EXPECT_LT((hessian * mode).norm(), 1e-12 * hessian.norm() * mode.norm());
  // All frames turned by one finite rotation about their own positions: the
  // skinned positions and the energy do not change at all.
  GeneralisedState turned = hex->state;
  for (int n = 0; n < turned.num_nodes(); ++n)
    turned.mutable_rotation(n) = ExpSO3(Eigen::Vector3d(0.4, 2.0, -1.1));
  for (int s = 0; s < hex->model->num_samples(); ++s)
    EXPECT_LT((hex->model->SamplePosition(turned, s) - hex->model->sample_rest_position(s)).norm(),
              1e-12);
  EXPECT_LT(hex->model->Value(turned), 1e-20);
}

// Frames moved by x_i = Q U x_i0 with R_i = Q give F = Q U at every sample of
// a linearly complete sampling, and E = V psi(U) with the analytic
// Saint Venant-Kirchhoff density of U.
TEST(FrameModel, UniformStretchIsExact) {
  const Material material = Tissue();
  const double mu = material.LameMuKpa(), lambda = material.LameLambdaKpa();
  const Eigen::Vector3d stretch(1.3, 0.9, 1.1);
  Eigen::Vector3d green;
  for (int c = 0; c < 3; ++c) green[c] = 0.5 * (stretch[c] * stretch[c] - 1);
  const double psi = mu * green.squaredNorm() + 0.5 * lambda * green.sum() * green.sum();
  const Eigen::Matrix3d q = ExpSO3(Eigen::Vector3d(0.3, 1.2, -0.7));
  const Eigen::Matrix3d f = q * stretch.asDiagonal();
  for (const FrameSampling& sampling : {HexSampling(), TetSampling(), MlsSampling()}) {
    auto m = MakeModel(sampling, {});
    for (int n = 0; n < m->state.num_nodes(); ++n) {
      m->state.mutable_positions().row(n) =
          (f * m->state.rest_positions().row(n).transpose()).transpose();
      m->state.mutable_rotation(n) = q;
    }
    for (int s = 0; s < m->model->num_samples(); ++s)
      EXPECT_LT((m->model->DeformationGradient(m->state, s) - f).norm(), 1e-12);
    EXPECT_NEAR(m->model->Value(m->state), 2000.0 * psi, 1e-10 * 2000.0 * psi);
  }
}

// The projected Hessian is positive semi-definite in a compressed, twisted
// state where the exact one is not.
TEST(FrameModel, ProjectedHessianIsPositiveSemiDefinite) {
  FrameModelOptions exact;
  exact.project_hessian = false;
  auto m = MakeModel(HexSampling(), exact);
  auto projected = MakeModel(HexSampling(), {});
  for (GeneralisedState* state : {&m->state, &projected->state}) {
    state->mutable_positions() *= 0.7;
    Deform(state, 1.0, 0.5 * kPi, 5);
  }
  const Eigen::VectorXd exact_values =
      Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(Hessian(*m->model, m->state)).eigenvalues();
  const Eigen::VectorXd values =
      Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(Hessian(*projected->model, projected->state))
          .eigenvalues();
  EXPECT_LT(exact_values[0], -1e-6 * exact_values.maxCoeff());
  EXPECT_GT(values[0], -1e-12 * values.maxCoeff());
}

TEST(FrameModel, LumpedInertiaKeepsMassAndIsPositive) {
  for (const FrameSampling& sampling : {HexSampling(), TetSampling(), MlsSampling()}) {
    auto m = MakeModel(sampling, {});
    std::vector<NodeInertia> inertia(m->state.num_nodes());
    m->model->AddNodeInertia(m->state, &inertia);
    double mass = 0;
    for (const NodeInertia& n : inertia) {
      mass += n.mass_kg;
      EXPECT_GT(n.mass_kg, 0);
      EXPECT_GT(Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(n.body_inertia).eigenvalues()[0], 0);
    }
    EXPECT_NEAR(mass, 2e-3, 1e-15);  // 2000 mm^3 of water = 2 g
    EXPECT_NEAR(m->model->total_mass_kg(), 2e-3, 1e-15);
  }
}

TEST(FrameModel, BadSamplesThrow) {
  FrameSampling sampling = HexSampling();
  GeneralisedState state;
  const std::vector<int> nodes = AddFrameNodes(sampling.frame_positions, &state);
  std::vector<FrameSample> samples = sampling.samples;
  samples[3].weights[0] += 0.1;
  EXPECT_THROW(FrameModel(state, nodes, samples, Tissue()), Error);
  samples = sampling.samples;
  samples[0].frames[1] = samples[0].frames[0];
  EXPECT_THROW(FrameModel(state, nodes, samples, Tissue()), Error);
  GeneralisedState points;
  std::vector<int> point_nodes;
  for (int i = 0; i < sampling.frame_positions.rows(); ++i)
    point_nodes.push_back(points.AddPointNode(sampling.frame_positions.row(i).transpose()));
  EXPECT_THROW(FrameModel(points, point_nodes, sampling.samples, Tissue()), Error);
}

// Mean downward displacement (mm) of the nodes among `nodes` that rest at z = 0.
double MeanSinkAtZ0(const GeneralisedState& state, const std::vector<int>& nodes) {
  double sink = 0;
  int count = 0;
  for (int n : nodes)
    if (state.rest_positions()(n, 2) == 0.0) {
      sink += state.rest_positions()(n, 2) - state.positions()(n, 2);
      ++count;
    }
  return sink / count;
}

// Coupling by shared frames (seed 004 section 4.2): two stiff bodies joined
// by a soft connective layer, three frame models over one column of frames
// 20 x 20 x 30 mm (layers z in [0,10], [10,20], [20,30]); the models share the
// frames at z = 10 and 20. The top face is clamped, gravity -z. With nu = 0 the
// stress is uniaxial, sigma(z) = rho g z (weight of the column below z), and
// the bottom face sinks by rho g sum_layers (z_top^2 - z_bottom^2) / (2 E)
// (small strain: 0.4 % in the layer, so Saint Venant-Kirchhoff within 1 %).
TEST(FrameCoupling, SharedFramesCarryTheLowerBody) {
  const TetMesh column = MakeBoxTetMesh({20, 20, 30}, {2, 2, 6});
  const double e_body = 1e6, e_tissue = 5e4;  // Pa
  GeneralisedState state;
  const std::vector<int> nodes = AddFrameNodes(column.vertices, &state);
  const FrameSampling all = SampleTetMesh(column, 4);
  std::vector<std::vector<FrameSample>> layer(3);
  for (const FrameSample& sample : all.samples)
    layer[std::min(2, static_cast<int>(sample.rest_position.z() / 10))].push_back(sample);
  std::vector<std::unique_ptr<FrameModel>> models;
  std::vector<std::unique_ptr<FrameGravity>> weights;
  std::vector<GeneralisedEnergyTerm*> terms;
  for (int k = 0; k < 3; ++k) {
    const Material material{k == 1 ? e_tissue : e_body, 0.0, 1000.0};
    models.push_back(std::make_unique<FrameModel>(state, nodes, layer[k], material));
    weights.push_back(std::make_unique<FrameGravity>(
        models.back().get(), Eigen::Vector3d(0, 0, -kStandardGravityMmPerS2)));
    terms.push_back(models.back().get());
    terms.push_back(weights.back().get());
  }
  for (int n : nodes)
    if (state.rest_positions()(n, 2) == 30.0) {
      state.SetFixedTranslation(n, true);
      state.SetFixedRotation(n, true);
    }
  GeneralisedStaticOptions options;
  options.tolerance_mm = 1e-10;
  GeneralisedStaticSolver solver(options);
  ASSERT_EQ(solver.Solve(&state, terms).status, StepStatus::kConverged);
  const double rho_g = 1e-6 * kStandardGravityMmPerS2;                                    // mN/mm^3
  const double e_b = e_body * kPaToInternalStress, e_t = e_tissue * kPaToInternalStress;  // kPa
  const double expected = rho_g * (50 / e_b + 150 / e_t + 250 / e_b);                     // mm
  const double sink = MeanSinkAtZ0(state, nodes);
  std::printf("bottom face sinks %.6f mm, uniaxial analytic %.6f mm\n", sink, expected);
  EXPECT_NEAR(sink, expected, 0.01 * expected);
}

// Coupling by offset springs (generalised_terms.h): a corotational tet body
// (z in [0, 10]) hangs from a soft frame layer (z in [10, 20], top clamped).
// Each frame at z = 10 is tied by stiff zero-length springs to the tet
// vertices at z = 10 within one cell (offset anchors on the frame), which ties
// the frame's rotation as well as its translation to the body: a bonded
// interface. (Springs at the coincident vertices alone pin the layer only at
// points, its free frame rotations let the face between them give, and the
// column sinks about 30 % more than the bonded solution.) nu = 0, gravity -z:
// the bottom sinks by rho g ((20^2 - 10^2) / (2 E_layer) + 10^2 / (2 E_body))
// plus the springs' stretch W_body / (#springs k).
TEST(FrameCoupling, SpringsHangATetBodyFromAFrameLayer) {
  const double e_body = 1e6, e_layer = 5e4, k = 1e5;  // Pa, Pa, N/m per spring
  const MechanicalState body(MakeBoxTetMesh({20, 20, 10}, {2, 2, 2}),
                             Material{e_body, 0.0, 1000.0});
  GeneralisedState state;
  const std::vector<int> vertex_node = AddTetVertexNodes(body, &state);
  TetElasticityTerm tets(&body, vertex_node);
  FrameSampling layer = SampleTetMesh(MakeBoxTetMesh({20, 20, 10}, {2, 2, 2}), 4);
  layer.frame_positions.col(2).array() += 10;
  for (FrameSample& sample : layer.samples) sample.rest_position.z() += 10;
  const std::vector<int> frames = AddFrameNodes(layer.frame_positions, &state);
  FrameModel model(state, frames, layer.samples, Material{e_layer, 0.0, 1000.0});
  const Eigen::Vector3d g(0, 0, -kStandardGravityMmPerS2);
  FrameGravity layer_weight(&model, g);
  GravityTerm body_weight(CollectNodeInertia(state, {&tets}), g);
  ZeroLengthSpringTerm springs;
  int joined = 0;
  for (int f : frames) {
    if (state.rest_positions()(f, 2) == 20.0) {
      state.SetFixedTranslation(f, true);
      state.SetFixedRotation(f, true);
    }
    if (state.rest_positions()(f, 2) != 10.0) continue;
    for (int n : vertex_node) {
      const Eigen::Vector3d offset =
          (state.rest_positions().row(n) - state.rest_positions().row(f)).transpose();
      if (state.rest_positions()(n, 2) == 10.0 && offset.norm() < 10.5) {
        springs.Add(SpringAnchor::AtOffset(f, offset), SpringAnchor::AtNode(n), k);
        ++joined;
      }
    }
  }
  ASSERT_EQ(joined, 9 + 2 * 12);  // each of the 12 grid edges of the face joins two ways
  GeneralisedStaticOptions options;
  options.tolerance_mm = 1e-10;
  GeneralisedStaticSolver solver(options);
  ASSERT_EQ(solver.Solve(&state, {&model, &layer_weight, &tets, &body_weight, &springs}).status,
            StepStatus::kConverged);
  const double rho_g = 1e-6 * kStandardGravityMmPerS2;  // mN/mm^3
  const double body_weight_mn = rho_g * 4000;
  const double expected =
      rho_g * (150 / (e_layer * kPaToInternalStress) + 50 / (e_body * kPaToInternalStress)) +
      body_weight_mn / (joined * k);
  const double sink = MeanSinkAtZ0(state, vertex_node);
  std::printf("tet body bottom sinks %.6f mm, uniaxial analytic %.6f mm\n", sink, expected);
  EXPECT_NEAR(sink, expected, 0.01 * expected);
}

}  // namespace
}  // namespace arreg::mechanics
