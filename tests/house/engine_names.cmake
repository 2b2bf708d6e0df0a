# No branch on an engine's name outside the registry (ARCHITECTURE "One engine registry";
# engines/include/octocd/engine_registry.hpp, engines/include/octocd/engines.hpp): fails when a
# C++ or CUDA source under cli/, python/src/, bench/, validation/ or harness/ compares a string with
# "cpu", "cuda" or "bullet" (== or !=, either side). Callers ask EngineInfo instead.
# Run: cmake -DSRC=<source dir> -P tests/house/engine_names.cmake
if(NOT SRC)
  message(FATAL_ERROR "engine_names.cmake: pass -DSRC=<the source directory>")
endif()
include(${CMAKE_CURRENT_LIST_DIR}/scan_sources.cmake)
house_scan(_hits _files_seen "[!=]=[ ]*\"(cpu|cuda|bullet)\"|\"(cpu|cuda|bullet)\"[ ]*[!=]=" cli python/src bench validation harness)
if(_files_seen EQUAL 0)
  message(FATAL_ERROR "engine_names.cmake: no source found under ${SRC} (cli, python/src, bench, validation)")
endif()
if(NOT _hits STREQUAL "")
  message(FATAL_ERROR "a branch on an engine's name outside the registry; ask octocd::engine_info(name) for the "
    "capability instead (engines/include/octocd/engine_registry.hpp):\n${_hits}")
endif()
message(STATUS "engine_names: ${_files_seen} files, no branch on an engine's name")

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
