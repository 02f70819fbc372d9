# Checks that every module includes only from the modules below it in the module graph of
# docs/architecture.md (the graph the CMake link interfaces form). Run as
#   cmake -DSOURCE_DIR=<tree> -P cmake/check_module_includes.cmake
# Prints each violation as file:line and fails; a test plants one to prove that it would.
#
# Each row: a module (a folder, or a single header that is a module of its own) and the
# modules its sources may include besides itself. The longest matching path wins, so
# drivers/api is not drivers. tools/, tests/, bench/ and fuzz/ may include anything.
cmake_minimum_required(VERSION 3.25)
set(modules
  "core|"
  "client|client/facecap_udp_layout.hpp"
  "client/facecap_udp_layout.hpp|"
  "formats|core"
  "solver/params.hpp|core"
  "solver|solver/params.hpp,core"
  "drivers/api|core"
  "drivers/capture|formats,core"
  "drivers/replay|drivers/api,drivers/capture,formats,core"
  "drivers/sim|drivers/api,solver,solver/params.hpp,formats,core"
  "drivers/natnet|drivers/api,formats,core"
  "drivers/device|drivers/api,formats,core"
  "drivers/usb|drivers/device,drivers/api,formats,core"
  "drivers/hid|drivers/device,drivers/api,formats,core"
  "drivers/v4l2|drivers/api,formats,core"
  "drivers|drivers/api,drivers/sim,drivers/replay,drivers/natnet,drivers/device,drivers/usb,drivers/hid,drivers/v4l2,solver,solver/params.hpp,formats,core"
  "config|drivers/api,solver/params.hpp,client,core"
  "pipeline|config,solver,solver/params.hpp,formats,drivers/api,core"
  "outputs/api|formats,core"
  "outputs/shm|outputs/api,client,formats,core"
  "outputs/recording|outputs/api,formats,core"
  "drivers/natnet|drivers/api,formats,core"
  "outputs/net|outputs/api,formats,core"
  "outputs/udp|outputs/net,outputs/api,formats,client/facecap_udp_layout.hpp,core"
  "outputs/vmc|outputs/net,outputs/api,formats,core"
  "outputs/livelink|outputs/net,outputs/api,formats,core"
  "outputs|outputs/api,outputs/shm,outputs/recording,outputs/net,outputs/udp,outputs/vmc,outputs/livelink,config,drivers/api,solver/params.hpp,client,formats,core"
  "control|outputs/api,formats,core"
  "daemon|control,pipeline,outputs,outputs/api,outputs/shm,outputs/recording,outputs/net,outputs/udp,outputs/vmc,outputs/livelink,drivers,drivers/api,drivers/sim,drivers/replay,drivers/natnet,drivers/device,drivers/usb,drivers/hid,drivers/v4l2,config,solver,solver/params.hpp,formats,client,core"
)

if(NOT SOURCE_DIR)
  message(FATAL_ERROR "usage: cmake -DSOURCE_DIR=<source tree> -P check_module_includes.cmake")
endif()

# The module a path belongs to (the longest row that prefixes it), or "" when unrestricted.
function(module_of path out)
  set(best "")
  foreach(row IN LISTS modules)
    string(REPLACE "|" ";" parts "${row}")
    list(GET parts 0 name)
    string(LENGTH "${name}" length)
    string(FIND "${path}" "${name}/" position)
    if(position EQUAL 0 OR path STREQUAL name)
      string(LENGTH "${best}" best_length)
      if(length GREATER best_length)
        set(best "${name}")
      endif()
    endif()
  endforeach()
  set(${out} "${best}" PARENT_SCOPE)
endfunction()

function(allowed_of module out)
  foreach(row IN LISTS modules)
    string(REPLACE "|" ";" parts "${row}")
    list(GET parts 0 name)
    if(name STREQUAL module)
      list(LENGTH parts n)
      set(deps "")
      if(n GREATER 1)
        list(GET parts 1 deps)
        string(REPLACE "," ";" deps "${deps}")
      endif()
      set(${out} "${deps}" PARENT_SCOPE)
      return()
    endif()
  endforeach()
endfunction()

file(GLOB_RECURSE sources RELATIVE "${SOURCE_DIR}"
  "${SOURCE_DIR}/*.hpp" "${SOURCE_DIR}/*.cpp" "${SOURCE_DIR}/*.h" "${SOURCE_DIR}/*.c")
set(violations 0)
set(checked 0)
foreach(file IN LISTS sources)
  if(file MATCHES "^(build|\\.)" OR file MATCHES "/build[^/]*/")
    continue()
  endif()
  module_of("${file}" module)
  if(module STREQUAL "")
    continue()
  endif()
  allowed_of("${module}" allowed)
  math(EXPR checked "${checked} + 1")
  file(STRINGS "${SOURCE_DIR}/${file}" lines)
  set(line_no 0)
  foreach(line IN LISTS lines)
    math(EXPR line_no "${line_no} + 1")
    if(line MATCHES "^[ \t]*#[ \t]*include[ \t]*\"([^\"]+)\"")
      set(included "${CMAKE_MATCH_1}")
      module_of("${included}" target)
      if(target STREQUAL "" OR target STREQUAL module)
        continue()
      endif()
      list(FIND allowed "${target}" found)
      if(found EQUAL -1)
        message("${file}:${line_no}: ${module} includes ${target} (\"${included}\"), which is not below it; "
                "${module} may include: ${allowed}")
        math(EXPR violations "${violations} + 1")
      endif()
    endif()
  endforeach()
endforeach()
if(violations GREATER 0)
  message(FATAL_ERROR "${violations} include(s) against the module graph (docs/architecture.md)")
endif()
message("module includes: ${checked} files checked, none against the module graph")
