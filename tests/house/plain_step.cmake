# The reference step stays plain (ARCHITECTURE "The house, revision 4"): planted faults
# live in tests/faults/, never in the product. Fails when a C++ or CUDA source under core/,
# gpu/, engines/, cli/, python/src/ or validation/ names PlantedFaults, plant_faults,
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
set(_hits "")
set(_files_seen 0)
foreach(dir core gpu engines cli python/src validation)
  file(GLOB_RECURSE _files ${SRC}/${dir}/*.cpp ${SRC}/${dir}/*.hpp ${SRC}/${dir}/*.h ${SRC}/${dir}/*.cu
    ${SRC}/${dir}/*.cuh)
  foreach(f IN LISTS _files)
    math(EXPR _files_seen "${_files_seen} + 1")
    file(STRINGS ${f} _lines REGEX "${_pattern}")
    foreach(l IN LISTS _lines)
      file(RELATIVE_PATH _rel ${SRC} ${f})
      string(STRIP "${l}" l)
      string(APPEND _hits "  ${_rel}: ${l}\n")
    endforeach()
  endforeach()
endforeach()
if(_files_seen EQUAL 0)
  message(FATAL_ERROR "plain_step.cmake: no source found under ${SRC} (core, gpu, engines, cli, python/src, validation)")
endif()
if(NOT _hits STREQUAL "")
  message(FATAL_ERROR "a planted fault in the product; faults belong to tests/faults/planted_faults.hpp (a test "
    "build of the stages of core/include/octocd/stages.hpp):\n${_hits}")
endif()
message(STATUS "plain_step: ${_files_seen} files, no planted fault")
