// Which kernel paths this CPU runs, and their tables (kernels.hpp). Compiled for the
// baseline like the rest of the solver.
#include "solver/kernels/kernels.hpp"

#if defined(FACECAP_KERNELS_X86)
#include <cpuid.h>
#endif

#include <fmt/format.h>

#include "core/error.hpp"

namespace facecap::kernels {

namespace portable {
const KernelTable& kernel_table() noexcept;
}
#if defined(FACECAP_KERNELS_X86)
namespace avx2 {
const KernelTable& kernel_table() noexcept;
}
namespace avx512 {
const KernelTable& kernel_table() noexcept;
}
#endif

namespace {

struct CpuFeatures {
  bool avx2 = false, fma = false, f16c = false, avx512 = false;
};

// __builtin_cpu_supports also checks that the OS saves the wider registers (XCR0).
CpuFeatures read_cpu_features() noexcept {
  CpuFeatures f;
#if defined(FACECAP_KERNELS_X86)
  __builtin_cpu_init();
  f.avx2 = __builtin_cpu_supports("avx2");
  f.fma = __builtin_cpu_supports("fma");
  // Clang's __builtin_cpu_supports does not know "f16c": CPUID leaf 1, ECX bit 29 (its
  // registers are the AVX ones, whose saving the avx2 check above covers).
  unsigned eax = 0, ebx = 0, ecx = 0, edx = 0;
  f.f16c = __get_cpuid(1, &eax, &ebx, &ecx, &edx) && (ecx & bit_F16C) != 0;
  f.avx512 = __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512bw") &&
             __builtin_cpu_supports("avx512vl") && __builtin_cpu_supports("avx512dq");
#endif
  return f;
}

const CpuFeatures& cpu() noexcept {
  static const CpuFeatures features = read_cpu_features();
  return features;
}

bool avx2_path_runs(const CpuFeatures& f) noexcept { return f.avx2 && f.fma && f.f16c; }

}  // namespace

bool cpu_runs(KernelPath path) noexcept {
  switch (path) {
    case KernelPath::kAuto:
    case KernelPath::kPortable: return true;
    case KernelPath::kAvx2: return avx2_path_runs(cpu());
    case KernelPath::kAvx512: return avx2_path_runs(cpu()) && cpu().avx512;
  }
  return false;
}

KernelPath best_path() noexcept {
  if (cpu_runs(KernelPath::kAvx512)) return KernelPath::kAvx512;
  if (cpu_runs(KernelPath::kAvx2)) return KernelPath::kAvx2;
  return KernelPath::kPortable;
}

std::string_view cpu_features() noexcept {
  static const std::string text = [] {
    const CpuFeatures& f = cpu();
    std::string s;
    for (const auto& [has, name] : {std::pair{f.avx512, "avx512"}, {f.avx2, "avx2"}, {f.fma, "fma"}, {f.f16c, "f16c"}})
      if (has) s += s.empty() ? name : fmt::format(" {}", name);
    return s.empty() ? std::string("none of avx2, fma, f16c, avx512") : s;
  }();
  return text;
}

const KernelTable& table(KernelPath path) {
  if (path == KernelPath::kAuto) path = best_path();
  if (!cpu_runs(path))
    throw Error(fmt::format("kernels \"{}\": this CPU cannot run them (it has {}); use \"auto\" or \"portable\"",
                            kKernelPaths.name(path), cpu_features()));
  switch (path) {
#if defined(FACECAP_KERNELS_X86)
    case KernelPath::kAvx512: return avx512::kernel_table();
    case KernelPath::kAvx2: return avx2::kernel_table();
#endif
    default: return portable::kernel_table();
  }
}

}  // namespace facecap::kernels
