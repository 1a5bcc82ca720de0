// Sparse symmetric positive-definite linear solvers behind one interface:
// preconditioned conjugate gradient and CHOLMOD Cholesky, made by a factory.
#pragma once

#include <Eigen/Core>
#include <memory>
#include <string>

#include "core/enum_names.h"
#include "mechanics/system_matrix.h"

namespace arreg::mechanics {

// kCholmodPcg: CHOLMOD's factor of an earlier matrix preconditions CG on the
// current one (for slowly changing matrices such as corotational Hessians from
// frame to frame); refactorised when that pays off (see refactor_by_cost).
enum class LinearSolverType { kConjugateGradient, kCholmod, kCholmodPcg };
enum class Preconditioner {
  kNone,
  kJacobi,       // inverse of the diagonal
  kBlockJacobi,  // inverses of the 3x3 vertex blocks (DOFs vertex-major, 3 per vertex)
  kIncompleteCholesky,
};
enum class CholmodFactorization { kSupernodal, kSimplicial, kAuto };

// The spellings in scene files, options and records.
inline constexpr EnumName<LinearSolverType> kLinearSolverTypeNames[] = {
    {LinearSolverType::kCholmodPcg, "cholmod-pcg"},
    {LinearSolverType::kCholmod, "cholmod"},
    {LinearSolverType::kConjugateGradient, "cg"}};
inline constexpr EnumName<Preconditioner> kPreconditionerNames[] = {
    {Preconditioner::kNone, "none"},
    {Preconditioner::kJacobi, "jacobi"},
    {Preconditioner::kBlockJacobi, "block-jacobi"},
    {Preconditioner::kIncompleteCholesky, "ichol"}};
inline constexpr EnumName<CholmodFactorization> kCholmodFactorizationNames[] = {
    {CholmodFactorization::kSupernodal, "supernodal"},
    {CholmodFactorization::kSimplicial, "simplicial"},
    {CholmodFactorization::kAuto, "auto"}};

// Name and inverse; the parsers throw arreg::Error naming the choice for any other name.
LinearSolverType ParseLinearSolverType(const std::string& name);
const char* LinearSolverTypeName(LinearSolverType type);
Preconditioner ParsePreconditioner(const std::string& name);
CholmodFactorization ParseCholmodFactorization(const std::string& name);

struct LinearSolverOptions {
  LinearSolverType type = LinearSolverType::kCholmod;  // default CHOLMOD
  // CG and cholmod-pcg (relative_tolerance, max_iterations, warm_start):
  Preconditioner preconditioner = Preconditioner::kJacobi;  // default Jacobi
  double relative_tolerance = 1e-8;  // stop when |b - A x| <= tol |b|; default 1e-8
  int max_iterations = 1000;         // iteration cap; default 1000
  bool warm_start = true;            // start from the caller's x (last solution); default true
  // CHOLMOD only:
  // default auto: supernodal when the factor needs >= 100 flops per nonzero
  CholmodFactorization factorization = CholmodFactorization::kAuto;
  // cholmod-pcg only. Amortised refactorisation: the next solve refactorises
  // when the last solve cost more (in flops: CG iterations x (triangular solves
  // + product with A)) than the mean per solve since the last factorisation,
  // the factorisation included - the refactorisation pays for itself once the
  // iterations of a stale factor have grown enough. Default true.
  bool refactor_by_cost = true;
  // cholmod-pcg only: a solve that needed more than this many CG iterations
  // makes the next one refactorise, whatever the cost rule says; default 20.
  int refactor_iterations = 20;
  void Check() const;
};

enum class LinearSolverStatus {
  kConverged,        // CG reached the tolerance / Cholesky succeeded
  kMaxIterations,    // CG hit the iteration cap (x holds the last iterate)
  kIndefinite,       // matrix not positive definite (CG curvature <= 0, Cholesky pivot <= 0)
  kNumericalFailure  // NaN or other failure
};
const char* LinearSolverStatusName(LinearSolverStatus status);

struct LinearSolverSummary {
  LinearSolverStatus status = LinearSolverStatus::kConverged;
  int iterations = 0;                  // CG iterations (0 for Cholesky)
  double relative_residual = 0.0;      // |b - A x| / |b| (CG)
  bool symbolic_analysis = false;      // Cholesky: symbolic analysis redone in this call
  bool numeric_factorization = false;  // Cholesky: numeric refactorisation done in this call
  std::string message;
};

class LinearSolver {
 public:
  virtual ~LinearSolver() = default;
  static std::unique_ptr<LinearSolver> Create(const LinearSolverOptions& options);

  // Declares that the pattern of the matrix changed (next Solve redoes the
  // symbolic analysis / preconditioner structure).
  virtual void PatternChanged() = 0;
  // Declares that the values changed since the last Solve (refactorise).
  virtual void ValuesChanged() = 0;
  // Solves A x = b for symmetric positive-definite A (full symmetric storage).
  // With warm_start, *x is the initial guess (its size must match b; otherwise zero).
  virtual LinearSolverSummary Solve(const SparseMatrixd& A, const Eigen::VectorXd& b,
                                    Eigen::VectorXd* x) = 0;
  virtual std::string name() const = 0;
};

}  // namespace arreg::mechanics
