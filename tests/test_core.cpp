#include <cstdlib>
#include <sstream>

#include <catch2/catch.hpp>
#include <fcntl.h>
#include <fmt/format.h>
#include <spdlog/sinks/ostream_sink.h>
#include <sys/stat.h>
#include <unistd.h>

#include "core/enum_table.hpp"
#include "core/error.hpp"
#include "core/frame.hpp"
#include "core/huge_pages.hpp"
#include "core/io.hpp"
#include "core/log.hpp"
#include "core/printable.hpp"
#include "core/realtime.hpp"
#include "core/text_list.hpp"
#include "core/time.hpp"
#include "core/toml_reader.hpp"
#include "tests/test_support.hpp"

using namespace facecap;

TEST_CASE("error text names the file and line and column") {
  const Error e = Error("bad value", ErrorLocation{.file = "a.toml", .line = 3, .column = 7, .key = "solver.beta"});
  CHECK(std::string(e.what()) == "a.toml:3:7 [solver.beta]: bad value");
  CHECK(std::string(offset_error("x.c3d", 512, "truncated").what()) == "x.c3d @ byte 512: truncated");
  CHECK(e.message() == "bad value");
  CHECK(e.where().line == 3);
}

TEST_CASE("marker labels are fixed size and truncate long names") {
  MarkerLabel label("Mouth_Lend");
  CHECK(label.view() == "Mouth_Lend");
  MarkerLabel long_label(std::string(100, 'x'));
  CHECK(long_label.view().size() == MarkerLabel::kCapacity);
  Marker m;
  m.flags = kMarkerMissing;
  MarkerFrame frame;
  frame.markers = {m, Marker{}};
  CHECK(frame.present_count() == 1);
}

TEST_CASE("solve stages have names") {
  CHECK(solve_stage_name(SolveStage::kBacksolve) == "backsolve");
  CHECK(solve_stage_name(SolveStage::kWeights) == "weights");
}

TEST_CASE("atomic write then read returns the same bytes and missing files name themselves") {
  const auto dir = test::scratch_dir("io");
  const std::string text = "facecap\0bytes";
  write_file_atomically(dir / "f.bin", std::span<const char>(text.data(), text.size()));
  const auto back = read_file_bytes(dir / "f.bin");
  CHECK(std::string(back.begin(), back.end()) == text);
  CHECK_THROWS_WITH(read_file_bytes(dir / "absent.bin"), Catch::Contains("absent.bin") && Catch::Contains("cannot open"));
}

TEST_CASE("FNV-1a matches the published test vector") {
  Fnv1a64 h;
  h.add("a", 1);
  CHECK(h.digest() == 0xaf63dc4c8601ec8cull);
}

TEST_CASE("prefetch_until covers every range before its deadline and nothing after it") {
  const std::vector<std::byte> large(200'000), small(3);
  const std::span<const std::byte> ranges[] = {large, small};
  CHECK(prefetch_until(ranges, std::numeric_limits<int64_t>::max()) == 200'003);
  CHECK(prefetch_until(ranges, monotonic_now_ns()) == 0);  // the deadline has passed
  CHECK(prefetch_until({}, std::numeric_limits<int64_t>::max()) == 0);
}

TEST_CASE("huge-page vectors are aligned, hold their values and map large arrays on 2 MiB boundaries") {
  HugePageVector<float> small(1000, 1.5f);
  CHECK(reinterpret_cast<std::uintptr_t>(small.data()) % 64 == 0);
  const std::size_t count = (3 << 20) / sizeof(double);  // 3 MiB: mapped on its own
  HugePageVector<double> large(count);
  for (std::size_t i = 0; i < count; ++i) large[i] = double(i);
  CHECK(reinterpret_cast<std::uintptr_t>(large.data()) % kHugePageBytes == 0);
  CHECK(large[count - 1] == double(count - 1));
  HugePageVector<double> copy = large;
  CHECK(copy == large);
  CHECK(small[999] == 1.5f);
}

namespace {
enum class Fruit : uint8_t { kApple, kPear, kPlum };
constexpr EnumTable kFruits{std::array{EnumEntry{Fruit::kApple, "apple", "red or green"},
                                       EnumEntry{Fruit::kPear, "pear", "tapered"}}};
static_assert(kFruits.parse("pear") == Fruit::kPear);
static_assert(!kFruits.parse("Pear"));
}  // namespace

TEST_CASE("an enum table parses and names exactly its rows, in order") {
  CHECK(kFruits.parse("apple") == Fruit::kApple);
  CHECK_FALSE(kFruits.parse("plum"));
  CHECK(kFruits.name(Fruit::kPear) == "pear");
  CHECK(kFruits.name(Fruit::kPlum) == "?");  // a value the table lacks
  CHECK(kFruits.description(Fruit::kApple) == "red or green");
  CHECK(kFruits.names() == std::vector<std::string_view>{"apple", "pear"});
  REQUIRE(kFruits.choices().size() == 2);
  CHECK(kFruits.choices()[1].description == "tapered");
}

TEST_CASE("read_file_bytes refuses a directory instead of sizing it as 2^63 bytes") {
  const auto dir = test::scratch_dir("io-directory");
  CHECK_THROWS_WITH(read_file_bytes(dir), Catch::Contains(dir.string()) && Catch::Contains("is a directory"));
}

TEST_CASE("Only regular files are opened: a FIFO, a device or (with no_follow) a symlink is refused at once, naming it") {
  const auto dir = test::scratch_dir("io-regular");
  const auto fifo = dir / "shape.obj";
  REQUIRE(::mkfifo(fifo.c_str(), 0644) == 0);  // no writer: opening it blocking would wait forever
  CHECK_THROWS_WITH(read_file_bytes(fifo), Catch::Contains(fifo.string()) && Catch::Contains("is a FIFO (named pipe), not a regular file"));
  CHECK_THROWS_WITH(MappedFile(fifo), Catch::Contains("is a FIFO"));
  CHECK_THROWS_WITH(read_file_bytes("/dev/zero"), Catch::Contains("/dev/zero") && Catch::Contains("is a character device"));
  test::write_text(dir / "real.txt", "twelve bytes");
  std::filesystem::create_symlink(dir / "real.txt", dir / "link.txt");
  CHECK(MappedFile(dir / "link.txt").bytes().size() == 12);  // followed by default
  CHECK_THROWS_WITH(MappedFile(dir / "link.txt", true), Catch::Contains("is a symbolic link"));
  const MappedFile mapped(dir / "real.txt", true);
  CHECK(std::string(mapped.bytes().begin(), mapped.bytes().end()) == "twelve bytes");
}

TEST_CASE("TOML text is checked to be UTF-8 first, at the line and column of the first bad byte") {
  CHECK_NOTHROW(check_utf8("name = \"a\xc3\xa9\xe2\x82\xac\xf0\x9f\x98\x80\"\n", "ok.toml"));  // é € 😀
  const std::pair<const char*, const char*> bad[] = {
      {"\xc0\xaf", "0xc0"},          // overlong '/'
      {"\xed\xa0\x80", "0xed"},      // a UTF-16 surrogate
      {"\xf4\x90\x80\x80", "0xf4"},  // past U+10FFFF
      {"\xe2\x82", "0xe2"},          // cut short at the end
      {"\x80", "0x80"},              // a lone continuation byte
      {"\xff", "0xff"},
  };
  for (const auto& [bytes, first] : bad) {
    INFO(first);
    // Line 2, after "x = \"\xc3\xa9": column 7 counts é as one character.
    const std::string text = std::string("a = 1\nx = \"\xc3\xa9") + bytes + "\"\n";
    CHECK_THROWS_WITH(parse_toml(text, "bad.toml"),
                      Catch::Contains("bad.toml:2:7") && Catch::Contains(first) && Catch::Contains("not valid UTF-8"));
  }
  CHECK_THROWS_WITH(parse_toml("a = \n", "syntax.toml"), Catch::Contains("syntax.toml:1:"));
}
TEST_CASE("a non-ASCII character outside TOML strings and comments is refused before toml++ sees it") {
  // toml++ 3.3 tested it for whitespace and reached __builtin_unreachable (found by the
  // calibration_profile fuzzer: "offset = [0.01, 0, Н").
  CHECK_THROWS_WITH(parse_toml("a = 1\noffset = [0.01, 0, \xd0\x9d\n", "cyrillic.toml"),
                    Catch::Contains("cyrillic.toml:2:20") && Catch::Contains("non-ASCII character outside a string"));
  CHECK_THROWS_WITH(parse_toml("caf\xc3\xa9 = 1\n", "key.toml"), Catch::Contains("key.toml:1:4"));
  // Inside strings (escaped quotes, multi-line, literal) and comments it is text.
  const toml::table t = parse_toml("# caf\xc3\xa9\na = \"q\\\"\xc3\xa9\" # \xd0\x9d\nb = '\xc3\xa9'\n"
                                   "c = \"\"\"x\"\xc3\xa9\n\xd0\x9d\"\"\"\nd = '''\xc3\xa9'''\n",
                                   "strings.toml");
  CHECK(t["a"].value<std::string>() == "q\"\xc3\xa9");
  CHECK(t["b"].value<std::string>() == "\xc3\xa9");
  CHECK(t["c"].value<std::string>() == "x\"\xc3\xa9\n\xd0\x9d");
  CHECK(t["d"].value<std::string>() == "\xc3\xa9");
  // In a multi-line basic string toml++ also tests the character after a backslash, and
  // the whitespace a line-ending backslash trims (found by the fuzzer the same way).
  CHECK_THROWS_WITH(parse_toml("a = \"\"\"x\\\xc3\xa9\"\"\"\n", "escape.toml"),
                    Catch::Contains("escape.toml:1:10") && Catch::Contains("after a backslash"));
  CHECK_THROWS_WITH(parse_toml("a = \"\"\"x\\\n\n  \xcd\x9c\"\"\"\n", "trim.toml"),
                    Catch::Contains("trim.toml:3:3") && Catch::Contains("a line-ending backslash trims"));
  // A quote where no string can start (after '+') is read by toml++ as part of a bare value.
  CHECK_THROWS_WITH(parse_toml("units=+\"blink\xd0\x90\"\n", "plus.toml"),
                    Catch::Contains("plus.toml:1:14") && Catch::Contains("outside a string"));
  // Nor where '=' does not separate a key from its value (rig_manifest fuzz finding).
  CHECK_THROWS_WITH(parse_toml("namshapdeunitected=+=\"sub'''i\xef\xb9\xbfts_de\n", "junk.toml"),
                    Catch::Contains("junk.toml:1:"));
  const toml::table trimmed = parse_toml("a = \"\"\"x\\\n  y\xc3\xa9 \\\\\xc3\xa9\"\"\"\n", "trimmed.toml");
  CHECK(trimmed["a"].value<std::string>() == "xy\xc3\xa9 \\\xc3\xa9");
}

TEST_CASE("a descriptor is the journal's stream only when $JOURNAL_STREAM names its device and inode") {
  const auto file = test::scratch_dir("journal") / "stream";
  test::write_text(file, "");
  const int fd = ::open(file.c_str(), O_WRONLY);
  REQUIRE(fd >= 0);
  struct stat st {};
  REQUIRE(::fstat(fd, &st) == 0);
  ::unsetenv("JOURNAL_STREAM");
  CHECK_FALSE(is_journal_stream(fd));
  ::setenv("JOURNAL_STREAM", fmt::format("{}:{}", st.st_dev, st.st_ino).c_str(), 1);
  CHECK(is_journal_stream(fd));
  ::setenv("JOURNAL_STREAM", fmt::format("{}:{}", st.st_dev, st.st_ino + 1).c_str(), 1);  // inherited, not ours
  CHECK_FALSE(is_journal_stream(fd));
  ::setenv("JOURNAL_STREAM", "garbage", 1);
  CHECK_FALSE(is_journal_stream(fd));
  ::unsetenv("JOURNAL_STREAM");
  ::close(fd);
}

TEST_CASE("outside text is made printable: controls, C1 controls and bytes that are not UTF-8 escaped, UTF-8 kept") {
  CHECK(printable("Anna take 3") == "Anna take 3");
  CHECK(printable("Zo\xc3\xab \xe2\x82\xac \xf0\x9f\x98\x80") == "Zo\xc3\xab \xe2\x82\xac \xf0\x9f\x98\x80");  // ë € 😀
  CHECK(printable("a\nb\r\tc") == "a\\x0ab\\x0d\\x09c");
  CHECK(printable("\x1b[2J\x7f") == "\\x1b[2J\\x7f");
  CHECK(printable(std::string_view("nul\0x", 5)) == "nul\\x00x");
  CHECK(printable("\xc2\x9b" "31m") == "\\xc2\\x9b31m");                 // U+009B, a C1 CSI
  CHECK(printable("\xff\xfe") == "\\xff\\xfe");                         // never UTF-8
  CHECK(printable("\xc3") == "\\xc3");                                   // cut sequence
  CHECK(printable("\xc0\xaf") == "\\xc0\\xaf");                         // overlong '/'
  CHECK(printable("\xed\xa0\x80") == "\\xed\\xa0\\x80");                // a surrogate
  CHECK(printable("\xf4\x90\x80\x80") == "\\xf4\\x90\\x80\\x80");       // above U+10FFFF
  CHECK(printable("\xe2\x82") == "\\xe2\\x82");                         // cut before its last byte
}

TEST_CASE("a log message carrying outside text stays one line: no journald priority can be forged in it") {
  // The journal's format ("<N>level: message"), chosen when standard output is the journal's stream.
  struct stat out {};
  REQUIRE(::fstat(STDOUT_FILENO, &out) == 0);
  ::setenv("JOURNAL_STREAM", fmt::format("{}:{}", out.st_dev, out.st_ino).c_str(), 1);
  std::ostringstream text;
  const auto previous = spdlog::default_logger();
  spdlog::set_default_logger(
      std::make_shared<spdlog::logger>("", std::make_shared<spdlog::sinks::ostream_sink_st>(text)));
  configure_log_output();
  spdlog::info("take started: {}", "evil\n<0>facecapd: EMERGENCY\x1b]0;owned\x07\xff");
  spdlog::set_default_logger(previous);
  ::unsetenv("JOURNAL_STREAM");
  CHECK(text.str() == "<6>info: take started: evil\\x0a<0>facecapd: EMERGENCY\\x1b]0;owned\\x07\\xff\n");
}

TEST_CASE("split_list splits at its separators, trims spaces and tabs and drops empty items") {
  using V = std::vector<std::string>;
  CHECK(split_list("a, b ,,\tc ") == V{"a", "b", "c"});
  CHECK(split_list("Marker 1, Marker 2") == V{"Marker 1", "Marker 2"});  // spaces inside an item stay
  CHECK(split_list(" a.lan, b.lan  c.lan,,", ", \t") == V{"a.lan", "b.lan", "c.lan"});
  CHECK(split_list("").empty());
  CHECK(split_list(" , ,").empty());
  CHECK(split_list("/dev/video0") == V{"/dev/video0"});
}
