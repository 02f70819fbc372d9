#pragma once
// Text from outside (NatNet servers, recordings, control clients) made safe to log or show:
// nothing in it can end a log line, forge a journald priority, or drive a terminal.
#include <string>
#include <string_view>

namespace facecap {

// Appends `text` to `out` with every byte that is a control character (C0, DEL), starts a
// C1 control (U+0080..U+009F), or is not part of valid UTF-8 written as \xNN; valid UTF-8
// otherwise kept ("Zoë" stays "Zoë", "a\nb" becomes "a\x0ab"). Allocates only to grow `out`.
void append_printable(std::string_view text, std::string& out);
std::string printable(std::string_view text);

}  // namespace facecap
