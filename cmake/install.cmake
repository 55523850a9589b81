# `cmake --install`: the vmap binary, the libraries, the public headers, the scenes and the
# models they name (share/vmap), and a CMake package: find_package(vmap [COMPONENTS validate]).
include(GNUInstallDirs)
include(CMakePackageConfigHelpers)

set(VMAP_CMAKE_DIR ${CMAKE_INSTALL_LIBDIR}/cmake/vmap)
install(TARGETS vmap RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
install(TARGETS vmap_core EXPORT vmapTargets ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR})
install(TARGETS vmap_validate EXPORT vmapValidateTargets
        ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR})
install(DIRECTORY include/vmap DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
install(DIRECTORY scenes DESTINATION ${CMAKE_INSTALL_DATADIR}/vmap)
# The viewer's page (`vmap view`), with three.js when scripts/fetch-web.sh has vendored it.
install(DIRECTORY web DESTINATION ${CMAKE_INSTALL_DATADIR}/vmap)
# The meshes are fetched at set-up time (scripts/fetch-models.sh), not part of the source; a
# tree without them installs the scenes alone.
install(DIRECTORY ${CMAKE_SOURCE_DIR}/models/ DESTINATION ${CMAKE_INSTALL_DATADIR}/vmap/models
        OPTIONAL FILES_MATCHING PATTERN "*.off" PATTERN "*.ply")

install(EXPORT vmapTargets NAMESPACE vmap:: FILE vmapTargets.cmake DESTINATION ${VMAP_CMAKE_DIR})
install(EXPORT vmapValidateTargets NAMESPACE vmap:: FILE vmapValidateTargets.cmake
        DESTINATION ${VMAP_CMAKE_DIR})
configure_package_config_file(cmake/vmapConfig.cmake.in
                              ${CMAKE_BINARY_DIR}/generated/vmapConfig.cmake
                              INSTALL_DESTINATION ${VMAP_CMAKE_DIR})
write_basic_package_version_file(${CMAKE_BINARY_DIR}/generated/vmapConfigVersion.cmake
                                 COMPATIBILITY SameMinorVersion)
install(FILES ${CMAKE_BINARY_DIR}/generated/vmapConfig.cmake
              ${CMAKE_BINARY_DIR}/generated/vmapConfigVersion.cmake
              ${CMAKE_SOURCE_DIR}/cmake/Findstreamvbyte.cmake
        DESTINATION ${VMAP_CMAKE_DIR})
