#pragma once
// Lists written as text in options and configuration ("M001, M002", "/dev/video0,/dev/video2").
#include <string>
#include <string_view>
#include <vector>

namespace facecap {

// The items of `text` split at any of `separators`, each trimmed of spaces and tabs; empty
// items are dropped ("a, b,,c " gives a, b, c).
std::vector<std::string> split_list(std::string_view text, std::string_view separators = ",");

}  // namespace facecap
