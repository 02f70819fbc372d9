# cmake -DNM=<nm> -DKERNELS="<path>=<object>;..." -P check_kernel_symbols.cmake
#
# The kernel objects (solver/kernels/kernels_<path>.cpp) are compiled for wider CPUs than
# the rest. An external symbol they define outside facecap::kernels::<path> (an inline
# function or template instantiated there, say std::min<float>) could be the copy the
# linker keeps for every caller, and would run AVX2 or AVX-512 instructions on a CPU
# without them. So each object may define nothing else; the exception-personality
# reference the compiler emits is data, not code.
set(failures "")
foreach(entry IN LISTS KERNELS)
  string(REGEX MATCH "^([a-z0-9]+)=(.+)$" parsed "${entry}")
  if(NOT parsed)
    message(FATAL_ERROR "check_kernel_symbols: bad entry '${entry}' (want <path>=<object>)")
  endif()
  set(path "${CMAKE_MATCH_1}")
  set(object "${CMAKE_MATCH_2}")
  string(LENGTH "${path}" length)
  execute_process(COMMAND ${NM} --defined-only --extern-only "${object}"
                  OUTPUT_VARIABLE listing ERROR_VARIABLE errors RESULT_VARIABLE status)
  if(NOT status EQUAL 0)
    message(FATAL_ERROR "check_kernel_symbols: ${NM} failed on ${object}: ${errors}")
  endif()
  string(REPLACE "\n" ";" lines "${listing}")
  set(own 0)
  foreach(line IN LISTS lines)
    if(NOT line MATCHES "^[0-9a-fA-F]* *([A-Za-z]) (.+)$")
      continue()
    endif()
    set(type "${CMAKE_MATCH_1}")
    set(symbol "${CMAKE_MATCH_2}")
    if(symbol MATCHES "^_ZN7facecap7kernels${length}${path}")
      math(EXPR own "${own} + 1")
    elseif(NOT symbol STREQUAL "DW.ref.__gxx_personality_v0")
      string(APPEND failures "  ${path}: ${symbol} (${type})\n")
    endif()
  endforeach()
  if(own EQUAL 0)
    string(APPEND failures "  ${path}: ${object} defines no facecap::kernels::${path} symbol (not a kernel object?)\n")
  endif()
endforeach()
if(failures)
  message(FATAL_ERROR "kernel objects define symbols outside their namespace, which the linker may share with "
                      "code built for a narrower CPU:\n${failures}")
endif()
list(LENGTH KERNELS count)
message(STATUS "${count} kernel object(s): every external symbol is in its own path's namespace")
