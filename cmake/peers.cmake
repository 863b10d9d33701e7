# Side-by-side benchmarks against the systems a user would pick instead, built
# from their unmodified public source in ../shared/peers (its SOURCE.md says
# what is there and how it builds). Nothing of theirs is copied into this
# repository, installed, or built by the nodelets: each program switches
# itself off at configure time, with a message, where the folder or a library
# it needs is missing (as on a user's machine).
#
#   kiss_icp_comparison_benchmark (benchmark/kiss_icp_comparison.cpp): KISS-ICP
#     1.2.3 and our odometry on the same scans, threads and run.
#   vdbfusion_comparison_benchmark (benchmark/vdbfusion_comparison.cpp):
#     VDBFusion 0.1.6 and our TSDF mapping on the same scans and run.
#
# Sophus (header-only, no Debian package) is configured and installed into
# <build>/peers/sophus at configure time; KISS-ICP's C++ library is added as a
# subdirectory built in <build>/peers/kiss_icp with downloads off. Core-only
# builds build the program with `all`; catkin builds only on request
# (catkin_make kiss_icp_comparison_benchmark), so that catkin_make does not
# compile a peer nobody asked for. VDBFusion's C++ library is added the same
# way (built in <build>/peers/vdbfusion) on Debian's OpenVDB (libopenvdb-dev,
# a benchmark-only dependency); its own fallback, which downloads and builds
# OpenVDB, is never reached.

set(RIM_PEERS_DIR "${RIM_REPOSITORY_DIR}/../shared/peers" CACHE PATH
    "Unmodified peer source for the side-by-side benchmarks (KISS-ICP, Sophus, VDBFusion)")

function(rim_add_kiss_icp_comparison)
  set(name kiss_icp_comparison_benchmark)
  get_filename_component(peers "${RIM_PEERS_DIR}" ABSOLUTE)
  set(kiss_icp_source "${peers}/kiss-icp/cpp/kiss_icp")
  set(sophus_source "${peers}/Sophus")
  if(NOT EXISTS "${kiss_icp_source}/CMakeLists.txt" OR NOT EXISTS "${sophus_source}/CMakeLists.txt")
    message(STATUS "${name} switched off: no KISS-ICP and Sophus source in ${peers} (see its SOURCE.md)")
    return()
  endif()
  if(RIM_FUZZ)
    message(STATUS "${name} switched off: not in a fuzzer build")
    return()
  endif()

  # What KISS-ICP 1.2.3 needs, checked here so that its own fallbacks (which
  # download) are never reached.
  set(missing "")
  if(CMAKE_VERSION VERSION_LESS 3.24)
    list(APPEND missing "CMake >= 3.24 (Sophus 1.24)")
  endif()
  if(Eigen3_VERSION VERSION_LESS 3.4)
    list(APPEND missing "Eigen >= 3.4")
  endif()
  if(NOT TBB_VERSION OR TBB_VERSION VERSION_LESS 2021)
    list(APPEND missing "oneTBB >= 2021 (libtbb-dev)")
  endif()
  find_package(tsl-robin-map QUIET NO_MODULE)
  if(NOT TARGET tsl::robin_map)
    list(APPEND missing "robin-map (robin-map-dev)")
  endif()
  if(missing)
    string(REPLACE ";" ", " missing "${missing}")
    message(STATUS "${name} switched off: needs ${missing}")
    return()
  endif()

  # Sophus into a prefix of ours (never into the read-only peers folder).
  set(sophus_build "${CMAKE_BINARY_DIR}/peers/sophus-build")
  set(sophus_prefix "${CMAKE_BINARY_DIR}/peers/sophus")
  if(NOT EXISTS "${sophus_prefix}/share/sophus/cmake/SophusConfig.cmake")
    execute_process(
      COMMAND ${CMAKE_COMMAND} -S "${sophus_source}" -B "${sophus_build}" -G "${CMAKE_GENERATOR}"
        -DCMAKE_INSTALL_PREFIX=${sophus_prefix} -DCMAKE_BUILD_TYPE=Release -DEigen3_DIR=${Eigen3_DIR}
        -DBUILD_SOPHUS_TESTS=OFF -DBUILD_SOPHUS_EXAMPLES=OFF -DBUILD_PYTHON_BINDINGS=OFF
        -DSOPHUS_USE_BASIC_LOGGING=ON -DSOPHUS_INSTALL=ON
      RESULT_VARIABLE result OUTPUT_VARIABLE output ERROR_VARIABLE output)
    if(result EQUAL 0)
      execute_process(COMMAND ${CMAKE_COMMAND} --install "${sophus_build}"
        RESULT_VARIABLE result OUTPUT_VARIABLE output ERROR_VARIABLE output)
    endif()
    if(NOT result EQUAL 0)
      message(STATUS "${name} switched off: Sophus from ${sophus_source} did not install into "
        "${sophus_prefix}:\n${output}")
      return()
    endif()
  endif()

  # KISS-ICP as it is, with our Eigen, TBB and robin-map and that Sophus.
  # Set in this function's scope only: the rest of the project never sees them.
  list(PREPEND CMAKE_PREFIX_PATH "${sophus_prefix}")
  set(FETCHCONTENT_FULLY_DISCONNECTED ON)
  set(USE_CCACHE OFF)  # it would set a global compiler launcher for the whole project
  set(USE_SYSTEM_EIGEN3 ON)
  set(USE_SYSTEM_SOPHUS ON)
  set(USE_SYSTEM_TSL-ROBIN-MAP ON)
  set(USE_SYSTEM_TBB ON)
  find_package(Sophus QUIET NO_MODULE)
  if(NOT TARGET Sophus::Sophus)
    message(STATUS "${name} switched off: Sophus installed into ${sophus_prefix} is not found there")
    return()
  endif()
  add_subdirectory("${kiss_icp_source}" "${CMAKE_BINARY_DIR}/peers/kiss_icp" EXCLUDE_FROM_ALL)

  add_executable(${name} benchmark/kiss_icp_comparison.cpp test/test_data.cpp)
  target_link_libraries(${name} PRIVATE range_image_mapping_all kiss_icp_pipeline)
  target_include_directories(${name} PRIVATE test benchmark)
  target_compile_definitions(${name} PRIVATE RIM_DEFAULT_DATA_DIR="${RIM_DEFAULT_DATA_DIR}"
    RIM_TOOL_PATH="$<TARGET_FILE:rim>" RIM_PEERS_DIR="${peers}"
    RIM_DEFAULT_WORK_DIR="${CMAKE_BINARY_DIR}/kiss_icp_comparison" RIM_SOURCE_DIR="${RIM_REPOSITORY_DIR}")
  target_compile_options(${name} PRIVATE -Wall -Wextra)
  set_target_properties(${name} PROPERTIES RUNTIME_OUTPUT_DIRECTORY ${RIM_BIN_DIR})
  add_dependencies(${name} rim)  # it simulates the presets with rim simulate
  if(NOT RIM_CORE_ONLY)
    set_target_properties(${name} PROPERTIES EXCLUDE_FROM_ALL ON)
  endif()
  message(STATUS "${name}: KISS-ICP from ${kiss_icp_source}, Sophus installed into ${sophus_prefix}")
endfunction()

function(rim_add_vdbfusion_comparison)
  set(name vdbfusion_comparison_benchmark)
  get_filename_component(peers "${RIM_PEERS_DIR}" ABSOLUTE)
  # The library folder alone: the top-level project would look for OpenVDB
  # in its own way and download it where it is not found.
  set(vdbfusion_source "${peers}/vdbfusion/src/vdbfusion/vdbfusion")
  if(NOT EXISTS "${vdbfusion_source}/CMakeLists.txt")
    message(STATUS "${name} switched off: no VDBFusion source in ${peers} (see its SOURCE.md)")
    return()
  endif()
  if(RIM_FUZZ)
    message(STATUS "${name} switched off: not in a fuzzer build")
    return()
  endif()

  # Debian's OpenVDB ships its FindOpenVDB.cmake in a multiarch folder that
  # is not on CMake's module path. Set in this function's scope only.
  include(GNUInstallDirs)
  file(GLOB openvdb_module_dirs "${CMAKE_INSTALL_FULL_LIBDIR}/cmake/OpenVDB" "/usr/lib/*/cmake/OpenVDB"
    "/usr/local/lib/cmake/OpenVDB")
  list(PREPEND CMAKE_MODULE_PATH ${openvdb_module_dirs})
  find_package(OpenVDB QUIET)
  if(NOT TARGET OpenVDB::openvdb)
    message(STATUS "${name} switched off: needs OpenVDB (libopenvdb-dev)")
    return()
  endif()
  # Built and run only with Debian bookworm's 10.0 so far; bullseye has 7.1.
  # Older ones (Ubuntu 20.04's 6.2) are not tried: VDBFusion 0.1.6 uses newer
  # accessor calls (Grid::getUnsafeAccessor).
  if(OpenVDB_VERSION VERSION_LESS 7.1)
    message(STATUS "${name} switched off: needs OpenVDB >= 7.1, found ${OpenVDB_VERSION}")
    return()
  endif()

  add_subdirectory("${vdbfusion_source}" "${CMAKE_BINARY_DIR}/peers/vdbfusion" EXCLUDE_FROM_ALL)
  # Its sources are not ours: no warnings from them in our build logs.
  target_compile_options(vdbfusion PRIVATE -w)

  add_executable(${name} benchmark/vdbfusion_comparison.cpp test/test_data.cpp)
  target_link_libraries(${name} PRIVATE range_image_mapping_all VDBFusion::vdbfusion)
  target_include_directories(${name} PRIVATE test benchmark)
  target_compile_definitions(${name} PRIVATE RIM_DEFAULT_DATA_DIR="${RIM_DEFAULT_DATA_DIR}"
    RIM_PEERS_DIR="${peers}" RIM_SOURCE_DIR="${RIM_REPOSITORY_DIR}")
  target_compile_options(${name} PRIVATE -Wall -Wextra)
  set_target_properties(${name} PROPERTIES RUNTIME_OUTPUT_DIRECTORY ${RIM_BIN_DIR})
  if(NOT RIM_CORE_ONLY)
    set_target_properties(${name} PROPERTIES EXCLUDE_FROM_ALL ON)
  endif()
  message(STATUS "${name}: VDBFusion from ${vdbfusion_source}, OpenVDB ${OpenVDB_VERSION}")
endfunction()

if(RIM_BENCHMARKS)
  rim_add_kiss_icp_comparison()
  rim_add_vdbfusion_comparison()
endif()
