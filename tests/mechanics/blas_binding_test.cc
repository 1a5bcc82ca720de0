// The process's BLAS symbols come from the system's libblas.so.3 (see
// cmake/ArregDependencies.cmake), and the description names a shadowing library.
#include <gtest/gtest.h>

#include "mechanics/blas_binding.h"
#include "mechanics/linear_solver.h"

namespace arreg::mechanics {
namespace {

TEST(BlasBinding, CholmodsBlasIsLibblas) {
  // CHOLMOD is linked, so libblas.so.3 is loaded and dtrsv_ resolves.
  const auto solver = LinearSolver::Create(LinearSolverOptions());
  ASSERT_NE(solver, nullptr);
  const BlasBinding binding = ProbeBlasBinding();
  ASSERT_FALSE(binding.provider.empty());
  ASSERT_FALSE(binding.system.empty());
  EXPECT_TRUE(binding.system_bound) << DescribeBlasBinding(binding);
  EXPECT_EQ(binding.provider, binding.system);
}

TEST(BlasBinding, DescriptionNamesWhatIsShadowed) {
  BlasBinding b;
  EXPECT_EQ(DescribeBlasBinding(b), "none loaded");
  b.provider = "/lib/a.so";
  b.system = "/lib/b.so";
  EXPECT_EQ(DescribeBlasBinding(b), "/lib/a.so (shadows libblas.so.3 = /lib/b.so)");
  b.system_bound = true;
  b.system = b.provider;
  EXPECT_EQ(DescribeBlasBinding(b), "/lib/a.so");
}

}  // namespace
}  // namespace arreg::mechanics
