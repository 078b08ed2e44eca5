// tools/html.h — the pieces of a self-contained HTML page: the run report (tools/run_report.h)
// and the study's page (tools/study_report.cpp).
//
// "Self-contained" is the rule every piece keeps: the page is ONE file that a browser shows
// with no network and no other file — styles in one <style>, plots as inline <svg>, images as
// base64 PNG data URIs, no script. So a report can be mailed, attached to an issue or opened
// from a laptop's Downloads folder years later and still look the same.
#pragma once
#include <string>
#include <vector>

#include "core/image.h"

namespace hashcc::html {

// Text for HTML content and attribute values: & < > " ' escaped, control characters (other than
// tab and newline) replaced by a space. Every string from a file or a command line goes through
// it (a path may hold '<' or '&'; a command line holds quotes).
std::string escape(const std::string& s);

// RFC 4648 base64 (with '=' padding) of raw bytes.
std::string base64(const std::string& bytes);

// <img> of PNG bytes as a data URI; alt is escaped. width_px > 0 sets the displayed width.
std::string png_img(const std::string& png_bytes, const std::string& alt, int width_px = 0);
// The same for pixels: downscaled (area filter) so that the longer side is at most max_side
// (0: as they are), then PNG-encoded. Keeps a page's size in check: a 504×378 photo is ~300 KB
// as PNG, a 320-px copy ~120 KB.
std::string image_img(const ImageU8& im, int max_side, const std::string& alt);

// An SVG document (tools/svg.h writes them) made fit to sit inside HTML: the XML declaration
// dropped and every id it defines (and each url(#id) / href="#id" naming one) prefixed with
// `uid` — two plots on one page both define id="frame", and an inline SVG's ids share the
// page's one namespace, so without this the second plot would clip to the first one's frame.
std::string inline_svg(const std::string& svg, const std::string& uid);

// <section id="id"><h2>title</h2>body</section>. body is HTML (already escaped).
std::string section(const std::string& id, const std::string& title, const std::string& body);
// The one line a section shows when its inputs are absent: what is missing and how to get it.
// Text (escaped here).
std::string absent(const std::string& text);
// A table of text cells (escaped here). rows may be shorter than header (empty cells).
std::string table(const std::vector<std::string>& header,
                  const std::vector<std::vector<std::string>>& rows,
                  const std::string& css_class = "");
// A table whose cells are already HTML (images, links, markup).
std::string table_html(const std::vector<std::string>& header,
                       const std::vector<std::vector<std::string>>& rows,
                       const std::string& css_class = "");

// The whole document: doctype, UTF-8, the page's styles, a title (escaped) and body (HTML).
std::string page(const std::string& title, const std::string& body);

}  // namespace hashcc::html
