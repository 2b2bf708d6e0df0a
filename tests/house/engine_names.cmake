# No branch on an engine's name outside the registry (ARCHITECTURE "One engine registry";
# engines/include/octocd/engine_registry.hpp, engines/include/octocd/engines.hpp): fails when a
# C++ or CUDA source under cli/, python/src/, bench/, validation/ or harness/ compares a string with
# an engine's name (built in: cpu, cuda, bullet, mujoco, ode, dart; the shipped process
# engines: rapier, jolt) (== or !=, either side). Callers ask EngineInfo instead.
# Run: cmake -DSRC=<source dir> -P tests/house/engine_names.cmake
cmake_policy(SET CMP0057 NEW)  # if(... IN_LIST ...)
if(NOT SRC)
  message(FATAL_ERROR "engine_names.cmake: pass -DSRC=<the source directory>")
endif()
include(${CMAKE_CURRENT_LIST_DIR}/scan_sources.cmake)
# Every engine name: the built-in entries' (engines/src/engines.cpp: `X.name = "NAME"` or
# `octocd_info("NAME", ...)`, `reference_info("NAME", ...)`) and the shipped process
# engines' (reference/engines.json.in: `"name": "NAME"`).
file(STRINGS ${SRC}/engines/src/engines.cpp _builtin REGEX "(\\.name = |[a-z]+_info\\()\"[a-z0-9_-]+\"")
file(STRINGS ${SRC}/reference/engines.json.in _process REGEX "\"name\": \"[a-z0-9_-]+\"")
set(_names "")
foreach(l IN LISTS _builtin _process)
  string(REGEX REPLACE ".*(= |\\(|: )\"([a-z0-9_-]+)\".*" "\\2" _n "${l}")
  list(APPEND _names ${_n})
endforeach()
list(REMOVE_DUPLICATES _names)
foreach(_required cpu cuda bullet mujoco ode dart rapier jolt)
  if(NOT _required IN_LIST _names)
    message(FATAL_ERROR "engine_names.cmake: engine '${_required}' not found in engines/src/engines.cpp or "
      "reference/engines.json.in (found: ${_names}); the scan below would miss it")
  endif()
endforeach()
list(JOIN _names "|" _alt)
house_scan(_hits _files_seen "[!=]=[ ]*\"(${_alt})\"|\"(${_alt})\"[ ]*[!=]=" cli python/src bench validation harness)
if(_files_seen EQUAL 0)
  message(FATAL_ERROR "engine_names.cmake: no source found under ${SRC} (cli, python/src, bench, validation)")
endif()
if(NOT _hits STREQUAL "")
  message(FATAL_ERROR "a branch on an engine's name outside the registry; ask octocd::engine_info(name) for the "
    "capability instead (engines/include/octocd/engine_registry.hpp):\n${_hits}")
endif()
message(STATUS "engine_names: ${_files_seen} files, no branch on an engine's name (${_alt})")

# Engine settings go through the registry (engines/include/octocd/engines.hpp:
# EngineSettingItems, each engine's entry parses its own items): no per-engine settings
# code under cli/ or python/src/ (a settings struct, its parser or a *_settings_from).
house_scan(_hits _files_seen "[A-Za-z]+_settings_from|apply_[a-z]+_settings|(Cuda|Bullet|Mujoco|Ode|Dart)Settings"
  cli python/src)
if(NOT _hits STREQUAL "")
  message(FATAL_ERROR "per-engine settings code outside the registry; pass EngineSettingItems to make_engine "
    "(engines/include/octocd/engines.hpp):\n${_hits}")
endif()
message(STATUS "engine_names: no per-engine settings code in cli/ or python/src/")
