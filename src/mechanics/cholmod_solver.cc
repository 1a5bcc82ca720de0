#include "mechanics/cholmod_solver.h"

#include <cholmod.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <mutex>
#include <string>

#include "core/error.h"
#include "mechanics/conjugate_gradient.h"

namespace arreg::mechanics {

namespace {

// CHOLMOD 3's supernodal factorisation runs its supernode loops with
// num_threads(CHOLMOD_OMP_NUM_THREADS), 4 compiled in, whatever OMP_NUM_THREADS
// says: on a 2-core machine that doubled the thread CPU time of a 3,366-DOF shell
// factorisation (8.5 ms instead of 3.9 ms), the supernodes being too small for
// threads to pay. No active parallel level while this guard lives makes those
// regions run on the calling thread.
class SerialOpenMp {
 public:
  SerialOpenMp() : levels_(omp_get_max_active_levels()) { omp_set_max_active_levels(0); }
  ~SerialOpenMp() { omp_set_max_active_levels(levels_); }
  SerialOpenMp(const SerialOpenMp&) = delete;
  SerialOpenMp& operator=(const SerialOpenMp&) = delete;

 private:
  int levels_;
};

// Debian's serial OpenBLAS, the BLAS CHOLMOD's supernodal factorisation and solves run on
// (docs/mechanics.md, "BLAS"), is built without OpenBLAS's USE_LOCKING (the library imports no
// pthread function): two threads inside it at once share its buffer pool unguarded and can
// get wrong factors. The numeric work of every solver in the process takes turns here; one
// thread pays an uncontended lock per factorisation or solve.
std::mutex& BlasTurn() {
  static std::mutex turn;
  return turn;
}

// Sparse Cholesky with CHOLMOD: the symbolic analysis (fill-reducing ordering,
// supernodes) is kept until the pattern changes; a value change only redoes the
// numeric factorisation; solves reuse their workspace.
class CholmodSolver : public LinearSolver {
 public:
  explicit CholmodSolver(const LinearSolverOptions& options)
      : options_(options), pcg_(options.type == LinearSolverType::kCholmodPcg) {
    cholmod_start(&common_);
    common_.print = 0;
    common_.error_handler = nullptr;
    // Orderings tried once per pattern, the one with the least fill kept: AMD
    // wins on compact meshes, METIS on elongated ones (on a 20x6x6 box it
    // needs 10 % less fill and flops than AMD).
    // LL' also for simplicial factors: LDL' would accept indefinite matrices
    // (negative pivots) that must be reported as such.
    common_.final_ll = 1;
    common_.nmethods = 2;
    common_.method[0].ordering = CHOLMOD_AMD;
    common_.method[1].ordering = CHOLMOD_METIS;
    switch (options.factorization) {
      case CholmodFactorization::kSupernodal:
        common_.supernodal = CHOLMOD_SUPERNODAL;
        break;
      case CholmodFactorization::kSimplicial:
        common_.supernodal = CHOLMOD_SIMPLICIAL;
        break;
      case CholmodFactorization::kAuto:
        // Supernodal only when the factor is dense enough for BLAS to pay off:
        // at CHOLMOD's default switch (40 flops per factor nonzero) the liver
        // mesh (64) went supernodal and its triangular solves, which dominate
        // cholmod-pcg, were 1.6x slower than simplicial; the 20x6x6 box (205)
        // refactorises 2x faster supernodal.
        common_.supernodal = CHOLMOD_AUTO;
        common_.supernodal_switch = 100;
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
    has_numeric_ = false;
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
      has_numeric_ = false;
      // Cost model of cholmod-pcg in flops: a factorisation, and one CG
      // iteration = a forward and a backward solve (2 flops per factor entry
      // each) plus the product with A.
      factorization_flops_ = common_.fl;
      iteration_flops_ = 4.0 * common_.lnz + 2.0 * static_cast<double>(A.nonZeros());
    }
    // cholmod-pcg: an earlier factor preconditions CG while it keeps CG short.
    if (!factor_valid_ && pcg_ && has_numeric_ && !refactor_next_) {
      const int iterations = PreconditionedCg(A, b, x, &summary);
      if (summary.status == LinearSolverStatus::kConverged) {
        const double cost = iterations * iteration_flops_;
        flops_since_factorization_ += cost;
        ++solves_since_factorization_;
        refactor_next_ = iterations > options_.refactor_iterations ||
                         (options_.refactor_by_cost &&
                          cost * solves_since_factorization_ > flops_since_factorization_);
        return summary;
      }
      if (summary.status == LinearSolverStatus::kNumericalFailure) return summary;
      summary = LinearSolverSummary();  // CG stalled or saw negative curvature: refactorise
    }
    if (!factor_valid_) {
      has_numeric_ = false;
      {
        const std::lock_guard<std::mutex> turn(BlasTurn());
        const SerialOpenMp serial;
        cholmod_factorize(&view, factor_, &common_);
      }
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
      has_numeric_ = true;
      refactor_next_ = false;
      flops_since_factorization_ = factorization_flops_ + iteration_flops_;
      solves_since_factorization_ = 1;
    }
    if (!SolveWithFactor(b, x)) {
      summary.status = LinearSolverStatus::kNumericalFailure;
      summary.message = "cholmod_solve2 failed";
      return summary;
    }
    if (!x->allFinite()) summary.status = LinearSolverStatus::kNumericalFailure;
    return summary;
  }

 private:
  // x = L^-T L^-1 b with the current factor (CHOLMOD's permutation included).
  bool SolveWithFactor(const Eigen::VectorXd& b, Eigen::VectorXd* x) {
    const int n = static_cast<int>(b.size());
    cholmod_dense rhs;
    rhs.nrow = n;
    rhs.ncol = 1;
    rhs.nzmax = n;
    rhs.d = n;
    rhs.x = const_cast<double*>(b.data());
    rhs.z = nullptr;
    rhs.xtype = CHOLMOD_REAL;
    rhs.dtype = CHOLMOD_DOUBLE;
    {
      const std::lock_guard<std::mutex> turn(BlasTurn());
      if (!cholmod_solve2(CHOLMOD_A, factor_, &rhs, nullptr, &x_, nullptr, &y_, &e_, &common_))
        return false;
    }
    x->resize(n);
    std::copy(static_cast<const double*>(x_->x), static_cast<const double*>(x_->x) + n, x->data());
    return true;
  }

  // Conjugate gradient on A (full symmetric CSC, so A^T x = A x is evaluated
  // row-wise) preconditioned by the stored factor. Returns the iterations.
  int PreconditionedCg(const SparseMatrixd& A, const Eigen::VectorXd& b, Eigen::VectorXd* x,
                       LinearSolverSummary* summary) {
    const int n = static_cast<int>(b.size());
    if (!options_.warm_start || x->size() != n) x->setZero(n);
    return PreconditionedConjugateGradient(
        [&A](const Eigen::VectorXd& v, Eigen::VectorXd* out) {
          out->noalias() = A.transpose() * v;
        },
        [this](const Eigen::VectorXd& r, Eigen::VectorXd* z) { return SolveWithFactor(r, z); },
        "cholmod_solve2 failed", b, options_.relative_tolerance, options_.max_iterations, x, &cg_,
        summary);
  }

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
  bool pcg_ = false;
  cholmod_common common_;
  cholmod_factor* factor_ = nullptr;
  cholmod_dense *x_ = nullptr, *y_ = nullptr, *e_ = nullptr;
  bool factor_valid_ = false;   // factor of the current values
  bool has_numeric_ = false;    // factor holds the values of some earlier matrix
  bool refactor_next_ = false;  // cholmod-pcg: refactorise at the next solve
  // cholmod-pcg cost model (flops; see LinearSolverOptions::refactor_by_cost).
  double factorization_flops_ = 0.0, iteration_flops_ = 0.0;
  double flops_since_factorization_ = 0.0;  // factorisation + solves since
  int solves_since_factorization_ = 0;      // including the factorisation's
  CgVectors cg_;
};

}  // namespace

std::unique_ptr<LinearSolver> MakeCholmodSolver(const LinearSolverOptions& options) {
  return std::make_unique<CholmodSolver>(options);
}

}  // namespace arreg::mechanics
