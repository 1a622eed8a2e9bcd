# Install rules (included from the top CMakeLists.txt when TETRIG_INSTALL is on; docs/embedding.md):
#   <prefix>/include/                      tetrig/*.hpp, tetrig/drivers/*.hpp, tetrig/version.h, tetrig_shm.h, tetrig.h
#   <prefix>/lib/                          libtetrig_runtime, libtetrig_drivers (+ libtetrig_devices): static by
#                                          default, shared with BUILD_SHARED_LIBS=ON; libtetrig.so (the C API, always shared)
#   <prefix>/lib/cmake/tetrig/             tetrigConfig.cmake, tetrigConfigVersion.cmake, tetrigTargets*.cmake:
#                                          find_package(tetrig CONFIG) -> tetrig::runtime, tetrig::drivers,
#                                          tetrig::devices (when built), tetrig::c
#   <prefix>/lib/pkgconfig/                tetrig.pc (the C API), tetrig-runtime.pc, tetrig-drivers.pc (+ tetrig-devices.pc)
#   <prefix>/bin/                          tetrig, tetrig-shm-cat (when the tools are built)
include(CMakePackageConfigHelpers)

set(TETRIG_INSTALL_CMAKEDIR ${CMAKE_INSTALL_LIBDIR}/cmake/tetrig)

# --- headers: the runtime's and the drivers' public folders, the generated version header, the C API ---
install(DIRECTORY ${PROJECT_SOURCE_DIR}/runtime/include/ DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}
        FILES_MATCHING PATTERN "*.hpp" PATTERN "*.h")
install(DIRECTORY ${PROJECT_SOURCE_DIR}/drivers/include/ DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}
        FILES_MATCHING PATTERN "*.hpp" PATTERN "*.h")
install(FILES ${TETRIG_GENERATED_INCLUDE_DIR}/tetrig/version.h DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/tetrig)
install(FILES ${PROJECT_SOURCE_DIR}/capi/include/tetrig.h DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})

# --- libraries and their exported targets (namespace tetrig::, names from EXPORT_NAME) ---
set(tetrig_installed_targets tetrig_runtime tetrig_drivers tetrig_c)
if(TARGET tetrig_devices)
  list(APPEND tetrig_installed_targets tetrig_devices)
  set(TETRIG_PACKAGE_HAS_DEVICES ON)
else()
  set(TETRIG_PACKAGE_HAS_DEVICES OFF)
endif()
# Shared libraries find each other in their own folder (libtetrig.so -> libtetrig_runtime.so with
# BUILD_SHARED_LIBS=ON), wherever the prefix is.
set_target_properties(${tetrig_installed_targets} PROPERTIES INSTALL_RPATH "$ORIGIN")
install(TARGETS ${tetrig_installed_targets} EXPORT tetrigTargets
        ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
        LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR}
        RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR}
        INCLUDES DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
install(EXPORT tetrigTargets NAMESPACE tetrig:: DESTINATION ${TETRIG_INSTALL_CMAKEDIR})
if(TARGET tetrig AND TARGET tetrig-shm-cat)
  install(TARGETS tetrig tetrig-shm-cat RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
endif()

# --- the CMake package: config (dependencies: Eigen, Threads; libusb and hidapi for the devices) and version ---
configure_package_config_file(${PROJECT_SOURCE_DIR}/cmake/tetrigConfig.cmake.in ${PROJECT_BINARY_DIR}/tetrigConfig.cmake
                              INSTALL_DESTINATION ${TETRIG_INSTALL_CMAKEDIR})
# 0.x: a minor version may break the API, so only the same MAJOR.MINOR is compatible.
write_basic_package_version_file(${PROJECT_BINARY_DIR}/tetrigConfigVersion.cmake VERSION ${PROJECT_VERSION}
                                 COMPATIBILITY SameMinorVersion)
install(FILES ${PROJECT_BINARY_DIR}/tetrigConfig.cmake ${PROJECT_BINARY_DIR}/tetrigConfigVersion.cmake
        DESTINATION ${TETRIG_INSTALL_CMAKEDIR})

# --- pkg-config files (version from project(VERSION)). Relocatable: the prefix is found from the .pc
# file's own folder (${pcfiledir}), so a tree installed with `cmake --install --prefix DIR` works. ---
file(RELATIVE_PATH TETRIG_PC_PREFIX_FROM_PCDIR /prefix/${CMAKE_INSTALL_LIBDIR}/pkgconfig /prefix)
if(BUILD_SHARED_LIBS)
  set(TETRIG_PC_LIBS_PRIVATE "")  # shared libraries carry their own dependencies
else()
  set(TETRIG_PC_LIBS_PRIVATE "-pthread")  # static archives: what the runtime needs from the system
endif()
foreach(pc tetrig tetrig-runtime tetrig-drivers)
  configure_file(${PROJECT_SOURCE_DIR}/cmake/${pc}.pc.in ${PROJECT_BINARY_DIR}/pkgconfig/${pc}.pc @ONLY)
  install(FILES ${PROJECT_BINARY_DIR}/pkgconfig/${pc}.pc DESTINATION ${CMAKE_INSTALL_LIBDIR}/pkgconfig)
endforeach()
if(TETRIG_PACKAGE_HAS_DEVICES)
  configure_file(${PROJECT_SOURCE_DIR}/cmake/tetrig-devices.pc.in ${PROJECT_BINARY_DIR}/pkgconfig/tetrig-devices.pc @ONLY)
  install(FILES ${PROJECT_BINARY_DIR}/pkgconfig/tetrig-devices.pc DESTINATION ${CMAKE_INSTALL_LIBDIR}/pkgconfig)
endif()
