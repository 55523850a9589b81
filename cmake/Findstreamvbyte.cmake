# Finds StreamVByte (Debian: libstreamvbyte-dev), the integer codec of the .vmap file's link
# lists, and defines the imported target streamvbyte::streamvbyte. The static archive is
# preferred, so the vmap binary and the GPU machine's bundle need no extra shared library.
find_path(streamvbyte_INCLUDE_DIR streamvbytedelta.h)
find_library(streamvbyte_LIBRARY NAMES libstreamvbyte.a streamvbyte)
include(FindPackageHandleStandardArgs)
find_package_handle_standard_args(streamvbyte REQUIRED_VARS streamvbyte_LIBRARY
                                  streamvbyte_INCLUDE_DIR)
if(streamvbyte_FOUND AND NOT TARGET streamvbyte::streamvbyte)
  add_library(streamvbyte::streamvbyte UNKNOWN IMPORTED)
  set_target_properties(streamvbyte::streamvbyte PROPERTIES
                        IMPORTED_LOCATION ${streamvbyte_LIBRARY}
                        INTERFACE_INCLUDE_DIRECTORIES ${streamvbyte_INCLUDE_DIR})
endif()
mark_as_advanced(streamvbyte_INCLUDE_DIR streamvbyte_LIBRARY)
