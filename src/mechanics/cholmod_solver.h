// The CHOLMOD backend of LinearSolver (kept out of linear_solver.h so that
// users of the interface do not see CHOLMOD's headers).
#pragma once

#include <memory>

#include "mechanics/linear_solver.h"

namespace arreg::mechanics {

std::unique_ptr<LinearSolver> MakeCholmodSolver(const LinearSolverOptions& options);

}  // namespace arreg::mechanics
