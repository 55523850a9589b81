# The Python module `vmap` (python/vmap_py.cpp, pybind11 + numpy from Debian: python3-pybind11,
# python3-numpy, python3-dev). Built into build/python/vmap/ when the interpreter, its headers and
# pybind11 are found; scripts/main.sh puts that folder on the Debian python3's path.
option(VMAP_PYTHON "Build the Python module when Python 3 and pybind11 are found" ON)
if(NOT VMAP_PYTHON)
  return()
endif()
# Debian's interpreter first (a pyenv or venv python3 on PATH may lack numpy or headers).
if(NOT DEFINED Python3_EXECUTABLE AND EXISTS /usr/bin/python3)
  set(Python3_EXECUTABLE /usr/bin/python3)
endif()
find_package(Python3 COMPONENTS Interpreter Development.Module)
if(Python3_FOUND)
  set(PYBIND11_FINDPYTHON ON)
  find_package(pybind11 CONFIG QUIET)
endif()
if(NOT Python3_FOUND OR NOT pybind11_FOUND)
  message(STATUS "vmap: Python 3 headers or pybind11 not found, no Python module "
                 "(scripts/setup.sh installs python3-dev python3-pybind11 python3-numpy)")
  set(VMAP_HAVE_PYTHON OFF)
  return()
endif()
set(VMAP_HAVE_PYTHON ON)
set(VMAP_PYTHON_DIR ${CMAKE_BINARY_DIR}/python)
pybind11_add_module(vmap_python python/vmap_py.cpp)
set_target_properties(vmap_python PROPERTIES OUTPUT_NAME _vmap
                      LIBRARY_OUTPUT_DIRECTORY ${VMAP_PYTHON_DIR}/vmap)
target_link_libraries(vmap_python PRIVATE vmap_core)
vmap_bit_identical(vmap_python)
target_include_directories(vmap_python PRIVATE src)
configure_file(python/vmap/__init__.py ${VMAP_PYTHON_DIR}/vmap/__init__.py COPYONLY)
message(STATUS "vmap: Python module for ${Python3_EXECUTABLE} (${Python3_VERSION}) in "
               "${VMAP_PYTHON_DIR}")

# The pytest suite (python/tests), when pytest is there (python3-pytest).
if(VMAP_TESTS)
  execute_process(COMMAND ${Python3_EXECUTABLE} -c "import pytest, numpy"
                  RESULT_VARIABLE vmap_no_pytest OUTPUT_QUIET ERROR_QUIET)
  if(vmap_no_pytest)
    message(STATUS "vmap: pytest or numpy missing for ${Python3_EXECUTABLE}: no Python tests")
  else()
    add_test(NAME Python.Pytest
             COMMAND ${Python3_EXECUTABLE} -m pytest -q -p no:cacheprovider
                     ${CMAKE_SOURCE_DIR}/python/tests)
    set_tests_properties(Python.Pytest PROPERTIES LABELS cpu ENVIRONMENT
                         "PYTHONPATH=${VMAP_PYTHON_DIR};VMAP_BIN=$<TARGET_FILE:vmap>")
  endif()
endif()

# Installed where Debian's python3 looks for packages under a prefix (/usr/local/lib/python3.11/
# dist-packages for the default prefix); the module finds the scenes at <prefix>/share/vmap.
set(VMAP_PYTHON_INSTALL_DIR
    lib/python${Python3_VERSION_MAJOR}.${Python3_VERSION_MINOR}/dist-packages/vmap)
install(TARGETS vmap_python LIBRARY DESTINATION ${VMAP_PYTHON_INSTALL_DIR})
install(FILES python/vmap/__init__.py DESTINATION ${VMAP_PYTHON_INSTALL_DIR})
file(WRITE ${VMAP_PYTHON_DIR}/interpreter "${Python3_EXECUTABLE}")
