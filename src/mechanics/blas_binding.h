// Which BLAS the process's sparse factorisations run on.
//
// CHOLMOD's supernodal factorisation and solves call the Fortran BLAS (dgemm_,
// dsyrk_, dtrsm_, dtrsv_, ...) through the dynamic linker, which binds each symbol
// to the first loaded library that exports it. The intended provider is the
// system's libblas.so.3 (Debian's alternatives: OpenBLAS after
// scripts/install-deps); a library loaded earlier that exports the same names
// (ATLAS's libf77blas, for one) silently replaces it for the whole process.
#pragma once

#include <string>

namespace arreg::mechanics {

struct BlasBinding {
  std::string provider;       // file of the object the process's dtrsv_ comes from ("" if none)
  std::string system;         // file behind libblas.so.3, symlinks resolved ("" if not loaded)
  bool system_bound = false;  // the process's dtrsv_ and dgemm_ are libblas.so.3's
};

// Looks the symbols up in the running process (no library is loaded by it).
BlasBinding ProbeBlasBinding();

// One line for `arreg --version` and benchmark logs: the provider's path, and
// when it is not libblas.so.3 what it shadows.
std::string DescribeBlasBinding(const BlasBinding& binding);

}  // namespace arreg::mechanics
