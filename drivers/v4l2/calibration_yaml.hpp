#pragma once
// The subset of YAML that camera calibration files use (docs/cameras.md), read by our own
// parser instead of cv::FileStorage, whose YAML reader can be kept busy forever by a few
// dozen hostile bytes. Linear in the input, depth bounded, every error with its line.
//
// Accepted: an optional `%YAML:1.0` (or `%YAML 1.x`) line and `---`; block mappings
// (`key: value`), block sequences (`- value`, `-` with the value on the lines below,
// `- key: value` starting a mapping); flow sequences of scalars (`[1, 2.5, -3e2]`, over
// several lines); plain, "double" and 'single' quoted scalars; tags (`!!opencv-matrix`,
// ignored); `#` comments. Not accepted: flow mappings, anchors, aliases, block scalars
// (`|`, `>`), several documents, tabs for indentation.
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace facecap::drivers::v4l2 {

class YamlNode {
 public:
  enum class Kind { kNone, kScalar, kSequence, kMapping };

  Kind kind() const noexcept { return kind_; }
  bool is_none() const noexcept { return kind_ == Kind::kNone; }
  bool is_sequence() const noexcept { return kind_ == Kind::kSequence; }
  bool is_mapping() const noexcept { return kind_ == Kind::kMapping; }
  // A scalar that reads whole as an integer / a real (YAML's .inf and .nan included);
  // quoted scalars are strings only.
  std::optional<int64_t> integer() const;
  std::optional<double> real() const;
  bool is_string() const noexcept { return kind_ == Kind::kScalar; }
  const std::string& text() const noexcept { return text_; }
  int line() const noexcept { return line_; }

  // Sequence items; mapping values by key (a missing key gives a kNone node).
  const std::vector<YamlNode>& items() const noexcept { return items_; }
  const YamlNode& operator[](std::string_view key) const;

 private:
  friend class YamlParser;
  Kind kind_ = Kind::kNone;
  std::string text_;
  bool quoted_ = false;
  int line_ = 0;
  std::vector<YamlNode> items_;     // sequence items, or mapping values
  std::vector<std::string> keys_;   // mapping keys, parallel to items_
};

// Throws Error naming `name` and the line on anything outside the subset.
YamlNode parse_calibration_yaml(std::string_view text, const std::string& name);

}  // namespace facecap::drivers::v4l2
