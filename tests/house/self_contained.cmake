# The project explains itself (docs/design.md): no source, script, scene, document or
# per-machine record (reports/<machine>/: its tables carry validators' figures) of the tree
# cites a file outside the repository (../shared/) or a numbered section of an outside
# specification ("SPEC 6"); citations name docs/design.md's sections.
# Run: cmake -DSRC=<source dir> -P tests/house/self_contained.cmake
if(NOT SRC)
  message(FATAL_ERROR "self_contained.cmake: pass -DSRC=<the source directory>")
endif()
set(hits "")
set(seen 0)
foreach(dir core gpu engines reference validation harness cli python bench report scripts tests docs datasets/scenes examples
    cmake fuzz reports)
  file(GLOB_RECURSE files ${SRC}/${dir}/*.cpp ${SRC}/${dir}/*.hpp ${SRC}/${dir}/*.cu ${SRC}/${dir}/*.cuh
    ${SRC}/${dir}/*.py ${SRC}/${dir}/*.sh ${SRC}/${dir}/*.md ${SRC}/${dir}/*.json ${SRC}/${dir}/*.cmake
    ${SRC}/${dir}/*.csv ${SRC}/${dir}/*.txt ${SRC}/${dir}/*.def ${SRC}/${dir}/CMakeLists.txt)
  foreach(f IN LISTS files)
    if(f MATCHES "/tests/house/self_contained.cmake$")
      continue()
    endif()
    math(EXPR seen "${seen} + 1")
    file(STRINGS ${f} lines REGEX "\\.\\./shared/|SPEC [0-9]")
    foreach(l IN LISTS lines)
      file(RELATIVE_PATH rel ${SRC} ${f})
      string(STRIP "${l}" l)
      string(APPEND hits "  ${rel}: ${l}\n")
    endforeach()
  endforeach()
endforeach()
foreach(f README.md CMakeLists.txt)
  file(STRINGS ${SRC}/${f} lines REGEX "\\.\\./shared/|SPEC [0-9]")
  foreach(l IN LISTS lines)
    string(APPEND hits "  ${f}: ${l}\n")
  endforeach()
endforeach()
if(seen EQUAL 0)
  message(FATAL_ERROR "self_contained.cmake: no file found under ${SRC}")
endif()
if(NOT hits STREQUAL "")
  message(FATAL_ERROR "a citation of a file outside the repository; cite docs/design.md (design.md section N):\n${hits}")
endif()
message(STATUS "self_contained: ${seen} files, every citation inside the repository")
