#pragma once
/// \file text.hpp
/// Text that came from an untrusted file (a trace's attributes, a file name) made safe for
/// where octocd shows or stores it (docs/robustness.md, "Sinks"): the terminal (no control
/// character reaches it), UTF-8 documents (JSON, XML: no invalid byte sequence), CSV cells
/// (no formula), every value bounded. Header-only, no allocation beyond the result.

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

/// The most bytes of one untrusted value (a name, a reason, an attribute) octocd prints or
/// writes into a line or a document (docs/robustness.md, "Sinks"): a longer value is cut.
inline constexpr std::size_t kMaxShownBytes = 4096;

/// The most bytes of one message line (an error, a verdict line) octocd prints: a longer
/// line keeps its head and its tail (the tail says what is allowed).
inline constexpr std::size_t kMaxLineBytes = 16384;

/// `n` written with thousands separators: 16777216 -> "16,777,216".
inline std::string grouped_count(std::size_t n) {
  std::string digits = std::to_string(n), out;
  for (std::size_t i = 0; i < digits.size(); ++i) {
    if (i > 0 && (digits.size() - i) % 3 == 0) out += ',';
    out += digits[i];
  }
  return out;
}

/// The largest k <= at with no UTF-8 sequence of `text` split at k (a cut point).
inline std::size_t utf8_cut_point(std::string_view text, std::size_t at) {
  if (at >= text.size()) return text.size();
  std::size_t k = at;
  for (int back = 0; back < 3 && k > 0 && (static_cast<unsigned char>(text[k]) & 0xC0) == 0x80; ++back) --k;
  return k;
}

/// `text` when it holds at most `max_bytes` bytes; else its first bytes (cut at a UTF-8
/// boundary), then "... (N bytes)" naming the whole length, then, when `tail_bytes` > 0,
/// its last `tail_bytes` bytes: "Sweep AAAA... (16,777,216 bytes)". The result holds at most
/// max_bytes + 32 bytes.
inline std::string bounded(std::string_view text, std::size_t max_bytes = kMaxShownBytes,
                           std::size_t tail_bytes = 0) {
  if (text.size() <= max_bytes) return std::string(text);
  if (tail_bytes > max_bytes / 2) tail_bytes = max_bytes / 2;
  const std::size_t head = utf8_cut_point(text, max_bytes - tail_bytes);
  std::string out(text.substr(0, head));
  out += "... (" + grouped_count(text.size()) + " bytes)";
  if (tail_bytes > 0) {
    std::size_t from = text.size() - tail_bytes;
    while (from < text.size() && (static_cast<unsigned char>(text[from]) & 0xC0) == 0x80) ++from;
    out += " ...";
    out.append(text.substr(from));
  }
  return out;
}

/// `text` for the terminal: control characters (U+0000..U+001F, U+007F; escape sequences
/// start with U+001B) and bytes that are not well-formed UTF-8 written as \xNN, so a file
/// name or a trace's attribute can neither move the cursor, recolour, retitle the terminal
/// nor hide what follows it. Printable UTF-8 is kept as it is. A value longer than
/// `max_bytes` is cut first (`bounded`); pass SIZE_MAX to keep every byte.
inline std::string printable(std::string_view text, std::size_t max_bytes = kMaxShownBytes) {
  static const char* const kHex = "0123456789abcdef";
  const std::string cut = text.size() > max_bytes ? bounded(text, max_bytes) : std::string();
  if (!cut.empty()) text = cut;
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

/// One message line for the terminal: `printable`, cut to kMaxLineBytes keeping its head and
/// its last 1,024 bytes (where a message says what is allowed).
inline std::string printable_line(std::string_view text) {
  return printable(text.size() > kMaxLineBytes ? bounded(text, kMaxLineBytes, 1024) : std::string(text),
                   static_cast<std::size_t>(-1));
}

/// A cell of a CSV file that a spreadsheet opens (OWASP, "CSV Injection"): a text cell that
/// begins with = + - @ TAB or CR gets a leading apostrophe so it is shown as text, never run
/// as a formula; a number (`-3.5`, `+2e-3`) is a number and stays as it is. Returns the cell
/// before CSV quoting.
inline std::string csv_text_cell(std::string_view text) {
  if (text.empty()) return std::string();
  const char c = text.front();
  if (c != '=' && c != '+' && c != '-' && c != '@' && c != '\t' && c != '\r') return std::string(text);
  // A number in full: sign, digits, at most one point, an optional exponent.
  std::size_t i = (c == '+' || c == '-') ? 1 : 0;
  bool digits = false, point = false;
  for (; i < text.size(); ++i) {
    if (text[i] >= '0' && text[i] <= '9') digits = true;
    else if (text[i] == '.' && !point) point = true;
    else break;
  }
  if (digits && i < text.size() && (text[i] == 'e' || text[i] == 'E')) {
    std::size_t k = i + 1;
    if (k < text.size() && (text[k] == '+' || text[k] == '-')) ++k;
    const std::size_t from = k;
    while (k < text.size() && text[k] >= '0' && text[k] <= '9') ++k;
    i = k > from ? k : i;
  }
  if (digits && i == text.size() && c != '=' && c != '@') return std::string(text);
  return "'" + std::string(text);
}

}  // namespace octocd
