#include "tools/html.h"

#include <algorithm>
#include <fmt/core.h>

#include "tools/svg.h"

namespace hashcc::html {

std::string escape(const std::string& s) { return svg::escape(s); }  // the same five entities

std::string base64(const std::string& bytes) {
  static const char* k = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  size_t i = 0;
  for (; i + 2 < bytes.size(); i += 3) {
    const uint32_t v = uint32_t(uint8_t(bytes[i])) << 16 | uint32_t(uint8_t(bytes[i + 1])) << 8 |
                       uint8_t(bytes[i + 2]);
    out += k[v >> 18 & 63];
    out += k[v >> 12 & 63];
    out += k[v >> 6 & 63];
    out += k[v & 63];
  }
  if (i < bytes.size()) {  // 1 or 2 bytes left: 2 or 3 characters, then padding
    uint32_t v = uint32_t(uint8_t(bytes[i])) << 16;
    if (i + 1 < bytes.size()) v |= uint32_t(uint8_t(bytes[i + 1])) << 8;
    out += k[v >> 18 & 63];
    out += k[v >> 12 & 63];
    out += i + 1 < bytes.size() ? k[v >> 6 & 63] : '=';
    out += '=';
  }
  return out;
}

std::string png_img(const std::string& png_bytes, const std::string& alt, int width_px) {
  return fmt::format("<img alt=\"{}\"{} src=\"data:image/png;base64,{}\">", escape(alt),
                     width_px > 0 ? fmt::format(" width=\"{}\"", width_px) : "", base64(png_bytes));
}

std::string image_img(const ImageU8& im, int max_side, const std::string& alt) {
  int w = im.width, h = im.height;
  working_size(im.width, im.height, max_side, &w, &h);
  if (w == im.width && h == im.height) return png_img(encode_png(im.rgb.data(), w, h), alt);
  const ImageU8 small = resize_area(im.rgb.data(), im.width, im.height, w, h);
  return png_img(encode_png(small.rgb.data(), w, h), alt);
}

namespace {
// Replaces every `before + X + after` by `before + uid + "-" + X + after`.
std::string prefix_refs(const std::string& s, const std::string& before, const std::string& uid) {
  std::string out;
  size_t at = 0;
  for (size_t k; (k = s.find(before, at)) != std::string::npos; at = k + before.size()) {
    out.append(s, at, k - at);
    out += before + uid + "-";
  }
  out.append(s, at, std::string::npos);
  return out;
}
}  // namespace

std::string inline_svg(const std::string& svg, const std::string& uid) {
  std::string s = svg;
  if (s.rfind("<?xml", 0) == 0) {
    const size_t end = s.find("?>");
    s.erase(0, end == std::string::npos ? 0 : end + 2);
    while (!s.empty() && (s[0] == '\n' || s[0] == '\r')) s.erase(0, 1);
  }
  for (const char* ref : {" id=\"", "url(#", "href=\"#"}) s = prefix_refs(s, ref, uid);
  return s;
}

std::string section(const std::string& id, const std::string& title, const std::string& body) {
  return fmt::format("<section id=\"{}\">\n<h2>{}</h2>\n{}\n</section>\n", escape(id),
                     escape(title), body);
}

std::string absent(const std::string& text) {
  return "<p class=\"absent\">" + escape(text) + "</p>\n";
}

std::string table_html(const std::vector<std::string>& header,
                       const std::vector<std::vector<std::string>>& rows,
                       const std::string& css_class) {
  std::string o = css_class.empty() ? "<table>\n" : "<table class=\"" + escape(css_class) + "\">\n";
  if (!header.empty()) {
    o += "<tr>";
    for (const std::string& h : header) o += "<th>" + h + "</th>";
    o += "</tr>\n";
  }
  for (const auto& r : rows) {
    o += "<tr>";
    for (size_t i = 0; i < std::max(r.size(), header.size()); ++i)
      o += "<td>" + (i < r.size() ? r[i] : std::string()) + "</td>";
    o += "</tr>\n";
  }
  return o + "</table>\n";
}

std::string table(const std::vector<std::string>& header,
                  const std::vector<std::vector<std::string>>& rows, const std::string& css_class) {
  std::vector<std::string> h;
  for (const std::string& s : header) h.push_back(escape(s));
  std::vector<std::vector<std::string>> r;
  for (const auto& row : rows) {
    r.emplace_back();
    for (const std::string& s : row) r.back().push_back(escape(s));
  }
  return table_html(h, r, css_class);
}

std::string page(const std::string& title, const std::string& body) {
  // One small style sheet; system fonts only (a web font would be a network fetch).
  static const char* css = R"(body{font-family:"DejaVu Sans",Helvetica,Arial,sans-serif;margin:24px auto;max-width:1240px;padding:0 16px;color:#222;background:#fff}
h1{font-size:24px;margin:0 0 4px}h2{font-size:19px;border-bottom:1px solid #ccc;padding-bottom:4px;margin-top:32px}
h3{font-size:15px;margin:18px 0 6px}
table{border-collapse:collapse;margin:8px 0;font-size:13px}th,td{border:1px solid #ddd;padding:3px 7px;text-align:left;vertical-align:top}
th{background:#f3f3f3}td.num,th.num{text-align:right}
.absent{color:#8a5a00;background:#fff8e6;border-left:4px solid #e6a700;padding:6px 10px}
.note{color:#555;font-size:13px}
code,pre{font-family:"DejaVu Sans Mono",monospace;font-size:12.5px}
pre{background:#f6f6f6;padding:8px;overflow-x:auto;white-space:pre-wrap;word-break:break-all}
.plots{display:flex;flex-wrap:wrap;gap:12px}.plots svg{max-width:100%;height:auto}
table.images td{text-align:center;font-size:12px}table.images img{display:block;margin:0 auto}
img{min-width:192px;height:auto;image-rendering:pixelated}.frames img{min-width:144px}
.frames{display:flex;flex-wrap:wrap;gap:6px}.frames figure{margin:0;font-size:11px;text-align:center}
details summary{cursor:pointer;color:#0b5394})";
  return fmt::format("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
                     "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n"
                     "<title>{}</title>\n<style>\n{}\n</style>\n</head>\n<body>\n{}</body>\n</html>\n",
                     escape(title), css, body);
}

}  // namespace hashcc::html
