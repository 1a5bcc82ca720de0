# Helpers that give every target the same flags and enforce the module layering.
#
# Module layering (who may link whom). A module may depend only on the modules
# listed for it; arreg_add_module() fails the configure step otherwise, so a
# cycle cannot creep in. A module's sources see only its own headers and those of
# the modules it depends on (directly or below): each module publishes its folder
# through an include root of its own (below), so an upward include fails to compile.
# Module ar_X is the folder src/ar/X/.
set(ARREG_ALLOWED_DEPS_core "")
set(ARREG_ALLOWED_DEPS_tracking "core")
set(ARREG_ALLOWED_DEPS_mechanics "core")
set(ARREG_ALLOWED_DEPS_cutting "core;mechanics")
# src/ar/: rendering and lifting below the pipeline; synthetic scenes and evaluation beside
# it; the frame-by-frame viewer above it; the initial alignment (Ceres) on its own.
set(ARREG_ALLOWED_DEPS_ar_render "core")
set(ARREG_ALLOWED_DEPS_ar_lift "core")
set(ARREG_ALLOWED_DEPS_ar_pipeline "core;tracking;mechanics;cutting;ar_render;ar_lift")
set(ARREG_ALLOWED_DEPS_ar_synth "core;tracking;ar_render")
set(ARREG_ALLOWED_DEPS_ar_eval "core;ar_render")
set(ARREG_ALLOWED_DEPS_ar_debug "core;ar_render;ar_pipeline")
set(ARREG_ALLOWED_DEPS_ar_align "core;tracking")

function(arreg_set_common_options target)
  target_compile_options(${target} PRIVATE
    $<$<CXX_COMPILER_ID:GNU,Clang>:-Wall -Wextra -Wpedantic -Wno-unused-parameter>
    # error.h's ARREG_CHECK_INPUT uses the GNU ", ##__VA_ARGS__" that GCC accepts silently.
    $<$<CXX_COMPILER_ID:Clang>:-Wno-gnu-zero-variadic-macro-arguments>)
  if(ARREG_NATIVE)
    target_compile_options(${target} PRIVATE -march=native)
  endif()
  if(ARREG_SANITIZE)
    target_compile_options(${target} PRIVATE -fsanitize=address,undefined -fno-omit-frame-pointer
                                             -fno-sanitize-recover=undefined
                                             # GCC 12 under ASan warns inside libstdc++'s <regex>.
                                             $<$<CXX_COMPILER_ID:GNU>:-Wno-maybe-uninitialized>)
    target_link_options(${target} PRIVATE -fsanitize=address,undefined)
  endif()
  if(ARREG_FUZZ)
    # Coverage for libFuzzer in every arreg target; only the fuzz executables link the fuzzer's main.
    target_compile_options(${target} PRIVATE -fsanitize=fuzzer-no-link,address,undefined
                                             -fno-omit-frame-pointer -fno-sanitize-recover=undefined)
    target_link_options(${target} PRIVATE -fsanitize=address,undefined)
  endif()
endfunction()

# arreg_add_module(NAME SOURCES ... MODULES <arreg modules> LIBS <third-party targets>)
function(arreg_add_module name)
  cmake_parse_arguments(ARG "" "" "SOURCES;MODULES;LIBS;PRIVATE_LIBS" ${ARGN})
  if(NOT DEFINED ARREG_ALLOWED_DEPS_${name})
    message(FATAL_ERROR "arreg module '${name}' has no entry in the layering table (cmake/ArregHelpers.cmake)")
  endif()
  foreach(dep IN LISTS ARG_MODULES)
    list(FIND ARREG_ALLOWED_DEPS_${name} ${dep} idx)
    if(idx EQUAL -1)
      message(FATAL_ERROR "arreg module '${name}' may not depend on '${dep}' "
                          "(allowed: ${ARREG_ALLOWED_DEPS_${name}}); see the layering table in README.md")
    endif()
  endforeach()
  set(module_targets "")
  foreach(dep IN LISTS ARG_MODULES)
    list(APPEND module_targets arreg_${dep})
  endforeach()
  add_library(arreg_${name} STATIC ${ARG_SOURCES})
  add_library(arreg::${name} ALIAS arreg_${name})
  # The module's include root: <build>/arreg-include/<name>/<folder> is a link to
  # src/<folder>, so "core/mesh.h" or "ar/render/rasterizer.h" resolve only for
  # the module itself and for the modules that link it.
  string(REPLACE "_" "/" folder "${name}")
  set(root "${PROJECT_BINARY_DIR}/arreg-include/${name}")
  get_filename_component(parent "${root}/${folder}" DIRECTORY)
  file(MAKE_DIRECTORY "${parent}")
  file(CREATE_LINK "${PROJECT_SOURCE_DIR}/src/${folder}" "${root}/${folder}" SYMBOLIC)
  target_include_directories(arreg_${name} PUBLIC "${root}")
  target_link_libraries(arreg_${name} PUBLIC ${module_targets} ${ARG_LIBS} PRIVATE ${ARG_PRIVATE_LIBS})
  arreg_set_common_options(arreg_${name})
endfunction()

# arreg_add_test(NAME SOURCES ... LIBS ... [LABELS ...] [TIMEOUT s])
# One GoogleTest executable per call, registered with CTest test by test
# (gtest_discover_tests) so that `ctest -L slow` / `-LE slow` select them.
function(arreg_add_test name)
  cmake_parse_arguments(ARG "" "TIMEOUT" "SOURCES;LIBS;LABELS" ${ARGN})
  add_executable(${name} ${ARG_SOURCES})
  target_link_libraries(${name} PRIVATE ${ARG_LIBS} GTest::gtest GTest::gtest_main)
  target_include_directories(${name} PRIVATE "${PROJECT_SOURCE_DIR}/tests")
  target_compile_definitions(${name} PRIVATE
    ARREG_SOURCE_DIR="${PROJECT_SOURCE_DIR}"
    ARREG_BINARY_DIR="${PROJECT_BINARY_DIR}")
  arreg_set_common_options(${name})
  if(NOT ARG_TIMEOUT)
    set(ARG_TIMEOUT 300)
  endif()
  if(NOT ARG_LABELS)
    set(ARG_LABELS unit)
  endif()
  gtest_discover_tests(${name}
    WORKING_DIRECTORY "${PROJECT_SOURCE_DIR}"
    PROPERTIES LABELS "${ARG_LABELS}" TIMEOUT ${ARG_TIMEOUT}
    DISCOVERY_TIMEOUT 60)
endfunction()
