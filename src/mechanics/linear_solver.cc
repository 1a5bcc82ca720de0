#include "mechanics/linear_solver.h"

#include <Eigen/Cholesky>
#include <Eigen/IterativeLinearSolvers>
#include <Eigen/OrderingMethods>
#include <cmath>
#include <vector>

#include "core/error.h"
#include "mechanics/cholmod_solver.h"
#include "mechanics/conjugate_gradient.h"

namespace arreg::mechanics {

LinearSolverType ParseLinearSolverType(const std::string& name) {
  return ParseName(kLinearSolverTypeNames, name, "", "linear solver");
}

const char* LinearSolverTypeName(LinearSolverType type) {
  return NameOf(kLinearSolverTypeNames, type);
}

Preconditioner ParsePreconditioner(const std::string& name) {
  return ParseName(kPreconditionerNames, name, "", "preconditioner");
}

CholmodFactorization ParseCholmodFactorization(const std::string& name) {
  return ParseName(kCholmodFactorizationNames, name, "", "CHOLMOD factorization");
}

const char* LinearSolverStatusName(LinearSolverStatus status) {
  switch (status) {
    case LinearSolverStatus::kConverged:
      return "converged";
    case LinearSolverStatus::kMaxIterations:
      return "max-iterations";
    case LinearSolverStatus::kIndefinite:
      return "indefinite";
    case LinearSolverStatus::kNumericalFailure:
      return "numerical-failure";
  }
  return "?";
}

void LinearSolverOptions::Check() const {
  ARREG_CHECK_INPUT(std::isfinite(relative_tolerance) && relative_tolerance > 0, "",
                    "linear_solver.relative_tolerance", "must be > 0, got ", relative_tolerance);
  ARREG_CHECK_INPUT(max_iterations >= 1, "", "linear_solver.max_iterations", "must be >= 1, got ",
                    max_iterations);
  ARREG_CHECK_INPUT(refactor_iterations >= 0, "", "linear_solver.refactor_iterations",
                    "must be >= 0, got ", refactor_iterations);
}

namespace {

// Preconditioned conjugate gradient (Saad, Iterative Methods, alg. 9.1).
class ConjugateGradientSolver : public LinearSolver {
 public:
  explicit ConjugateGradientSolver(const LinearSolverOptions& options) : options_(options) {}
  std::string name() const override { return "cg"; }
  void PatternChanged() override {
    pattern_valid_ = false;
    values_valid_ = false;
  }
  void ValuesChanged() override { values_valid_ = false; }

  LinearSolverSummary Solve(const SparseMatrixd& A, const Eigen::VectorXd& b,
                            Eigen::VectorXd* x) override {
    LinearSolverSummary summary;
    const int n = static_cast<int>(b.size());
    ARREG_ASSERT(A.rows() == n && A.cols() == n, "");
    if (!options_.warm_start || x->size() != n) x->setZero(n);
    if (!values_valid_ || !pattern_valid_) {
      if (!SetUpPreconditioner(A, &summary)) return summary;
      pattern_valid_ = values_valid_ = true;
    }
    PreconditionedConjugateGradient(
        [&A](const Eigen::VectorXd& v, Eigen::VectorXd* out) { out->noalias() = A * v; },
        [this](const Eigen::VectorXd& r, Eigen::VectorXd* z) {
          Precondition(r, z);
          return true;
        },
        "", b, options_.relative_tolerance, options_.max_iterations, x, &cg_, &summary);
    return summary;
  }

 private:
  bool SetUpPreconditioner(const SparseMatrixd& A, LinearSolverSummary* summary) {
    switch (options_.preconditioner) {
      case Preconditioner::kNone:
        break;
      case Preconditioner::kJacobi: {
        inverse_diagonal_ = A.diagonal();
        if ((inverse_diagonal_.array() <= 0.0).any()) {
          summary->status = LinearSolverStatus::kIndefinite;
          summary->message = "non-positive diagonal entry";
          return false;
        }
        inverse_diagonal_ = inverse_diagonal_.cwiseInverse();
        break;
      }
      case Preconditioner::kBlockJacobi: {
        const int n = static_cast<int>(A.rows());
        ARREG_CHECK_INPUT(n % 3 == 0, "", "linear_solver.preconditioner",
                          "block-jacobi needs 3 DOFs per vertex, got ", n, " DOFs");
        block_inverses_.resize(n / 3);
        std::vector<Eigen::Matrix3d> blocks(n / 3, Eigen::Matrix3d::Zero());
        for (int col = 0; col < n; ++col)
          for (SparseMatrixd::InnerIterator it(A, col); it; ++it)
            if (it.row() / 3 == col / 3) blocks[col / 3](it.row() % 3, col % 3) = it.value();
        for (int v = 0; v < n / 3; ++v) {
          Eigen::LLT<Eigen::Matrix3d> llt(blocks[v]);
          if (llt.info() != Eigen::Success) {
            summary->status = LinearSolverStatus::kIndefinite;
            summary->message = "diagonal block not positive definite";
            return false;
          }
          block_inverses_[v] = llt.solve(Eigen::Matrix3d::Identity());
        }
        break;
      }
      case Preconditioner::kIncompleteCholesky: {
        if (!pattern_valid_) ichol_.analyzePattern(A);
        ichol_.factorize(A);
        if (ichol_.info() != Eigen::Success) {
          summary->status = LinearSolverStatus::kIndefinite;
          summary->message = "incomplete Cholesky failed";
          return false;
        }
        break;
      }
    }
    return true;
  }

  void Precondition(const Eigen::VectorXd& r, Eigen::VectorXd* z) {
    switch (options_.preconditioner) {
      case Preconditioner::kNone:
        *z = r;
        break;
      case Preconditioner::kJacobi:
        z->noalias() = inverse_diagonal_.cwiseProduct(r);
        break;
      case Preconditioner::kBlockJacobi: {
        z->resize(r.size());
        for (size_t v = 0; v < block_inverses_.size(); ++v)
          z->segment<3>(3 * v).noalias() = block_inverses_[v] * r.segment<3>(3 * v);
        break;
      }
      case Preconditioner::kIncompleteCholesky:
        *z = ichol_.solve(r);
        break;
    }
  }

  LinearSolverOptions options_;
  bool pattern_valid_ = false, values_valid_ = false;
  Eigen::VectorXd inverse_diagonal_;
  CgVectors cg_;
  std::vector<Eigen::Matrix3d> block_inverses_;
  Eigen::IncompleteCholesky<double, Eigen::Lower, Eigen::AMDOrdering<int>> ichol_;
};

}  // namespace

std::unique_ptr<LinearSolver> LinearSolver::Create(const LinearSolverOptions& options) {
  options.Check();
  switch (options.type) {
    case LinearSolverType::kConjugateGradient:
      return std::make_unique<ConjugateGradientSolver>(options);
    case LinearSolverType::kCholmod:
    case LinearSolverType::kCholmodPcg:
      return MakeCholmodSolver(options);
  }
  return nullptr;
}

}  // namespace arreg::mechanics
