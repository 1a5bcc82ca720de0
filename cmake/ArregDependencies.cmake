# Third-party packages, all from Debian (scripts/install-deps installs them).
find_package(Threads REQUIRED)
find_package(Eigen3 3.4 REQUIRED NO_MODULE)
find_package(nlohmann_json 3.10 REQUIRED)
find_package(OpenCV 4 REQUIRED COMPONENTS core imgproc imgcodecs video calib3d)
find_package(PkgConfig REQUIRED)
pkg_check_modules(FFMPEG REQUIRED IMPORTED_TARGET libavformat libavcodec libswscale libavutil)
# Debian's SuiteSparse ships no CMake config: locate CHOLMOD directly.
find_path(CHOLMOD_INCLUDE_DIR cholmod.h PATH_SUFFIXES suitesparse REQUIRED)
find_library(CHOLMOD_LIBRARY cholmod REQUIRED)
add_library(arreg_cholmod INTERFACE)
target_include_directories(arreg_cholmod SYSTEM INTERFACE "${CHOLMOD_INCLUDE_DIR}")
target_link_libraries(arreg_cholmod INTERFACE "${CHOLMOD_LIBRARY}")
# CHOLMOD's OpenMP runtime, linked directly so that the solver can keep its loops serial
# (cholmod_solver.cc); no -fopenmp for our own sources.
find_package(OpenMP REQUIRED COMPONENTS CXX)
target_link_libraries(arreg_cholmod INTERFACE ${OpenMP_CXX_LIBRARIES})
find_package(CGAL 5.5 REQUIRED)
# ATLAS's libf77blas, when an executable names it, comes before libblas.so.3 in the dynamic
# linker's search order: its Fortran BLAS symbols (dtrsv_, dgemm_, ...) then shadow the system
# BLAS (OpenBLAS through Debian's alternatives, scripts/install-deps) for every library of the
# process, CHOLMOD included. Two places would name it: Debian's Ceres exports libf77blas and
# libatlas on its own link line, and its CMake config runs FindBLAS again for SuiteSparse, which
# prefers ATLAS when ATLAS is installed (Ceres' package pulls it in). Ceres calls only the
# standard BLAS and LAPACK interfaces: link the alternatives-managed libblas.so.3 and
# liblapack.so.3 (the generic vendor) and drop the ATLAS names. Tests: BlasBinding.*,
# Cli.VersionNamesTheBlasAndItIsLibblas.
set(BLA_VENDOR Generic)
find_package(Ceres 2.0 REQUIRED)
get_target_property(_arreg_ceres_libs Ceres::ceres INTERFACE_LINK_LIBRARIES)
list(FILTER _arreg_ceres_libs EXCLUDE REGEX "/lib(f77blas|atlas)\\.so")
set_target_properties(Ceres::ceres PROPERTIES INTERFACE_LINK_LIBRARIES "${_arreg_ceres_libs}")
if(ARREG_BUILD_TESTS)
  find_package(GTest REQUIRED)
endif()
