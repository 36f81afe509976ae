# write_if_changed(PATH TEXT): writes TEXT to PATH unless PATH already holds it, so that
# files generated at every build keep their time stamp (and what depends on them is not
# rebuilt) while they do not change. For the build's -P scripts (version.cmake,
# client/python/build_info.cmake).
function(write_if_changed path text)
  set(old "")
  if(EXISTS "${path}")
    file(READ "${path}" old)
  endif()
  if(NOT old STREQUAL text)
    file(WRITE "${path}" "${text}")
  endif()
endfunction()
