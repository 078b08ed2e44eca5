#include "core/exif.h"

#include <algorithm>
#include <fmt/core.h>

namespace hashcc {

namespace {

// The TIFF block, with every read bounds-checked: a read that does not fit returns false and
// leaves the value alone, so a truncated or lying block can never make us read past it.
struct Tiff {
  const uint8_t* p;
  size_t n;
  bool le;  // "II": least significant byte first; "MM": most significant first
  bool fits(uint64_t off, uint64_t len) const { return off <= n && len <= n - off; }
  bool u16(uint64_t off, uint32_t* v) const {
    if (!fits(off, 2)) return false;
    *v = le ? p[off] | (p[off + 1] << 8) : (p[off] << 8) | p[off + 1];
    return true;
  }
  bool u32(uint64_t off, uint32_t* v) const {
    if (!fits(off, 4)) return false;
    uint32_t a, b;
    u16(off, &a);
    u16(off + 2, &b);
    *v = le ? a | (b << 16) : (a << 16) | b;
    return true;
  }
};

// TIFF field types this reader understands (TIFF 6.0 §2): SHORT = u16, LONG = u32,
// RATIONAL = two u32 (numerator, denominator) stored at an offset, since 8 bytes do not fit in
// the entry's 4-byte value field.
constexpr uint32_t kShort = 3, kLong = 4, kRational = 5;

// The first value of the entry at `entry` as a number; false (and a note) for another type, a
// zero count, a zero denominator or a value outside the block.
bool entry_number(const Tiff& t, uint64_t entry, uint32_t tag, double* out,
                  std::vector<std::string>& notes) {
  uint32_t type = 0, count = 0, v = 0;
  t.u16(entry + 2, &type);
  t.u32(entry + 4, &count);
  if (count == 0) {
    notes.push_back(fmt::format("EXIF tag 0x{:04X} has no value: ignored", tag));
    return false;
  }
  if (type == kShort && t.u16(entry + 8, &v)) { *out = v; return true; }
  if (type == kLong && t.u32(entry + 8, &v)) { *out = v; return true; }
  if (type == kRational) {
    uint32_t off = 0, num = 0, den = 0;
    t.u32(entry + 8, &off);
    if (!t.u32(off, &num) || !t.u32(uint64_t(off) + 4, &den)) {
      notes.push_back(fmt::format("EXIF tag 0x{:04X}: its value at offset {} lies past the end of "
                                  "the {}-byte block (truncated): ignored", tag, off, t.n));
      return false;
    }
    if (den == 0) {
      notes.push_back(fmt::format("EXIF tag 0x{:04X} is {}/0: ignored", tag, num));
      return false;
    }
    *out = double(num) / den;
    return true;
  }
  notes.push_back(fmt::format("EXIF tag 0x{:04X} has type {}, expected SHORT, LONG or RATIONAL: "
                              "ignored", tag, type));
  return false;
}

// Calls f(tag, entry offset) for each entry of the IFD at `off` that lies inside the block.
// A truncated IFD adds a note and reads the entries that are there.
template <class F>
void for_each_entry(const Tiff& t, uint32_t off, const char* name,
                    std::vector<std::string>& notes, F f) {
  uint32_t count = 0;
  if (!t.u16(off, &count)) {
    notes.push_back(fmt::format("EXIF {} at offset {} lies past the end of the {}-byte block "
                                "(truncated or corrupt): ignored", name, off, t.n));
    return;
  }
  for (uint32_t k = 0; k < count; ++k) {
    const uint64_t entry = uint64_t(off) + 2 + 12 * uint64_t(k);
    if (!t.fits(entry, 12)) {
      notes.push_back(fmt::format("EXIF {} is truncated: {} entries announced, {} in the block; "
                                  "the rest ignored", name, count, k));
      return;
    }
    uint32_t tag = 0;
    t.u16(entry, &tag);
    f(tag, entry);
  }
}

uint32_t be16(const std::string& b, size_t i) { return (uint8_t(b[i]) << 8) | uint8_t(b[i + 1]); }

}  // namespace

ExifInfo parse_exif_tiff(const uint8_t* p, size_t n) {
  ExifInfo e;
  if (n < 8) {
    e.notes.push_back(fmt::format("EXIF block of {} bytes is too short for its 8-byte header "
                                  "(truncated): ignored", n));
    return e;
  }
  Tiff t{p, n, p[0] == 'I'};
  const bool mark_ok = (p[0] == 'I' && p[1] == 'I') || (p[0] == 'M' && p[1] == 'M');
  uint32_t magic = 0, ifd0 = 0;
  t.u16(2, &magic);
  if (!mark_ok || magic != 42) {
    e.notes.push_back(fmt::format("EXIF block starts {:02X} {:02X} {:02X} {:02X}, expected \"II\" "
                                  "or \"MM\" and 42 (a byte-order mark): ignored",
                                  p[0], p[1], p[2], p[3]));
    return e;
  }
  t.u32(4, &ifd0);
  // Offsets already read: an IFD pointer back to one of them is a loop (a crafted or broken
  // file), never followed again.
  std::vector<uint32_t> visited = {ifd0};
  uint32_t entries = 0;
  if (!t.u16(ifd0, &entries)) {
    e.notes.push_back(fmt::format("EXIF IFD0 at offset {} lies past the end of the {}-byte block "
                                  "(truncated or corrupt): ignored", ifd0, n));
    return e;
  }
  e.present = true;
  uint32_t exif_ifd = 0;
  bool has_exif_ifd = false;
  for_each_entry(t, ifd0, "IFD0", e.notes, [&](uint32_t tag, uint64_t entry) {
    double v = 0;
    if (tag == 0x0112 && entry_number(t, entry, tag, &v, e.notes)) {
      if (v >= 1 && v <= 8) e.orientation = int(v);
      else e.notes.push_back(fmt::format("EXIF orientation {} is not 1-8: taken as 1 (upright)", v));
    } else if (tag == 0x8769) {
      has_exif_ifd = t.u32(entry + 8, &exif_ifd);
    }
  });
  if (has_exif_ifd) {
    if (std::find(visited.begin(), visited.end(), exif_ifd) != visited.end()) {
      e.notes.push_back(fmt::format("EXIF IFD pointer {} points back at IFD0 (a loop): ignored",
                                    exif_ifd));
      return e;
    }
    visited.push_back(exif_ifd);
    for_each_entry(t, exif_ifd, "Exif IFD", e.notes, [&](uint32_t tag, uint64_t entry) {
      double v = 0;
      switch (tag) {
        case 0xA405: if (entry_number(t, entry, tag, &v, e.notes)) e.focal35_mm = v; break;
        case 0x920A: if (entry_number(t, entry, tag, &v, e.notes)) e.focal_mm = v; break;
        case 0xA20E: if (entry_number(t, entry, tag, &v, e.notes)) e.plane_xres = v; break;
        case 0xA210:
          if (entry_number(t, entry, tag, &v, e.notes)) {
            // EXIF 2.3: 2 inch, 3 cm; 4 mm and 5 µm are written by some makers too.
            const double mm[] = {0, 0, 25.4, 10, 1, 1e-3};
            e.plane_unit_mm = v >= 2 && v <= 5 ? mm[int(v)] : 0;
          }
          break;
        case 0xA002: if (entry_number(t, entry, tag, &v, e.notes)) e.pixel_x = int(std::min(v, 1e9)); break;
        case 0xA003: if (entry_number(t, entry, tag, &v, e.notes)) e.pixel_y = int(std::min(v, 1e9)); break;
        default: break;
      }
    });
  }
  return e;
}

ExifInfo read_exif_from_jpeg(const std::string& b) {
  const size_t n = b.size();
  if (n < 4 || uint8_t(b[0]) != 0xFF || uint8_t(b[1]) != 0xD8) return {};
  // The marker segments before the image data (SOS): FF, marker, u16 big-endian length
  // (counting itself), payload. EXIF is APP1 (FF E1) whose payload starts "Exif\0\0".
  size_t i = 2;
  while (i + 4 <= n) {
    if (uint8_t(b[i]) != 0xFF) break;  // not a marker: a corrupt file, stb will say so
    size_t m = i + 1;
    while (m < n && uint8_t(b[m]) == 0xFF) ++m;  // fill bytes
    if (m + 2 >= n) break;
    const uint8_t marker = uint8_t(b[m]);
    if (marker == 0xDA || marker == 0xD9) break;  // image data or end: no EXIF after this
    if ((marker >= 0xD0 && marker <= 0xD7) || marker == 0x01) { i = m + 1; continue; }
    const size_t len = be16(b, m + 1);
    if (len < 2 || m + 1 + len > n) {
      ExifInfo e;
      e.notes.push_back(fmt::format("JPEG segment FF{:02X} of {} bytes runs past the end of the "
                                    "file: EXIF not read", marker, len));
      return e;
    }
    const size_t payload = m + 3, plen = len - 2;
    if (marker == 0xE1 && plen >= 6 && b.compare(payload, 6, std::string("Exif\0\0", 6)) == 0)
      return parse_exif_tiff(reinterpret_cast<const uint8_t*>(b.data()) + payload + 6, plen - 6);
    i = m + 1 + len;
  }
  return {};
}

double exif_focal_px(const ExifInfo& e, int long_side, std::string* how) {
  if (e.focal35_mm > 0) {
    // 35 mm film is 36 mm wide (its long side): the same field of view across long_side pixels.
    if (how) *how = fmt::format("exif {:g} mm (35 mm equivalent)", e.focal35_mm);
    return e.focal35_mm / 36.0 * long_side;
  }
  if (e.focal_mm > 0 && e.plane_xres > 0 && e.plane_unit_mm > 0 && e.pixel_x > 0) {
    // The sensor's pixels per mm give the focal in the file's pixels; then to long_side.
    const double f_file_px = e.focal_mm * e.plane_xres / e.plane_unit_mm;
    if (how) *how = fmt::format("exif {:g} mm lens on a sensor of {:g} px/mm", e.focal_mm,
                                e.plane_xres / e.plane_unit_mm);
    return f_file_px * long_side / std::max(e.pixel_x, e.pixel_y);
  }
  if (how)
    *how = e.focal_mm > 0 ? fmt::format("exif FocalLength {:g} mm, but no 35 mm equivalent or "
                                        "sensor size to turn it into pixels: not used",
                                        e.focal_mm)
                          : "";
  return 0;
}

namespace {
struct TiffWriter {
  bool le;
  std::string s;
  void u16(uint32_t v) {
    if (le) { s += char(v & 0xFF); s += char(v >> 8 & 0xFF); }
    else { s += char(v >> 8 & 0xFF); s += char(v & 0xFF); }
  }
  void u32(uint32_t v) {
    if (le) { u16(v & 0xFFFF); u16(v >> 16); }
    else { u16(v >> 16); u16(v & 0xFFFF); }
  }
  void entry(uint32_t tag, uint32_t type, uint32_t count, uint32_t value) {
    u16(tag); u16(type); u32(count);
    if (type == kShort && count == 1) { u16(value); u16(0); }  // left-justified in 4 bytes
    else u32(value);
  }
};
}  // namespace

std::string make_exif_tiff(bool little_endian, int orientation, int focal35_mm, double focal_mm) {
  TiffWriter w{little_endian, {}};
  w.s += little_endian ? "II" : "MM";
  w.u16(42);
  w.u32(8);  // IFD0 right after the header
  const bool exif = focal35_mm > 0 || focal_mm > 0;
  const uint32_t n0 = (orientation > 0) + exif;
  const uint32_t exif_off = 8 + 2 + 12 * n0 + 4;
  const uint32_t n1 = (focal35_mm > 0) + (focal_mm > 0);
  const uint32_t data_off = exif_off + 2 + 12 * n1 + 4;  // the RATIONAL's 8 bytes
  w.u16(n0);
  if (orientation > 0) w.entry(0x0112, kShort, 1, uint32_t(orientation));
  if (exif) w.entry(0x8769, kLong, 1, exif_off);
  w.u32(0);  // no next IFD
  if (exif) {
    w.u16(n1);  // entries in increasing tag order, as TIFF asks
    if (focal_mm > 0) w.entry(0x920A, kRational, 1, data_off);
    if (focal35_mm > 0) w.entry(0xA405, kShort, 1, uint32_t(focal35_mm));
    w.u32(0);
    if (focal_mm > 0) { w.u32(uint32_t(focal_mm * 1000 + 0.5)); w.u32(1000); }
  }
  return w.s;
}

// Returns `jpeg` unchanged when it is not a JPEG or the block is too big for one segment.
std::string jpeg_with_exif(const std::string& jpeg, const std::string& tiff) {
  const size_t len = 2 + 6 + tiff.size();  // the length field counts itself
  if (jpeg.size() < 2 || uint8_t(jpeg[0]) != 0xFF || uint8_t(jpeg[1]) != 0xD8 || len > 0xFFFF)
    return jpeg;
  std::string app1 = "\xFF\xE1";
  app1 += char(len >> 8);
  app1 += char(len & 0xFF);
  app1 += std::string("Exif\0\0", 6) + tiff;
  return jpeg.substr(0, 2) + app1 + jpeg.substr(2);
}

}  // namespace hashcc
