#pragma once
// facecap's version, for --version and the control API: "0.1.0 (git 1a2b3c4d5e6f)" when
// built from a git checkout, "0.1.0" otherwise. Defined by the facecap_version library,
// which cmake/version.cmake generates at build time. RT-safe.
#include <string_view>

namespace facecap {

std::string_view version_string() noexcept;

}  // namespace facecap
