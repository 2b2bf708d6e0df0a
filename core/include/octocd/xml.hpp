#pragma once
/// \file xml.hpp
/// Escaping for the small XML files octocd writes (the XDMF sidecar of a trace, JUnit
/// reports of `octocd validate`).

#include <string>
#include <string_view>

#include "octocd/text.hpp"

namespace octocd {

/// `text` with the five XML special characters replaced by entities (&amp; &lt; &gt;
/// &quot; &apos;), so it is safe in element text and in double- or single-quoted
/// attribute values. Control characters other than tab, newline and carriage return
/// (not allowed in XML 1.0) become '?', and bytes that are not well-formed UTF-8 become
/// U+FFFD (utf8_replaced), so the document stays valid XML whatever a trace holds.
inline std::string xml_escape(std::string_view raw) {
  const std::string text = utf8_replaced(raw);
  std::string out;
  out.reserve(text.size());
  for (const char c : text) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      case '\'': out += "&apos;"; break;
      default:
        if (static_cast<unsigned char>(c) < 0x20 && c != '\t' && c != '\n' && c != '\r')
          out += '?';
        else
          out += c;
    }
  }
  return out;
}

}  // namespace octocd
