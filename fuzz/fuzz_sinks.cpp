// libFuzzer target: the sinks of untrusted text (core/include/octocd/text.hpp; issue 68,
// docs/robustness.md "Sinks"). The input is any byte string, shown as octocd shows a name,
// a reason or an error line. A finding is an output that breaks its sink's rule:
// - printable / printable_line (the terminal): a control byte (< 0x20, 0x7F) or a byte
//   sequence that is not well-formed UTF-8, or more bytes than the bound allows;
// - bounded: more than max_bytes + 32 bytes, or not a prefix of the input when cut;
// - csv_text_cell (CSV): a cell that begins with = + - @ TAB or CR and is not a number;
// - utf8_replaced (JSON, XML): not well-formed UTF-8.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <string_view>

#include "octocd/text.hpp"

namespace {

[[noreturn]] void finding(const char* what, std::string_view out) {
  std::fprintf(stderr, "fuzz_sinks: %s (%zu bytes out)\n", what, out.size());
  std::abort();
}

bool well_formed(std::string_view s) {
  for (std::size_t i = 0; i < s.size();) {
    const std::size_t n = octocd::utf8_sequence_length(s, i);
    if (n == 0) return false;
    i += n;
  }
  return true;
}

void terminal_safe(std::string_view out, const char* what) {
  for (const char c : out)
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7F) finding(what, out);
  if (!well_formed(out)) finding(what, out);
}

bool csv_number(std::string_view t) {
  std::size_t i = (t[0] == '+' || t[0] == '-') ? 1 : 0;
  bool digits = false;
  while (i < t.size() && ((t[i] >= '0' && t[i] <= '9') || t[i] == '.' || t[i] == 'e' || t[i] == 'E' ||
                          t[i] == '+' || t[i] == '-'))
    digits |= t[i] >= '0' && t[i] <= '9', ++i;
  return digits && i == t.size();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view in(reinterpret_cast<const char*>(data), size);
  const std::size_t max = size > 0 ? 1 + data[0] % 64 : 16;  // small bounds reach the cuts

  const std::string p = octocd::printable(in, max);
  terminal_safe(p, "printable: a control byte or invalid UTF-8 reached the terminal");
  if (p.size() > 4 * (max + 32)) finding("printable: past its bound", p);
  const std::string l = octocd::printable_line(in);
  terminal_safe(l, "printable_line: a control byte or invalid UTF-8 reached the terminal");
  if (l.size() > 4 * (octocd::kMaxLineBytes + 64)) finding("printable_line: past its bound", l);

  const std::string b = octocd::bounded(in, max);
  if (b.size() > max + 32) finding("bounded: past its bound", b);
  if (in.size() <= max ? b != in : in.compare(0, b.rfind("... ("), b.substr(0, b.rfind("... ("))) != 0)
    finding("bounded: not the input's head", b);

  const std::string c = octocd::csv_text_cell(in);
  if (!c.empty() && (c[0] == '=' || c[0] == '+' || c[0] == '-' || c[0] == '@' || c[0] == '\t' || c[0] == '\r') &&
      (c[0] == '=' || c[0] == '@' || !csv_number(c)))
    finding("csv_text_cell: a formula's first character", c);

  if (!well_formed(octocd::utf8_replaced(in))) finding("utf8_replaced: invalid UTF-8", in);
  return 0;
}
