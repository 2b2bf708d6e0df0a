# A physics row is a unit (docs/architecture.md "Adding a validator row"): its line of
# validation/include/octocd/validation_rows.def, and its measure and table entry
# (PhysicsValidators::Impl::measure<RowId::ID>, or judge<RowId::ID> for a row that judges
# checked frames, and table<RowId::ID>) in its own file under
# validation/physics/. The physics tier's shared files, physics_impl.hpp (the sums, one Tally
# per cause of every row, and each row's clock) and physics_table.cpp (the calls of every
# row's measure and table entry), are made from the table: fails when either names a row
# (RowId::ID for an ID of the table) outside a comment, and when a physics row of the table
# has no measure or no table entry under validation/physics/ (the linker names a missing
# one too; this says which file is expected). The IDs are read from the table, so a new row
# is covered without an edit here.
# Run: cmake -DSRC=<source dir> -P tests/house/physics_rows.cmake
cmake_minimum_required(VERSION 3.16)
if(NOT SRC)
  message(FATAL_ERROR "physics_rows.cmake: pass -DSRC=<the source directory>")
endif()
set(_table ${SRC}/validation/include/octocd/validation_rows.def)
file(STRINGS ${_table} _rows REGEX "^OCTOCD_ROW\\(")
set(_ids "")
set(_physics "")
foreach(_row IN LISTS _rows)
  if(NOT _row MATCHES "^OCTOCD_ROW\\(([A-Za-z0-9_]+), *\"[a-z0-9-]+\", *([A-Za-z]+),")
    message(FATAL_ERROR "physics_rows.cmake: a row of ${_table} without ID, name and tier: ${_row}")
  endif()
  list(APPEND _ids "${CMAKE_MATCH_1}")
  if(CMAKE_MATCH_2 STREQUAL "Physics")
    list(APPEND _physics "${CMAKE_MATCH_1}")
  endif()
endforeach()
list(LENGTH _ids _count)
list(LENGTH _physics _physics_count)
if(_count LESS 10 OR _physics_count LESS 5)
  message(FATAL_ERROR "physics_rows.cmake: ${_count} rows (${_physics_count} physics) read from ${_table}; "
    "expected the whole table")
endif()
list(JOIN _ids "|" _alternatives)

set(_hits "")
foreach(_rel validation/physics/physics_impl.hpp validation/physics/physics_table.cpp)
  if(NOT EXISTS ${SRC}/${_rel})
    message(FATAL_ERROR "physics_rows.cmake: ${SRC}/${_rel} not found")
  endif()
  file(STRINGS ${SRC}/${_rel} _lines REGEX "RowId::(${_alternatives})([^A-Za-z0-9_]|$)")
  foreach(_l IN LISTS _lines)
    string(STRIP "${_l}" _l)
    if(_l MATCHES "^(//|/\\*|\\*)")
      continue()
    endif()
    string(REGEX REPLACE "[ \t]//.*$" "" _code "${_l}")
    if(_code MATCHES "RowId::(${_alternatives})([^A-Za-z0-9_]|$)")
      string(APPEND _hits "  ${_rel}: ${_l}\n")
    endif()
  endforeach()
endforeach()
if(NOT _hits STREQUAL "")
  message(FATAL_ERROR "a row named in the physics tier's shared files; its tallies are its RowSums "
    "(Impl::tally(RowId, \"cause\")), its own state Impl::row_state<T>, its measure and table entry "
    "Impl::measure<RowId::ID> (or Impl::judge<RowId::ID>) and Impl::table<RowId::ID> in its own file under "
    "validation/physics/:\n${_hits}")
endif()

file(GLOB _files ${SRC}/validation/physics/*.cpp)
set(_missing "")
foreach(_id IN LISTS _physics)
  # Its measure: Impl::measure<RowId::ID> (FRAMES Every) or Impl::judge<RowId::ID> (FRAMES Checked).
  foreach(_what "(measure|judge)" table)
    set(_found 0)
    foreach(_f IN LISTS _files)
      file(STRINGS ${_f} _def REGEX "PhysicsValidators::Impl::${_what}<RowId::${_id}>\\(")
      if(_def)
        math(EXPR _found "${_found} + 1")
      endif()
    endforeach()
    if(NOT _found EQUAL 1)
      string(APPEND _missing "  ${_id}: ${_found} files define Impl::${_what}<RowId::${_id}> (expected 1)\n")
    endif()
  endforeach()
endforeach()
if(NOT _missing STREQUAL "")
  message(FATAL_ERROR "a physics row of ${_table} without its own measure or table entry under "
    "validation/physics/:\n${_missing}")
endif()
message(STATUS "physics_rows: ${_physics_count} physics rows of ${_count}, each with its measure and table entry; "
  "physics_impl.hpp and physics_table.cpp name no row")
