# ---- install: headers, static libraries, the `octocd` command and the CMake package ----
# (issue 11). `cmake --install build --prefix PREFIX` puts under PREFIX:
#   include/octocd/*.hpp, lib/liboctocd_{core,reference,validation,harness[,cuda]}.a, bin/octocd,
#   lib/cmake/octocd/{octocdConfig,octocdConfigVersion,octocdTargets}.cmake
# with the exported targets octocd::core, octocd::reference, octocd::validation, octocd::harness and,
# when OCTOCD_CUDA is on, octocd::cuda (in octocdCudaTargets.cmake, loaded only where the
# consumer's machine has the CUDA toolkit). Included from the top-level CMakeLists.txt.
include(GNUInstallDirs)
include(CMakePackageConfigHelpers)

set(_octocd_exported octocd_core octocd_reference octocd_validation octocd_harness)
set_target_properties(octocd_core PROPERTIES EXPORT_NAME core)
set_target_properties(octocd_reference PROPERTIES EXPORT_NAME reference)
set_target_properties(octocd_validation PROPERTIES EXPORT_NAME validation)
set_target_properties(octocd_harness PROPERTIES EXPORT_NAME harness)
add_library(octocd::core ALIAS octocd_core)
add_library(octocd::reference ALIAS octocd_reference)
add_library(octocd::validation ALIAS octocd_validation)
add_library(octocd::harness ALIAS octocd_harness)
if(OCTOCD_CUDA_ENABLED)
  # Without CUDA, octocd_cuda is a stub for the CLI only: not installed, not exported.
  set_target_properties(octocd_cuda PROPERTIES EXPORT_NAME cuda)
  add_library(octocd::cuda ALIAS octocd_cuda)
  install(DIRECTORY ${CMAKE_SOURCE_DIR}/gpu/include/ DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
endif()

install(TARGETS ${_octocd_exported} EXPORT octocdTargets
  ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
  LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR}
  INCLUDES DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
# octocd::cuda has an export file of its own (octocdCudaTargets.cmake), loaded by the
# package only where the CUDA toolkit is found: CPU-only consumers never need it (issue 17).
if(OCTOCD_CUDA_ENABLED)
  install(TARGETS octocd_cuda EXPORT octocdCudaTargets
    ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
    LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR}
    INCLUDES DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
endif()
install(TARGETS octocd RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR} COMPONENT runtime)
foreach(dir core validation harness)
  install(DIRECTORY ${CMAKE_SOURCE_DIR}/${dir}/include/ DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
endforeach()
foreach(room IN LISTS OCTOCD_REFERENCE_ROOMS)  # reference/<room>/include (reference/CMakeLists.txt)
  install(DIRECTORY ${CMAKE_SOURCE_DIR}/reference/${room}/include/ DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
endforeach()

set(_octocd_cmake_dir ${CMAKE_INSTALL_LIBDIR}/cmake/octocd)
install(EXPORT octocdTargets NAMESPACE octocd:: DESTINATION ${_octocd_cmake_dir})
if(OCTOCD_CUDA_ENABLED)
  install(EXPORT octocdCudaTargets NAMESPACE octocd:: DESTINATION ${_octocd_cmake_dir})
endif()
configure_package_config_file(${CMAKE_SOURCE_DIR}/cmake/octocdConfig.cmake.in
  ${CMAKE_BINARY_DIR}/octocdConfig.cmake INSTALL_DESTINATION ${_octocd_cmake_dir})
# 0.x: a minor version may break the API, so only the same minor version is compatible.
write_basic_package_version_file(${CMAKE_BINARY_DIR}/octocdConfigVersion.cmake
  VERSION ${PROJECT_VERSION} COMPATIBILITY SameMinorVersion)
install(FILES ${CMAKE_BINARY_DIR}/octocdConfig.cmake ${CMAKE_BINARY_DIR}/octocdConfigVersion.cmake
  DESTINATION ${_octocd_cmake_dir})

# ---- shared files: PREFIX/share/octocd, laid out as in the source tree -------------------
# The scenes, the dataset fetch script, the named bench sweeps and the report generator.
# The installed `octocd` finds them at <its folder>/../share/octocd (octocd::shared_dir(),
# core/include/octocd/shared_files.hpp), so the prefix may be copied or moved and the
# source tree removed (ctest install.relocatable; docs/install.md). That rule assumes the
# default CMAKE_INSTALL_BINDIR (bin) and CMAKE_INSTALL_DATADIR (share). With bin/octocd they
# form the component `runtime` (`cmake --install build --component runtime`: the command
# alone, without headers, libraries or the Python package).
set(_octocd_share ${CMAKE_INSTALL_DATADIR}/octocd)
install(DIRECTORY ${CMAKE_SOURCE_DIR}/datasets/scenes DESTINATION ${_octocd_share}/datasets
  COMPONENT runtime FILES_MATCHING PATTERN "*.json")
install(PROGRAMS ${CMAKE_SOURCE_DIR}/datasets/fetch.sh DESTINATION ${_octocd_share}/datasets COMPONENT runtime)
install(FILES ${CMAKE_SOURCE_DIR}/datasets/SHA256SUMS ${CMAKE_SOURCE_DIR}/datasets/split_mesh.py
  ${CMAKE_SOURCE_DIR}/datasets/README.md DESTINATION ${_octocd_share}/datasets COMPONENT runtime)
install(DIRECTORY ${CMAKE_SOURCE_DIR}/bench/sweeps DESTINATION ${_octocd_share}/bench
  COMPONENT runtime FILES_MATCHING PATTERN "*.json")
# The report: its entry point make_report.py and its modules report_*.py beside it.
file(GLOB _octocd_report_py CONFIGURE_DEPENDS ${CMAKE_SOURCE_DIR}/report/report_*.py)
install(FILES ${CMAKE_SOURCE_DIR}/report/make_report.py ${_octocd_report_py} ${CMAKE_SOURCE_DIR}/report/paper_tables.json
  DESTINATION ${_octocd_share}/report COMPONENT runtime)
# The shipped process engines (docs/bring-your-engine.md): PREFIX/share/octocd/engines.json
# naming the JavaScript engines installed beside it in reference/ (their npm packages are
# installed there with `npm ci --prefix PREFIX/share/octocd/reference`; until then `octocd
# engines` shows them unavailable with the reason). The build tree's own engines file
# (engines/CMakeLists.txt) points into the source tree instead.
set(OCTOCD_ENGINES_RAPIER_JS reference/rapier/rapier_engine.js)
set(OCTOCD_ENGINES_JOLT_JS reference/jolt/jolt_engine.js)
configure_file(${CMAKE_SOURCE_DIR}/reference/engines.json.in ${CMAKE_BINARY_DIR}/install-share/engines.json @ONLY)
install(FILES ${CMAKE_BINARY_DIR}/install-share/engines.json DESTINATION ${_octocd_share} COMPONENT runtime)
install(FILES ${CMAKE_SOURCE_DIR}/reference/package.json ${CMAKE_SOURCE_DIR}/reference/package-lock.json
  DESTINATION ${_octocd_share}/reference COMPONENT runtime OPTIONAL)
foreach(_octocd_js_engine rapier jolt js-common)
  file(GLOB _octocd_js CONFIGURE_DEPENDS ${CMAKE_SOURCE_DIR}/reference/${_octocd_js_engine}/*.js)
  if(_octocd_js)
    install(FILES ${_octocd_js} DESTINATION ${_octocd_share}/reference/${_octocd_js_engine} COMPONENT runtime)
  endif()
endforeach()
