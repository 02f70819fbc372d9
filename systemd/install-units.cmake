# Run by `cmake --install` (systemd/CMakeLists.txt sets the FACECAP_* directories): fills
# the units' paths in from the prefix of this install, CMAKE_INSTALL_PREFIX here, so the
# installed unit runs the facecapd installed beside it with the configuration installed
# beside it. A relative directory is under the prefix, an absolute one is used as it is.
# file(INSTALL) honours DESTDIR and records the files in install_manifest.txt.
function(facecap_full_path out dir)
  if(IS_ABSOLUTE "${dir}")
    set(${out} "${dir}" PARENT_SCOPE)
  else()
    set(${out} "${CMAKE_INSTALL_PREFIX}/${dir}" PARENT_SCOPE)
  endif()
endfunction()
facecap_full_path(FACECAP_UNIT_BINDIR "${FACECAP_BINDIR}")
facecap_full_path(FACECAP_UNIT_SYSCONFDIR "${FACECAP_SYSCONFDIR}")
facecap_full_path(FACECAP_UNIT_DOCDIR "${FACECAP_DOCDIR}")
facecap_full_path(unit_dir "${FACECAP_UNIT_DIR}")
foreach(unit facecapd.service facecapd@.service)
  configure_file("${FACECAP_UNIT_SOURCE_DIR}/${unit}.in" "${FACECAP_UNIT_WORK_DIR}/${unit}" @ONLY)
  file(INSTALL "${FACECAP_UNIT_WORK_DIR}/${unit}" DESTINATION "${unit_dir}")
endforeach()
