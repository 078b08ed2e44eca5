// test/xml_check.h — a small XML well-formedness check for the SVG and HTML writers' tests.
#pragma once
#include <cctype>
#include <string>
#include <vector>

namespace hashcc::test {

// A small XML well-formedness check (enough for SVG): balanced and properly nested tags, every
// attribute quoted, only the five predefined entities or character references, no bare '&' or
// '<' in text or attribute values, a single root element. Returns "" or the first problem.
inline std::string xml_problem(const std::string& s) {
  std::vector<std::string> stack;
  int roots = 0;
  size_t i = 0;
  auto check_amp = [&](size_t at) -> bool {
    const size_t semi = s.find(';', at);
    if (semi == std::string::npos || semi - at > 10) return false;
    const std::string ent = s.substr(at + 1, semi - at - 1);
    if (ent == "amp" || ent == "lt" || ent == "gt" || ent == "quot" || ent == "apos") return true;
    if (ent.size() >= 2 && ent[0] == '#') {
      for (size_t k = 1; k < ent.size(); ++k)
        if (!std::isxdigit(static_cast<unsigned char>(ent[k])) && !(k == 1 && ent[k] == 'x')) return false;
      return true;
    }
    return false;
  };
  auto is_name = [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_' || c == ':' || c == '.';
  };
  while (i < s.size()) {
    if (s[i] == '&') {
      if (!check_amp(i)) return "bad entity at " + std::to_string(i);
      ++i;
      continue;
    }
    if (s[i] != '<') {
      if (s[i] == '>') return "bare '>' in text at " + std::to_string(i);
      if (stack.empty() && !std::isspace(static_cast<unsigned char>(s[i])))
        return "text outside the root at " + std::to_string(i);
      ++i;
      continue;
    }
    if (s.compare(i, 5, "<?xml") == 0) {
      const size_t e = s.find("?>", i);
      if (e == std::string::npos || i != 0) return "bad XML declaration";
      i = e + 2;
      continue;
    }
    if (s.compare(i, 4, "<!--") == 0) {
      const size_t e = s.find("-->", i);
      if (e == std::string::npos) return "unterminated comment";
      i = e + 3;
      continue;
    }
    const bool closing = i + 1 < s.size() && s[i + 1] == '/';
    size_t j = i + (closing ? 2 : 1);
    const size_t name0 = j;
    while (j < s.size() && is_name(s[j])) ++j;
    const std::string name = s.substr(name0, j - name0);
    if (name.empty()) return "'<' without a tag name at " + std::to_string(i);
    if (closing) {
      while (j < s.size() && std::isspace(static_cast<unsigned char>(s[j]))) ++j;
      if (j >= s.size() || s[j] != '>') return "bad closing tag " + name;
      if (stack.empty() || stack.back() != name) return "mismatched </" + name + ">";
      stack.pop_back();
      i = j + 1;
      continue;
    }
    // Attributes.
    bool self_close = false;
    for (;;) {
      while (j < s.size() && std::isspace(static_cast<unsigned char>(s[j]))) ++j;
      if (j >= s.size()) return "unterminated tag " + name;
      if (s[j] == '>') { ++j; break; }
      if (s[j] == '/') {
        if (j + 1 >= s.size() || s[j + 1] != '>') return "bad '/' in tag " + name;
        self_close = true;
        j += 2;
        break;
      }
      const size_t a0 = j;
      while (j < s.size() && is_name(s[j])) ++j;
      if (j == a0) return "bad attribute in tag " + name + " at " + std::to_string(j);
      if (j >= s.size() || s[j] != '=') return "attribute without value in tag " + name;
      ++j;
      if (j >= s.size() || (s[j] != '"' && s[j] != '\'')) return "unquoted attribute in tag " + name;
      const char q = s[j++];
      while (j < s.size() && s[j] != q) {
        if (s[j] == '<') return "'<' in attribute value of " + name;
        if (s[j] == '&' && !check_amp(j)) return "bad entity in attribute of " + name;
        ++j;
      }
      if (j >= s.size()) return "unterminated attribute in " + name;
      ++j;
    }
    if (stack.empty()) ++roots;
    if (!self_close) stack.push_back(name);
    i = j;
  }
  if (!stack.empty()) return "unclosed <" + stack.back() + ">";
  if (roots != 1) return "expected one root element, found " + std::to_string(roots);
  return "";
}

}  // namespace hashcc::test
