# Every external dependency of lfnet is found here, and only here.
#
# The numerical core (core, optics, nn, recon) needs LibTorch and header-only nlohmann_json
# alone, so it builds on any machine that has LibTorch (a CUDA one included). OpenImageIO,
# CLI11, spdlog and libdeflate (the PNG encoder's compressor, io/png.h) are needed only by the
# I/O library and the program (LFNET_BUILD_APPS).
# OpenCV (its core and photo modules) is linked by the cv area alone (lfnet/cv/opencv.h:
# OpenCV's non-local means for pinv-nlm), which the program links; the core never does.

find_package(Torch REQUIRED)
find_package(Threads REQUIRED)

find_package(nlohmann_json 3 QUIET)
if(NOT nlohmann_json_FOUND)
  find_path(LFNET_NLOHMANN_INCLUDE nlohmann/json.hpp REQUIRED)
  add_library(nlohmann_json::nlohmann_json INTERFACE IMPORTED)
  target_include_directories(nlohmann_json::nlohmann_json INTERFACE ${LFNET_NLOHMANN_INCLUDE})
endif()

# zlib, optional: with it, core/zip_check.h also verifies the compressed entries of LibTorch
# archives (TorchScript code) before LibTorch reads them. Debian: zlib1g-dev.
find_package(ZLIB QUIET)

# LibTorch's imported target carries its flags in TORCH_CXX_FLAGS; wrap it once.
if(NOT TARGET lfnet_torch)
  add_library(lfnet_torch INTERFACE)
  target_link_libraries(lfnet_torch INTERFACE ${TORCH_LIBRARIES})
  separate_arguments(_lfnet_torch_flags UNIX_COMMAND "${TORCH_CXX_FLAGS}")
  target_compile_options(lfnet_torch INTERFACE ${_lfnet_torch_flags})
endif()

if(LFNET_BUILD_APPS)
  find_package(OpenImageIO REQUIRED)
  find_package(spdlog REQUIRED)
  find_package(CLI11 REQUIRED)
  # libdeflate 1.14 (Debian: libdeflate-dev) installs no CMake package file.
  find_path(LFNET_LIBDEFLATE_INCLUDE libdeflate.h REQUIRED)
  find_library(LFNET_LIBDEFLATE_LIBRARY deflate REQUIRED)
  if(NOT TARGET lfnet_libdeflate)
    add_library(lfnet_libdeflate INTERFACE)
    target_include_directories(lfnet_libdeflate INTERFACE ${LFNET_LIBDEFLATE_INCLUDE})
    target_link_libraries(lfnet_libdeflate INTERFACE ${LFNET_LIBDEFLATE_LIBRARY})
  endif()
  find_package(OpenCV REQUIRED COMPONENTS core photo imgproc)  # imgproc: tests' reference demosaic
endif()

if(LFNET_BUILD_TESTS)
  find_package(Catch2 2 REQUIRED)
  find_package(Python3 COMPONENTS Interpreter)
endif()
