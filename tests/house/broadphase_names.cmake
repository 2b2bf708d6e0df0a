# Every broadphase's name is spelled in one place, the table core/include/octocd/broadphase_table.def
# (ARCHITECTURE revision 6 "One table per identity"; docs/architecture.md "Adding a broadphase"):
# fails when a string literal of a name of that table ("octree", 'fcl-sap', ...) appears in a
# product source (C++, CUDA, Python, shell, CMake) under core/, gpu/, reference/, engines/,
# validation/, cli/, bench/, python/, report/ or scripts/. Code names a broadphase by its
# BroadPhaseId (broadphase_name(BroadPhaseId::octree)) and asks its BroadPhaseInfo for facts.
# Comments, docs/ and tests/ may spell names. The names are read from the table, so a new row
# is covered without an edit here.
# Run: cmake -DSRC=<source dir> -P tests/house/broadphase_names.cmake
cmake_minimum_required(VERSION 3.16)
if(NOT SRC)
  message(FATAL_ERROR "broadphase_names.cmake: pass -DSRC=<the source directory>")
endif()
set(_table ${SRC}/core/include/octocd/broadphase_table.def)
file(STRINGS ${_table} _rows REGEX "^OCTOCD_BROADPHASE\\(")
set(_names "")
foreach(_row IN LISTS _rows)
  if(NOT _row MATCHES "^OCTOCD_BROADPHASE\\([a-z0-9_]+, *\"([a-z0-9-]+)\"")
    message(FATAL_ERROR "broadphase_names.cmake: a row of ${_table} without a quoted name: ${_row}")
  endif()
  list(APPEND _names "${CMAKE_MATCH_1}")
endforeach()
list(LENGTH _names _count)
if(_count LESS 5)
  message(FATAL_ERROR "broadphase_names.cmake: ${_count} rows read from ${_table}; expected the whole table")
endif()
list(JOIN _names "|" _alternatives)
set(_literal "\"(${_alternatives})\"|'(${_alternatives})'")

# Files that may spell a name, each for its reason (relative to SRC).
set(_allowed
  # The engine registry's own broadphases (EngineInfo::own_broadphase -> class) for a report
  # without the registry at hand; tests/report/test_report_comparisons.py keeps it in step.
  report/report_plots.py
  # Seed data for the fuzzers: a sweep definition copied from fuzz/fuzz_bench_result.cpp.
  scripts/fuzz_json_seeds.py
  # The broadphase bench's table: its ratio column is to bullet-dbvt, the reference baseline.
  bench/broadphase_table.py)

set(_hits "")
set(_seen 0)
foreach(_dir core gpu reference engines validation cli bench python report scripts)
  file(GLOB_RECURSE _files ${SRC}/${_dir}/*.cpp ${SRC}/${_dir}/*.hpp ${SRC}/${_dir}/*.h ${SRC}/${_dir}/*.cu
    ${SRC}/${_dir}/*.cuh ${SRC}/${_dir}/*.def ${SRC}/${_dir}/*.py ${SRC}/${_dir}/*.sh ${SRC}/${_dir}/*.cmake
    ${SRC}/${_dir}/CMakeLists.txt)
  foreach(_f IN LISTS _files)
    file(RELATIVE_PATH _rel ${SRC} ${_f})
    if(_f STREQUAL _table OR _rel IN_LIST _allowed)
      continue()
    endif()
    math(EXPR _seen "${_seen} + 1")
    file(STRINGS ${_f} _lines REGEX "${_literal}")
    foreach(_l IN LISTS _lines)
      string(STRIP "${_l}" _l)
      # A whole-line comment (C++ //, /* and * lines; Python, shell and CMake #).
      if(_l MATCHES "^(//|/\\*|\\*|#)")
        continue()
      endif()
      # A trailing comment: C++ // everywhere, # in Python, shell and CMake.
      string(REGEX REPLACE "[ \t]//.*$" "" _code "${_l}")
      if(_f MATCHES "\\.(py|sh|cmake)$|CMakeLists\\.txt$")
        string(REGEX REPLACE "[ \t]#.*$" "" _code "${_code}")
      endif()
      if(_code MATCHES "${_literal}")
        string(APPEND _hits "  ${_rel}: ${_l}\n")
      endif()
    endforeach()
  endforeach()
endforeach()
if(_seen LESS 100)
  message(FATAL_ERROR "broadphase_names.cmake: only ${_seen} product files found under ${SRC}")
endif()
if(NOT _hits STREQUAL "")
  message(FATAL_ERROR "a broadphase's name spelled outside its table (core/include/octocd/broadphase_table.def); "
    "name it by its BroadPhaseId (broadphase_name(BroadPhaseId::octree)) or ask its BroadPhaseInfo "
    "(octocd/broadphase_registry.hpp) instead:\n${_hits}")
endif()
message(STATUS "broadphase_names: ${_count} names, ${_seen} product files, no name spelled outside the table")
