// The source of facecap_test_pch, the target whose precompiled header the test programs
// reuse (tests/CMakeLists.txt); it defines nothing.
