# Writes OUT (tessera/_build.py): the commit this tree was built from, read from the
# header core/util/version.cmake writes (VERSION_HEADER), and the protocol version the
# coordinator speaks and the longest job name it takes, read from proto/wire.h (WIRE_H). Rewritten only when it changes.
include("${CMAKE_CURRENT_LIST_DIR}/../../core/util/write_if_changed.cmake")
file(STRINGS "${VERSION_HEADER}" vline REGEX "TESSERA_GIT_VERSION")
string(REGEX REPLACE ".*TESSERA_GIT_VERSION \"([^\"]*)\".*" "\\1" v "${vline}")
file(STRINGS "${WIRE_H}" pline REGEX "kProtocolVersion = ")
string(REGEX REPLACE ".*kProtocolVersion = ([0-9]+).*" "\\1" p "${pline}")
if(NOT p MATCHES "^[0-9]+$")
  message(FATAL_ERROR "no kProtocolVersion in ${WIRE_H}")
endif()
file(STRINGS "${WIRE_H}" nline REGEX "kMaxJobNameBytes = ")
string(REGEX REPLACE ".*kMaxJobNameBytes = ([0-9]+).*" "\\1" n "${nline}")
if(NOT n MATCHES "^[0-9]+$")
  message(FATAL_ERROR "no kMaxJobNameBytes in ${WIRE_H}")
endif()
set(text "# Written by the build (client/python/build_info.cmake).\nVERSION = \"${v}\"\nPROTOCOL_VERSION = ${p}\nMAX_JOB_NAME_BYTES = ${n}\n")
write_if_changed("${OUT}" "${text}")
