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
find_package(Ceres 2.0 REQUIRED)
if(ARREG_BUILD_TESTS)
  find_package(GTest REQUIRED)
endif()
