#include "mechanics/cholmod_solver.h"

#include <cholmod.h>

#include "core/error.h"

namespace arreg::mechanics {

namespace {

// Sparse Cholesky with CHOLMOD: the symbolic analysis (fill-reducing ordering,
// supernodes) is kept until the pattern changes; a value change only redoes the
// numeric factorisation; solves reuse their workspace.
class CholmodSolver : public LinearSolver {
 public:
  explicit CholmodSolver(const LinearSolverOptions& options) : options_(options) {
    cholmod_start(&common_);
    common_.print = 0;
    common_.error_handler = nullptr;
    switch (options.factorization) {
      case CholmodFactorization::kSupernodal:
        common_.supernodal = CHOLMOD_SUPERNODAL;
        break;
      case CholmodFactorization::kSimplicial:
        common_.supernodal = CHOLMOD_SIMPLICIAL;
        break;
      case CholmodFactorization::kAuto:
        common_.supernodal = CHOLMOD_AUTO;
        break;
    }
  }
  ~CholmodSolver() override {
    FreeFactor();
    if (x_) cholmod_free_dense(&x_, &common_);
    if (y_) cholmod_free_dense(&y_, &common_);
    if (e_) cholmod_free_dense(&e_, &common_);
    cholmod_finish(&common_);
  }
  CholmodSolver(const CholmodSolver&) = delete;
  CholmodSolver& operator=(const CholmodSolver&) = delete;

  std::string name() const override { return "cholmod"; }
  void PatternChanged() override {
    FreeFactor();
    factor_valid_ = false;
  }
  void ValuesChanged() override { factor_valid_ = false; }

  LinearSolverSummary Solve(const SparseMatrixd& A, const Eigen::VectorXd& b,
                            Eigen::VectorXd* x) override {
    LinearSolverSummary summary;
    const int n = static_cast<int>(b.size());
    ARREG_ASSERT(A.rows() == n && A.cols() == n && A.isCompressed(), "");
    cholmod_sparse view = View(A);
    if (factor_ && static_cast<int>(factor_->n) != n) FreeFactor();
    if (!factor_) {
      factor_ = cholmod_analyze(&view, &common_);
      if (!factor_ || common_.status < CHOLMOD_OK) {
        summary.status = LinearSolverStatus::kNumericalFailure;
        summary.message = "cholmod_analyze failed";
        FreeFactor();
        return summary;
      }
      summary.symbolic_analysis = true;
      factor_valid_ = false;
    }
    if (!factor_valid_) {
      cholmod_factorize(&view, factor_, &common_);
      summary.numeric_factorization = true;
      if (common_.status == CHOLMOD_NOT_POSDEF) {
        summary.status = LinearSolverStatus::kIndefinite;
        summary.message =
            "matrix not positive definite (column " + std::to_string(factor_->minor) + ")";
        return summary;
      }
      if (common_.status < CHOLMOD_OK) {
        summary.status = LinearSolverStatus::kNumericalFailure;
        summary.message = "cholmod_factorize failed";
        return summary;
      }
      factor_valid_ = true;
    }
    cholmod_dense rhs;
    rhs.nrow = n;
    rhs.ncol = 1;
    rhs.nzmax = n;
    rhs.d = n;
    rhs.x = const_cast<double*>(b.data());
    rhs.z = nullptr;
    rhs.xtype = CHOLMOD_REAL;
    rhs.dtype = CHOLMOD_DOUBLE;
    if (!cholmod_solve2(CHOLMOD_A, factor_, &rhs, nullptr, &x_, nullptr, &y_, &e_, &common_)) {
      summary.status = LinearSolverStatus::kNumericalFailure;
      summary.message = "cholmod_solve2 failed";
      return summary;
    }
    x->resize(n);
    std::copy(static_cast<const double*>(x_->x), static_cast<const double*>(x_->x) + n, x->data());
    if (!x->allFinite()) summary.status = LinearSolverStatus::kNumericalFailure;
    return summary;
  }

 private:
  // A non-owning CHOLMOD view of the full symmetric CSC matrix; stype -1 makes
  // CHOLMOD read only the lower triangle.
  static cholmod_sparse View(const SparseMatrixd& A) {
    cholmod_sparse s;
    s.nrow = A.rows();
    s.ncol = A.cols();
    s.nzmax = A.nonZeros();
    s.p = const_cast<int*>(A.outerIndexPtr());
    s.i = const_cast<int*>(A.innerIndexPtr());
    s.nz = nullptr;
    s.x = const_cast<double*>(A.valuePtr());
    s.z = nullptr;
    s.stype = -1;
    s.itype = CHOLMOD_INT;
    s.xtype = CHOLMOD_REAL;
    s.dtype = CHOLMOD_DOUBLE;
    s.sorted = 1;
    s.packed = 1;
    return s;
  }
  void FreeFactor() {
    if (factor_) cholmod_free_factor(&factor_, &common_);
    factor_ = nullptr;
  }

  LinearSolverOptions options_;
  cholmod_common common_;
  cholmod_factor* factor_ = nullptr;
  cholmod_dense *x_ = nullptr, *y_ = nullptr, *e_ = nullptr;
  bool factor_valid_ = false;
};

}  // namespace

std::unique_ptr<LinearSolver> MakeCholmodSolver(const LinearSolverOptions& options) {
  return std::make_unique<CholmodSolver>(options);
}

}  // namespace arreg::mechanics
