# house_scan(OUT_HITS OUT_COUNT REGEX DIR...): the lines of the C++ and CUDA sources under
# ${SRC}/DIR (recursively) that match REGEX, as "  relative/path: line\n" entries in
# OUT_HITS, and the number of files read in OUT_COUNT. Shared by the house checks
# (engine_names.cmake, plain_step.cmake).
function(house_scan out_hits out_count regex)
  set(hits "")
  set(seen 0)
  foreach(dir IN LISTS ARGN)
    file(GLOB_RECURSE files ${SRC}/${dir}/*.cpp ${SRC}/${dir}/*.hpp ${SRC}/${dir}/*.h ${SRC}/${dir}/*.cu
      ${SRC}/${dir}/*.cuh)
    foreach(f IN LISTS files)
      math(EXPR seen "${seen} + 1")
      file(STRINGS ${f} lines REGEX "${regex}")
      foreach(l IN LISTS lines)
        file(RELATIVE_PATH rel ${SRC} ${f})
        string(STRIP "${l}" l)
        string(APPEND hits "  ${rel}: ${l}\n")
      endforeach()
    endforeach()
  endforeach()
  set(${out_hits} "${hits}" PARENT_SCOPE)
  set(${out_count} ${seen} PARENT_SCOPE)
endfunction()
