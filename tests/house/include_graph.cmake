# No circles between the product's files (ARCHITECTURE "No circles"), none between its rooms,
# and the judges include nothing of the harness ("Output above the judges"). Reads every
# quoted #include of the C++ and CUDA sources of core, gpu, reference, validation, harness,
# engines, cli, python/src and bench, resolves it (beside the including file; `octocd/X` in a
# folder's include/; else the one product file whose path ends with it) and fails on:
# - a circle between units, a unit being a source with its headers (cli/run.cpp with
#   cli/run.hpp; harness/src/expect.cpp with harness/include/octocd/expect.hpp). Unit U
#   reaches unit V when a file of U calls (writes `NAME(`) a free function that a header
#   U includes (directly or through other headers) declares at namespace level and a source
#   of V defines (a column-0 definition in a source that includes that header). So
#   commands.cpp calling run.cpp's add_run_command while run.cpp calls commands.cpp's
#   engines_help, both through commands.hpp, is a circle;
# - a circle between rooms (the top-level folders: core, gpu, ..., cli, python, bench;
#   an adapter's registration file, compiled into octocd_engines, is in engines) through
#   their includes;
# - an include from validation/ (the judges) of a file under harness/;
# - an include from validation/device/ (the judges' device part) of a file outside it and
#   core/ (it shares no code with the engine it judges: docs/architecture.md, "The judges'
#   device part");
# - an include from engines/ or reference/ (the engines) of a file under validation/: an
#   engine reads its traces through core's external-trace reader, never the judges' library
#   (docs/architecture.md, "No circles").
# Run: cmake -DSRC=<source dir> -P tests/house/include_graph.cmake
if(NOT SRC)
  message(FATAL_ERROR "include_graph.cmake: pass -DSRC=<the source directory>")
endif()
set(_rooms core gpu reference validation harness engines cli python/src bench)

set(_files "")
foreach(room IN LISTS _rooms)
  file(GLOB_RECURSE f RELATIVE ${SRC} ${SRC}/${room}/*.cpp ${SRC}/${room}/*.hpp ${SRC}/${room}/*.h
    ${SRC}/${room}/*.cu ${SRC}/${room}/*.cuh)
  list(APPEND _files ${f})
endforeach()
list(LENGTH _files _nfiles)
if(_nfiles EQUAL 0)
  message(FATAL_ERROR "include_graph.cmake: no source found under ${SRC} (${_rooms})")
endif()

# unit_of(OUT PATH): the folder with a trailing /include/octocd or /src dropped, and the stem.
function(unit_of out path)
  get_filename_component(dir ${path} DIRECTORY)
  get_filename_component(stem ${path} NAME_WE)
  string(REGEX REPLACE "/include/octocd$" "" dir "${dir}")
  string(REGEX REPLACE "/src$" "" dir "${dir}")
  set(${out} "${dir}/${stem}" PARENT_SCOPE)
endfunction()
# An adapter's registration file (reference/<engine>/<engine>_engine.cpp, named by
# octocd_register_engine in reference's CMakeLists.txt files) is compiled into the registry's
# library, octocd_engines: it stands in the room engines, wherever its folder is.
file(GLOB_RECURSE _reference_lists ${SRC}/reference/CMakeLists.txt)
set(_registered "")
foreach(l IN LISTS _reference_lists)
  get_filename_component(dir ${l} DIRECTORY)
  file(RELATIVE_PATH dir ${SRC} ${dir})
  file(STRINGS ${l} regs REGEX "octocd_register_engine\\(")
  foreach(r IN LISTS regs)
    if(r MATCHES "CMAKE_CURRENT_SOURCE_DIR}/([^ )]+)")
      list(APPEND _registered "${dir}/${CMAKE_MATCH_1}")
    endif()
  endforeach()
endforeach()

# room_of(OUT PATH): the top-level folder (python/src is the room python; a registered
# adapter file is in engines).
function(room_of out path)
  list(FIND _registered "${path}" at)
  if(at GREATER -1)
    set(${out} "engines" PARENT_SCOPE)
    return()
  endif()
  string(REGEX MATCH "^[^/]+" r "${path}")
  set(${out} "${r}" PARENT_SCOPE)
endfunction()

# resolve(OUT FROM TEXT): the product file that `#include "TEXT"` in FROM reads, "" when none
# (a system or generated header).
function(resolve out from text)
  get_filename_component(dir ${from} DIRECTORY)
  get_filename_component(beside "${SRC}/${dir}/${text}" ABSOLUTE)
  if(EXISTS "${beside}" AND NOT IS_DIRECTORY "${beside}")
    file(RELATIVE_PATH rel ${SRC} ${beside})
    set(${out} "${rel}" PARENT_SCOPE)
    return()
  endif()
  foreach(f IN LISTS _files)
    if(text MATCHES "^octocd/")
      if(f MATCHES "/include/${text}$")
        set(${out} "${f}" PARENT_SCOPE)
        return()
      endif()
    elseif(f STREQUAL text OR f MATCHES "/${text}$")
      set(${out} "${f}" PARENT_SCOPE)
      return()
    endif()
  endforeach()
  set(${out} "" PARENT_SCOPE)
endfunction()

# Pass 1: each file's resolved includes (_inc_<id>), the free functions each header declares
# (_decl_<id>), the names each file calls (_calls_<id>_<NAME>), the room graph and the rule
# that the judges include nothing of the harness.
set(_units "")
set(_room_names "")
set(_judges_to_harness "")
set(_device_judge_out "")
set(_engines_to_judges "")
set(_kw "^(namespace|using|template|class|struct|union|enum|return|typedef|static_assert|if|for|while|switch|case|default|public|private|protected|extern|friend|operator|sizeof|decltype|alignas|noexcept)$")
foreach(f IN LISTS _files)
  unit_of(uf ${f})
  room_of(rf ${f})
  string(MAKE_C_IDENTIFIER "${f}" idf)
  string(MAKE_C_IDENTIFIER "${rf}" ridf)
  list(APPEND _units "${uf}")
  list(APPEND _room_names "${rf}")
  set(_inc_${idf} "")
  file(STRINGS ${SRC}/${f} incs REGEX "^[ \t]*#[ \t]*include[ \t]*\"")
  foreach(line IN LISTS incs)
    string(REGEX REPLACE "^[ \t]*#[ \t]*include[ \t]*\"([^\"]+)\".*" "\\1" text "${line}")
    resolve(to ${f} "${text}")
    if(to STREQUAL "")
      continue()
    endif()
    list(APPEND _inc_${idf} "${to}")
    if(f MATCHES "^validation/" AND to MATCHES "^harness/")
      string(APPEND _judges_to_harness "  ${f} includes ${to}\n")
    endif()
    if(f MATCHES "^validation/device/" AND NOT to MATCHES "^(validation/device|core)/")
      string(APPEND _device_judge_out "  ${f} includes ${to}\n")
    endif()
    if(rf MATCHES "^(engines|reference)$" AND to MATCHES "^validation/")
      string(APPEND _engines_to_judges "  ${f} includes ${to}\n")
    endif()
    room_of(rt ${to})
    if(NOT rt STREQUAL rf)
      list(APPEND _rout_${ridf} "${rt}")
      string(MAKE_C_IDENTIFIER "${rt}" ridt)
      set(_rwhy_${ridf}_${ridt} "${f} -> ${to}")
    endif()
  endforeach()
  # Column-0 lines: a header's declarations, a source's definitions (the first NAME( of the line).
  file(STRINGS ${SRC}/${f} tops REGEX "^[A-Za-z_][^;]*[A-Za-z0-9_]\\(")
  set(_top_${idf} "")
  foreach(line IN LISTS tops)
    if(line MATCHES "^[A-Za-z_][A-Za-z0-9_]*" AND CMAKE_MATCH_0 MATCHES "${_kw}")
      continue()
    endif()
    if(line MATCHES "([A-Za-z_][A-Za-z0-9_:]*)\\(")
      set(name "${CMAKE_MATCH_1}")
      if(NOT name MATCHES "::" AND NOT name MATCHES "${_kw}")
        list(APPEND _top_${idf} "${name}")
      endif()
    endif()
  endforeach()
  file(READ ${SRC}/${f} body)
  string(REGEX MATCHALL "[A-Za-z_][A-Za-z0-9_]*\\(" called "${body}")
  list(REMOVE_DUPLICATES called)
  foreach(c IN LISTS called)
    string(LENGTH "${c}" n)
    math(EXPR n "${n} - 1")
    string(SUBSTRING "${c}" 0 ${n} c)
    set(_calls_${idf}_${c} 1)
  endforeach()
endforeach()
list(REMOVE_DUPLICATES _units)
list(REMOVE_DUPLICATES _room_names)

if(NOT _judges_to_harness STREQUAL "")
  message(FATAL_ERROR "the judges (validation/) include the harness (harness/), which stands above them "
    "(docs/architecture.md, \"What the harness does with verdicts\"):\n${_judges_to_harness}")
endif()

if(NOT _device_judge_out STREQUAL "")
  message(FATAL_ERROR "the judges' device part (validation/device/) includes a file outside itself and core/ "
    "(docs/architecture.md, \"The judges' device part\"):\n${_device_judge_out}")
endif()

if(NOT _engines_to_judges STREQUAL "")
  message(FATAL_ERROR "an engine (engines/, reference/) includes the judges (validation/), which stand above "
    "the engines they judge; traces are read through core's octocd/external_trace.hpp (docs/architecture.md, "
    "\"No circles\"):\n${_engines_to_judges}")
endif()

# Pass 2: who defines what a header declares: a source (.cpp, .cu) that includes the header
# and has a column-0 line of that name (_def_<header id>_<NAME>: the defining units).
foreach(f IN LISTS _files)
  if(NOT f MATCHES "\\.(cpp|cu)$")
    continue()
  endif()
  string(MAKE_C_IDENTIFIER "${f}" idf)
  unit_of(uf ${f})
  foreach(h IN LISTS _inc_${idf})
    string(MAKE_C_IDENTIFIER "${h}" idh)
    foreach(name IN LISTS _top_${idf})
      list(FIND _top_${idh} "${name}" at)
      if(at GREATER -1)
        list(APPEND _def_${idh}_${name} "${uf}")
      endif()
    endforeach()
  endforeach()
endforeach()

# Pass 3: unit edges. For each file, the headers it reaches; for each free function they
# declare that the file calls, an edge to the units that define it.
set(_edges 0)
foreach(f IN LISTS _files)
  string(MAKE_C_IDENTIFIER "${f}" idf)
  unit_of(uf ${f})
  string(MAKE_C_IDENTIFIER "${uf}" idu)
  set(seen ${_inc_${idf}})
  set(todo ${_inc_${idf}})
  while(todo)
    list(POP_FRONT todo h)
    string(MAKE_C_IDENTIFIER "${h}" idh)
    foreach(next IN LISTS _inc_${idh})
      list(FIND seen "${next}" at)
      if(at EQUAL -1)
        list(APPEND seen "${next}")
        list(APPEND todo "${next}")
      endif()
    endforeach()
  endwhile()
  foreach(h IN LISTS seen)
    string(MAKE_C_IDENTIFIER "${h}" idh)
    foreach(name IN LISTS _top_${idh})
      if(NOT _calls_${idf}_${name})
        continue()
      endif()
      list(FIND _def_${idh}_${name} "${uf}" own)
      if(own GREATER -1)
        continue()  # this unit defines it too (an alternative: cuda_world.cpp and cuda_stub.cpp)
      endif()
      foreach(v IN LISTS _def_${idh}_${name})
        if(NOT v STREQUAL uf)
          string(MAKE_C_IDENTIFIER "${v}" idv)
          list(APPEND _out_${idu} "${v}")
          if(NOT DEFINED _why_${idu}_${idv})
            set(_why_${idu}_${idv} "${f} calls ${name}, ${h}")
          endif()
          math(EXPR _edges "${_edges} + 1")
        endif()
      endforeach()
    endforeach()
  endforeach()
endforeach()

# circles(OUT_TEXT NODES PREFIX WHY_PREFIX): the nodes that lie on a circle, with the includes
# that tie them, as text ("" when there is none). Repeatedly drops every node that no kept
# node includes or that includes no kept node; what is left lies on or between circles.
function(circles out nodes prefix why)
  foreach(n IN LISTS nodes)
    string(MAKE_C_IDENTIFIER "${n}" id)
    set(_alive_${id} 1)
    set(_in_${id} 0)
  endforeach()
  set(kept ${nodes})
  set(changed 1)
  while(changed)
    set(changed 0)
    foreach(n IN LISTS kept)
      string(MAKE_C_IDENTIFIER "${n}" id)
      set(_in_${id} 0)
    endforeach()
    foreach(n IN LISTS kept)
      string(MAKE_C_IDENTIFIER "${n}" id)
      set(has_out 0)
      foreach(t IN LISTS ${prefix}${id})
        string(MAKE_C_IDENTIFIER "${t}" tid)
        if(_alive_${tid})
          set(has_out 1)
          set(_in_${tid} 1)
        endif()
      endforeach()
      set(_has_out_${id} ${has_out})
    endforeach()
    set(next "")
    foreach(n IN LISTS kept)
      string(MAKE_C_IDENTIFIER "${n}" id)
      if(_has_out_${id} AND _in_${id})
        list(APPEND next "${n}")
      else()
        set(_alive_${id} 0)
        set(changed 1)
      endif()
    endforeach()
    set(kept ${next})
  endwhile()
  set(text "")
  foreach(n IN LISTS kept)
    string(MAKE_C_IDENTIFIER "${n}" id)
    set(targets ${${prefix}${id}})
    list(REMOVE_DUPLICATES targets)
    foreach(t IN LISTS targets)
      string(MAKE_C_IDENTIFIER "${t}" tid)
      if(_alive_${tid})
        string(APPEND text "  ${n} -> ${t} (${${why}${id}_${tid}})\n")
      endif()
    endforeach()
  endforeach()
  set(${out} "${text}" PARENT_SCOPE)
endfunction()

circles(_unit_circles "${_units}" _out_ _why_)
if(NOT _unit_circles STREQUAL "")
  message(FATAL_ERROR "a circle between units (a source with its headers), each calling the other through "
    "the headers it includes; move what both sides need into a unit of its own (as cli/command_support.cpp "
    "holds what run and validate share):\n"
    "${_unit_circles}")
endif()
circles(_room_circles "${_room_names}" _rout_ _rwhy_)
if(NOT _room_circles STREQUAL "")
  message(FATAL_ERROR "a circle between rooms (top-level folders): a lower room includes a higher one:\n"
    "${_room_circles}")
endif()
list(LENGTH _units _nunits)
list(LENGTH _room_names _nrooms)
message(STATUS "include_graph: ${_nfiles} files, ${_nunits} units, ${_edges} calls between units, "
  "${_nrooms} rooms: no circle; the judges include nothing of the harness; their device part only core; "
  "the engines nothing of the judges")
