# facecap_module_headers(<target> <module folder> [FILES <file>...])
#
# Makes "<module folder>/<header>" includable by <target> and by the targets that link it,
# and by no other: the module's source folder (or only the FILES named) is linked into an
# include root of the target's own in the build tree, which the target publishes. So a
# module can only include the modules it links, and the link graph is the module graph of
# docs/architecture.md (tests/check_module_includes.cmake checks the same rule on the
# sources themselves).
function(facecap_module_headers target module)
  cmake_parse_arguments(M "" "" "FILES" ${ARGN})
  set(root "${PROJECT_BINARY_DIR}/include/${target}")
  if(M_FILES)
    file(MAKE_DIRECTORY "${root}/${module}")
    foreach(f IN LISTS M_FILES)
      file(CREATE_LINK "${PROJECT_SOURCE_DIR}/${module}/${f}" "${root}/${module}/${f}" SYMBOLIC)
    endforeach()
  else()
    get_filename_component(parent "${root}/${module}" DIRECTORY)
    file(MAKE_DIRECTORY "${parent}")
    file(CREATE_LINK "${PROJECT_SOURCE_DIR}/${module}" "${root}/${module}" SYMBOLIC)
  endif()
  get_target_property(type ${target} TYPE)
  if(type STREQUAL "INTERFACE_LIBRARY")
    target_include_directories(${target} INTERFACE "$<BUILD_INTERFACE:${root}>")
  else()
    target_include_directories(${target} PUBLIC "$<BUILD_INTERFACE:${root}>")
  endif()
endfunction()
