# Writes OUTPUT, a header that defines YOCTO_SOURCE_HASH: the first 16 hex
# digits of a SHA-256 over the renderer's sources (every file under libs/
# and apps/ of SOURCE_DIR, names and contents). Render parts record it, so
# that a merge refuses parts of different code. The file is rewritten only
# when the hash changes, so that nothing recompiles otherwise.
file(GLOB_RECURSE sources LIST_DIRECTORIES false
     "${SOURCE_DIR}/libs/*.h" "${SOURCE_DIR}/libs/*.cpp" "${SOURCE_DIR}/apps/*.h"
     "${SOURCE_DIR}/apps/*.cpp")
list(SORT sources)
set(listing "")
foreach(source ${sources})
  file(SHA256 "${source}" hash)
  file(RELATIVE_PATH name "${SOURCE_DIR}" "${source}")
  string(APPEND listing "${name} ${hash}\n")
endforeach()
string(SHA256 total "${listing}")
string(SUBSTRING "${total}" 0 16 total)
set(content "#define YOCTO_SOURCE_HASH \"${total}\"\n")
set(previous "")
if(EXISTS "${OUTPUT}")
  file(READ "${OUTPUT}" previous)
endif()
if(NOT previous STREQUAL content)
  file(WRITE "${OUTPUT}" "${content}")
endif()
