# The reference step stays plain (ARCHITECTURE "The house, revision 4"): planted faults
# live in tests/faults/, never in the product. Fails when a C++ or CUDA source under core/,
# gpu/, engines/, cli/, python/src/, validation/ or harness/ names PlantedFaults, plant_faults,
# FaultyWorld or a fault field of tests/faults/planted_faults.hpp (but normal_sign, which a
# tolerance's name holds), or templates a formula on a test-only rounding (kOtherRounding).
# Run: cmake -DSRC=<source dir> -P tests/house/plain_step.cmake
if(NOT SRC)
  message(FATAL_ERROR "plain_step.cmake: pass -DSRC=<the source directory>")
endif()
set(_pattern "PlantedFaults|plant_faults|FaultyWorld|kOtherRounding|other_rounding|explicit_euler|skip_clamp|")
string(APPEND _pattern "broadphase_drops_pair|midphase_drops_contact|jmin_first_pass_only|one_pass_fewer|")
string(APPEND _pattern "last_pass_no_corrections|impulse_wrong_body|corrections_summed|eq12_weights|friction_sign|")
string(APPEND _pattern "momentum_leak")
include(${CMAKE_CURRENT_LIST_DIR}/scan_sources.cmake)
house_scan(_hits _files_seen "${_pattern}" core gpu engines cli python/src validation harness)
if(_files_seen EQUAL 0)
  message(FATAL_ERROR "plain_step.cmake: no source found under ${SRC} (core, gpu, engines, cli, python/src, validation)")
endif()
if(NOT _hits STREQUAL "")
  message(FATAL_ERROR "a planted fault in the product; faults belong to tests/faults/planted_faults.hpp (a test "
    "build of the stages of core/include/octocd/stages.hpp):\n${_hits}")
endif()
message(STATUS "plain_step: ${_files_seen} files, no planted fault")
