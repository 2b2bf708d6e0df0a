#pragma once
/// \file text.hpp
/// Text that came from an untrusted file (a trace's attributes, a file name) made safe for
/// where octocd shows or stores it (docs/robustness.md, "Untrusted traces"): the terminal
/// (no control character reaches it) and UTF-8 documents (JSON, XML: no invalid byte
/// sequence). Header-only, no allocation beyond the result.

#include <cstddef>
#include <string>
#include <string_view>

namespace octocd {

/// The length (1-4) of the well-formed UTF-8 sequence at text[i] (RFC 3629: no overlong
/// forms, no surrogates, at most U+10FFFF), or 0 when the bytes there are not one.
inline std::size_t utf8_sequence_length(std::string_view text, std::size_t i) {
  const auto at = [&](std::size_t k) { return static_cast<unsigned char>(text[k]); };
  const unsigned char c = at(i);
  if (c < 0x80) return 1;
  std::size_t n = 0;
  unsigned char lo = 0x80, hi = 0xBF;  // the allowed range of the second byte
  if (c >= 0xC2 && c <= 0xDF) n = 2;
  else if (c == 0xE0) n = 3, lo = 0xA0;
  else if (c >= 0xE1 && c <= 0xEC) n = 3;
  else if (c == 0xED) n = 3, hi = 0x9F;
  else if (c >= 0xEE && c <= 0xEF) n = 3;
  else if (c == 0xF0) n = 4, lo = 0x90;
  else if (c >= 0xF1 && c <= 0xF3) n = 4;
  else if (c == 0xF4) n = 4, hi = 0x8F;
  else return 0;
  if (i + n > text.size()) return 0;
  if (at(i + 1) < lo || at(i + 1) > hi) return 0;
  for (std::size_t k = 2; k < n; ++k)
    if (at(i + k) < 0x80 || at(i + k) > 0xBF) return 0;
  return n;
}

/// `text` with every byte that does not start or continue a well-formed UTF-8 sequence
/// replaced by U+FFFD (the replacement character), as nlohmann::json's
/// error_handler_t::replace does: valid UTF-8 for JSON and XML.
inline std::string utf8_replaced(std::string_view text) {
  std::string out;
  out.reserve(text.size());
  for (std::size_t i = 0; i < text.size();) {
    const std::size_t n = utf8_sequence_length(text, i);
    if (n == 0) {
      out += "\xEF\xBF\xBD";
      ++i;
    } else {
      out.append(text.substr(i, n));
      i += n;
    }
  }
  return out;
}

/// `text` for the terminal: control characters (U+0000..U+001F, U+007F; escape sequences
/// start with U+001B) and bytes that are not well-formed UTF-8 written as \xNN, so a file
/// name or a trace's attribute can neither move the cursor, recolour, retitle the terminal
/// nor hide what follows it. Printable UTF-8 is kept as it is.
inline std::string printable(std::string_view text) {
  static const char* const kHex = "0123456789abcdef";
  std::string out;
  out.reserve(text.size());
  for (std::size_t i = 0; i < text.size();) {
    const auto c = static_cast<unsigned char>(text[i]);
    const std::size_t n = utf8_sequence_length(text, i);
    if (n == 0 || c < 0x20 || c == 0x7F) {
      out += "\\x";
      out += kHex[c >> 4];
      out += kHex[c & 15];
      ++i;
    } else {
      out.append(text.substr(i, n));
      i += n;
    }
  }
  return out;
}

}  // namespace octocd
