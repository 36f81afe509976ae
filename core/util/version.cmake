# Writes OUT, a header naming the commit this tree was built from (git describe, "-dirty"
# with uncommitted changes; "unknown" outside a git checkout), rewritten only when it
# changes so that a build after a commit recompiles one file. Run at every build by the
# tessera_version_header target (core/CMakeLists.txt).
include("${CMAKE_CURRENT_LIST_DIR}/write_if_changed.cmake")
execute_process(COMMAND git -C "${SOURCE_DIR}" describe --always --dirty --abbrev=12
                OUTPUT_VARIABLE v OUTPUT_STRIP_TRAILING_WHITESPACE ERROR_QUIET RESULT_VARIABLE rc)
if(NOT rc EQUAL 0 OR v STREQUAL "")
  set(v "unknown")
endif()
set(text "#pragma once\n#define TESSERA_GIT_VERSION \"${v}\"\n")
write_if_changed("${OUT}" "${text}")
