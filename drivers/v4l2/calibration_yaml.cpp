#include "drivers/v4l2/calibration_yaml.hpp"

#include <charconv>
#include <cmath>
#include <limits>

#include <fmt/format.h>

#include "core/error.hpp"

namespace facecap::drivers::v4l2 {

std::optional<int64_t> YamlNode::integer() const {
  if (kind_ != Kind::kScalar || quoted_ || text_.empty()) return std::nullopt;
  std::string_view t = text_;
  if (t.front() == '+') t.remove_prefix(1);
  int64_t value = 0;
  const auto [end, ec] = std::from_chars(t.data(), t.data() + t.size(), value);
  if (ec != std::errc() || end != t.data() + t.size()) return std::nullopt;
  return value;
}

std::optional<double> YamlNode::real() const {
  if (kind_ != Kind::kScalar || quoted_ || text_.empty()) return std::nullopt;
  std::string_view t = text_;
  const bool negative = t.front() == '-';
  if (t.front() == '+' || t.front() == '-') t.remove_prefix(1);
  if (t == ".inf" || t == ".Inf" || t == ".INF")
    return negative ? -std::numeric_limits<double>::infinity() : std::numeric_limits<double>::infinity();
  if (t == ".nan" || t == ".NaN" || t == ".NAN") return std::numeric_limits<double>::quiet_NaN();
  if (t.empty() || t.front() == '+' || t.front() == '-') return std::nullopt;
  double value = 0;
  const auto [end, ec] = std::from_chars(t.data(), t.data() + t.size(), value);
  if (ec == std::errc::result_out_of_range) return negative ? -HUGE_VAL : HUGE_VAL;  // or a denormal: refused later
  if (ec != std::errc() || end != t.data() + t.size()) return std::nullopt;
  return negative ? -value : value;
}

const YamlNode& YamlNode::operator[](std::string_view key) const {
  static const YamlNode none;
  if (kind_ != Kind::kMapping) return none;
  for (std::size_t i = 0; i < keys_.size(); ++i)
    if (keys_[i] == key) return items_[i];
  return none;
}

class YamlParser {
 public:
  YamlParser(std::string_view text, const std::string& name) : name_(name) { split_lines(text); }

  YamlNode document() {
    if (at_ < lines_.size() && lines_[at_].content.starts_with("%YAML")) ++at_;
    if (at_ < lines_.size() && lines_[at_].content == "---") ++at_;
    if (at_ >= lines_.size()) return YamlNode{};
    if (lines_[at_].indent != 0) fail(lines_[at_].number, "the top level must not be indented");
    YamlNode root = block(0, 0);
    if (at_ < lines_.size()) {
      const Line& line = lines_[at_];
      fail(line.number, line.content == "---" || line.content == "..."
                            ? "only one document is read"
                            : fmt::format("unexpected indentation ({} spaces)", line.indent));
    }
    return root;
  }

 private:
  struct Line {
    int number = 0;
    std::size_t indent = 0;
    std::string content;  // without indentation, comment and trailing space
  };
  static constexpr int kMaxDepth = 32;

  [[noreturn]] void fail(int line, const std::string& what) const { throw line_error(name_, line, what); }

  void split_lines(std::string_view text) {
    int number = 0;
    while (!text.empty()) {
      const std::size_t eol = text.find('\n');
      std::string_view raw = text.substr(0, eol);
      text.remove_prefix(eol == std::string_view::npos ? text.size() : eol + 1);
      ++number;
      if (!raw.empty() && raw.back() == '\r') raw.remove_suffix(1);
      std::size_t indent = 0;
      while (indent < raw.size() && raw[indent] == ' ') ++indent;
      std::string_view content = strip_comment(raw.substr(indent), number);
      while (!content.empty() && (content.back() == ' ' || content.back() == '\t')) content.remove_suffix(1);
      if (content.empty()) continue;
      if (content.front() == '\t') fail(number, "a tab in the indentation (YAML indents with spaces)");
      lines_.push_back({number, indent, std::string(content)});
    }
  }

  // Cuts a # comment (at the start, or after a space) outside quotes.
  std::string_view strip_comment(std::string_view s, int number) const {
    char quote = 0;
    for (std::size_t i = 0; i < s.size(); ++i) {
      const char c = s[i];
      if (c == '\0') fail(number, "a NUL byte");
      if (quote) {
        if (c == '\\' && quote == '"') ++i;
        else if (c == quote) quote = 0;
      } else if ((c == '"' || c == '\'') && (i == 0 || std::string_view(" \t[,:-").find(s[i - 1]) != std::string_view::npos)) {
        quote = c;
      } else if (c == '#' && (i == 0 || s[i - 1] == ' ' || s[i - 1] == '\t')) {
        return s.substr(0, i);
      }
    }
    return s;
  }

  static bool is_item(const std::string& content) { return content == "-" || content.starts_with("- "); }

  // Where a `key: value` line's colon is (outside quotes and brackets), or npos.
  static std::size_t key_colon(std::string_view s) {
    if (s.empty() || s.front() == '[' || s.front() == '{') return std::string_view::npos;
    char quote = 0;
    for (std::size_t i = 0; i < s.size(); ++i) {
      const char c = s[i];
      if (quote) {
        if (c == '\\' && quote == '"') ++i;
        else if (c == quote) quote = 0;
      } else if (i == 0 && (c == '"' || c == '\'')) {
        quote = c;
      } else if (c == ':' && (i + 1 == s.size() || s[i + 1] == ' ')) {
        return i;
      }
    }
    return std::string_view::npos;
  }

  YamlNode block(std::size_t indent, int depth) {
    if (depth > kMaxDepth) fail(lines_[at_].number, fmt::format("nested deeper than {} levels", kMaxDepth));
    return is_item(lines_[at_].content) ? sequence(indent, depth) : mapping(indent, depth);
  }

  YamlNode mapping(std::size_t indent, int depth) {
    YamlNode node;
    node.kind_ = YamlNode::Kind::kMapping;
    node.line_ = lines_[at_].number;
    while (at_ < lines_.size() && lines_[at_].indent == indent && !is_item(lines_[at_].content)) {
      const Line& line = lines_[at_];
      const std::size_t colon = key_colon(line.content);
      if (line.content.front() == '{') fail(line.number, "flow mappings ({ ... }) are not read (nor is JSON): write YAML");
      if (line.content.front() == '<') fail(line.number, "XML is not read: write YAML");
      if (colon == std::string_view::npos) fail(line.number, "expected `key: value`");
      std::string key = scalar_text(std::string_view(line.content).substr(0, colon), line.number, false).text_;
      if (key.empty()) fail(line.number, "a key with no name");
      for (const std::string& k : node.keys_)
        if (k == key) fail(line.number, fmt::format("key `{}` given twice", key));
      std::string_view rest = std::string_view(line.content).substr(colon + 1);
      while (!rest.empty() && rest.front() == ' ') rest.remove_prefix(1);
      const int number = line.number;
      ++at_;
      node.keys_.push_back(std::move(key));
      node.items_.push_back(value(rest, indent, number, depth + 1, true));
    }
    return node;
  }

  YamlNode sequence(std::size_t indent, int depth) {
    YamlNode node;
    node.kind_ = YamlNode::Kind::kSequence;
    node.line_ = lines_[at_].number;
    while (at_ < lines_.size() && lines_[at_].indent == indent && is_item(lines_[at_].content)) {
      Line& line = lines_[at_];
      std::size_t offset = 1;
      while (offset < line.content.size() && line.content[offset] == ' ') ++offset;
      const std::string_view rest = std::string_view(line.content).substr(offset);
      if (!rest.empty() && (is_item(std::string(rest)) || key_colon(rest) != std::string_view::npos)) {
        // `- key: value` or `- - x`: the item is a block starting at rest's column.
        line.indent = indent + offset;
        line.content = std::string(rest);
        node.items_.push_back(block(line.indent, depth + 1));
        continue;
      }
      const int number = line.number;
      ++at_;
      node.items_.push_back(value(rest, indent, number, depth + 1, false));
    }
    return node;
  }

  // A value after `key:` or `-` on line `number`, whose parent is at `indent`.
  YamlNode value(std::string_view rest, std::size_t indent, int number, int depth, bool in_mapping) {
    if (depth > kMaxDepth) fail(number, fmt::format("nested deeper than {} levels", kMaxDepth));
    if (!rest.empty() && rest.front() == '!') {  // a tag such as !!opencv-matrix: the structure says the same
      const std::size_t end = rest.find(' ');
      rest = end == std::string_view::npos ? std::string_view() : rest.substr(end + 1);
      while (!rest.empty() && rest.front() == ' ') rest.remove_prefix(1);
    }
    if (rest.empty()) {
      if (at_ < lines_.size() && lines_[at_].indent > indent) return block(lines_[at_].indent, depth);
      // YAML lets a mapping's sequence sit at the key's own indentation.
      if (in_mapping && at_ < lines_.size() && lines_[at_].indent == indent && is_item(lines_[at_].content))
        return sequence(indent, depth);
      YamlNode empty;
      empty.kind_ = YamlNode::Kind::kScalar;
      empty.line_ = number;
      return empty;
    }
    switch (rest.front()) {
      case '[': return flow_sequence(rest, indent, number, depth);
      case '{': fail(number, "flow mappings ({ ... }) are not read: write the mapping as indented `key: value` lines");
      case '&':
      case '*': fail(number, "anchors and aliases are not read");
      case '|':
      case '>': fail(number, "block scalars (| and >) are not read");
      default: break;
    }
    if (at_ < lines_.size() && lines_[at_].indent > indent)
      fail(lines_[at_].number, "unexpected indentation after a scalar (values take one line)");
    return scalar_text(rest, number, true);
  }

  // A quoted or plain scalar making up all of s.
  YamlNode scalar_text(std::string_view s, int number, bool whole_value) const {
    YamlNode node;
    node.kind_ = YamlNode::Kind::kScalar;
    node.line_ = number;
    if (!s.empty() && (s.front() == '"' || s.front() == '\'')) {
      std::size_t used = 0;
      node.text_ = quoted(s, number, used);
      node.quoted_ = true;
      if (used != s.size()) fail(number, "text after a closing quote");
      return node;
    }
    if (whole_value && s.find(": ") != std::string_view::npos) fail(number, "a `key: value` inside a value");
    node.text_ = std::string(s);
    return node;
  }

  // The quoted scalar at the start of s; `used` is how many bytes it took.
  std::string quoted(std::string_view s, int number, std::size_t& used) const {
    const char quote = s.front();
    std::string out;
    for (std::size_t i = 1; i < s.size(); ++i) {
      const char c = s[i];
      if (quote == '\'' && c == '\'') {
        if (i + 1 < s.size() && s[i + 1] == '\'') {
          out += '\'';
          ++i;
          continue;
        }
        used = i + 1;
        return out;
      }
      if (quote == '"' && c == '"') {
        used = i + 1;
        return out;
      }
      if (quote == '"' && c == '\\') {
        if (++i == s.size()) break;
        switch (s[i]) {
          case '"': out += '"'; break;
          case '\\': out += '\\'; break;
          case '/': out += '/'; break;
          case 'n': out += '\n'; break;
          case 't': out += '\t'; break;
          case 'r': out += '\r'; break;
          default: fail(number, fmt::format("escape \\{} is not read", s[i]));
        }
        continue;
      }
      out += c;
    }
    fail(number, "a quoted string does not end on its line");
  }

  // `[a, b, [c]]`, continued on the following lines (indented past the parent) until it closes.
  YamlNode flow_sequence(std::string_view first, std::size_t indent, int number, int depth) {
    flow_ = {std::string(first), 0, number, indent};
    YamlNode node = flow_items(depth);
    while (flow_.pos < flow_.text.size() && flow_.text[flow_.pos] == ' ') ++flow_.pos;
    if (flow_.pos != flow_.text.size()) fail(flow_.line, "text after the closing ]");
    return node;
  }

  // Appends the next line of a [ list that goes on past its line.
  bool flow_more() {
    if (at_ >= lines_.size() || lines_[at_].indent <= flow_.indent) return false;
    flow_.text += ' ';
    flow_.text += lines_[at_].content;
    flow_.line = lines_[at_].number;
    ++at_;
    return true;
  }

  void flow_skip_space() {
    for (;;) {
      while (flow_.pos < flow_.text.size() && (flow_.text[flow_.pos] == ' ' || flow_.text[flow_.pos] == '\t')) ++flow_.pos;
      if (flow_.pos < flow_.text.size() || !flow_more()) return;
    }
  }

  YamlNode flow_items(int depth) {
    std::string& text = flow_.text;
    std::size_t& pos = flow_.pos;
    if (depth > kMaxDepth) fail(flow_.line, fmt::format("nested deeper than {} levels", kMaxDepth));
    YamlNode node;
    node.kind_ = YamlNode::Kind::kSequence;
    node.line_ = flow_.line;
    ++pos;  // [
    flow_skip_space();
    if (pos < text.size() && text[pos] == ']') {
      ++pos;
      return node;
    }
    for (;;) {
      flow_skip_space();
      if (pos >= text.size()) fail(flow_.line, "a [ list does not close");
      const char c = text[pos];
      if (c == '[') {
        node.items_.push_back(flow_items(depth + 1));
      } else if (c == '{') {
        fail(flow_.line, "flow mappings ({ ... }) are not read");
      } else if (c == ',' || c == ']') {
        fail(flow_.line, "an empty item in a [ list");
      } else if (c == '"' || c == '\'') {
        std::size_t used = 0;
        YamlNode item;
        item.kind_ = YamlNode::Kind::kScalar;
        item.line_ = flow_.line;
        item.text_ = quoted(std::string_view(text).substr(pos), flow_.line, used);
        item.quoted_ = true;
        pos += used;
        node.items_.push_back(std::move(item));
      } else {
        std::size_t end = text.find_first_of(",]", pos);
        while (end == std::string::npos) {
          const std::size_t searched = text.size();
          if (!flow_more()) fail(flow_.line, "a [ list does not close");
          end = text.find_first_of(",]", searched);
        }
        std::size_t last = end;
        while (last > pos && (text[last - 1] == ' ' || text[last - 1] == '\t')) --last;
        YamlNode item = scalar_text(std::string_view(text).substr(pos, last - pos), flow_.line, true);
        if (item.text_.find_first_of("[{") != std::string::npos) fail(flow_.line, "a bracket inside a plain scalar");
        node.items_.push_back(std::move(item));
        pos = end;
      }
      flow_skip_space();
      if (pos >= text.size()) fail(flow_.line, "a [ list does not close");
      if (text[pos] == ']') {
        ++pos;
        return node;
      }
      if (text[pos] != ',') fail(flow_.line, "expected , or ] in a [ list");
      ++pos;
    }
  }

  struct Flow {
    std::string text;
    std::size_t pos = 0;
    int line = 0;
    std::size_t indent = 0;  // of the value's parent: continuation lines are indented past it
  };
  Flow flow_;
  const std::string& name_;
  std::vector<Line> lines_;
  std::size_t at_ = 0;
};

YamlNode parse_calibration_yaml(std::string_view text, const std::string& name) {
  return YamlParser(text, name).document();
}

}  // namespace facecap::drivers::v4l2
