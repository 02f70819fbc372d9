// The avx512 path of the per-frame kernels (kernels.hpp); CMake compiles this file with
// that path's flags (solver/CMakeLists.txt).
#define FACECAP_KERNEL_NS avx512
#include "solver/kernels/kernels_impl.inl"
