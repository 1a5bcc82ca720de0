#include "mechanics/blas_binding.h"

#include <dlfcn.h>

#include <climits>
#include <cstdlib>

namespace arreg::mechanics {

namespace {

// The file of the shared object holding `address`, symlinks resolved.
std::string ObjectFile(void* address) {
  Dl_info info{};
  if (address == nullptr || dladdr(address, &info) == 0 || info.dli_fname == nullptr) return "";
  char resolved[PATH_MAX];
  if (realpath(info.dli_fname, resolved) == nullptr) return info.dli_fname;
  return resolved;
}

}  // namespace

BlasBinding ProbeBlasBinding() {
  BlasBinding binding;
  void* process_trsv = dlsym(RTLD_DEFAULT, "dtrsv_");
  void* process_gemm = dlsym(RTLD_DEFAULT, "dgemm_");
  binding.provider = ObjectFile(process_trsv);
  // RTLD_NOLOAD: only a handle to the copy already in the process, never a new load.
  void* system = dlopen("libblas.so.3", RTLD_LAZY | RTLD_NOLOAD);
  if (system == nullptr) return binding;
  void* system_trsv = dlsym(system, "dtrsv_");
  void* system_gemm = dlsym(system, "dgemm_");
  binding.system = ObjectFile(system_trsv);
  binding.system_bound =
      process_trsv != nullptr && process_trsv == system_trsv && process_gemm == system_gemm;
  dlclose(system);
  return binding;
}

std::string DescribeBlasBinding(const BlasBinding& binding) {
  if (binding.provider.empty()) return "none loaded";
  if (binding.system_bound || binding.system.empty()) return binding.provider;
  return binding.provider + " (shadows libblas.so.3 = " + binding.system + ")";
}

}  // namespace arreg::mechanics
