// core/exif.h — the few EXIF tags a photo folder needs: which way up the photo is, and its lens.
//
// A JPEG from a phone or camera carries an APP1 segment "Exif\0\0" followed by a TIFF block:
//   bytes 0-1  "II" (little-endian, Intel) or "MM" (big-endian, Motorola)
//   bytes 2-3  42
//   bytes 4-7  offset of IFD0 (offsets count from the start of the TIFF block)
// An IFD is a u16 entry count, then 12-byte entries (tag u16, type u16, count u32, value u32 —
// the value itself when it fits in 4 bytes, else the offset of the value), then the offset of
// the next IFD. We read IFD0 (Orientation, and the pointer 0x8769 to the Exif IFD) and the Exif
// IFD (the focal lengths, the pixel size). Nothing else is followed.
//
// This reader is hashcc's own (README, "Dependencies": why not libexif/exiv2). It never throws
// and never reads outside the bytes it is given: a bad block (truncated, wrong byte-order mark,
// offsets past the end, an IFD that points back at one already read) is ignored, and `notes`
// says what was wrong so the loader can print it. Fuzzed: tools/fuzz/fuzz_exif.cpp.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

namespace hashcc {

struct ExifInfo {
  bool present = false;      // a TIFF block was found and its IFD0 read
  int orientation = 1;       // 0x0112, 1..8 (EXIF 2.3 §4.6.4); 1 when absent or out of range
  double focal35_mm = 0;     // 0xA405 FocalLengthIn35mmFilm, mm; 0 = absent
  double focal_mm = 0;       // 0x920A FocalLength (the real lens), mm; 0 = absent
  double plane_xres = 0;     // 0xA20E FocalPlaneXResolution: sensor pixels per unit; 0 = absent
  double plane_unit_mm = 0;  // 0xA210 FocalPlaneResolutionUnit in mm (2 inch, 3 cm, 4 mm, 5 µm)
  int pixel_x = 0, pixel_y = 0;    // 0xA002/0xA003 PixelX/YDimension; 0 = absent
  std::vector<std::string> notes;  // what was wrong with the block, if anything (then ignored)
};

// The Exif block of a JPEG file's bytes (the APP1 "Exif\0\0" segment before the image data).
// Not a JPEG, or no Exif segment: present = false, no notes (a PNG is not an error).
ExifInfo read_exif_from_jpeg(const std::string& bytes);
// The TIFF block itself (from its "II"/"MM"), as found after "Exif\0\0".
ExifInfo parse_exif_tiff(const uint8_t* p, size_t n);

// True for orientations 5-8: the photo is stored on its side, so it displays H wide, W high.
inline bool orientation_swaps_axes(int orientation) { return orientation >= 5 && orientation <= 8; }

// The starting focal in pixels, along the image's longer side of `long_side` pixels (as
// displayed, after any downscale), from the EXIF lens, or 0 when the block does not say.
//  - FocalLengthIn35mmFilm: the focal a 36×24 mm film frame would need for the same field of
//    view. Convention here: the frame's long side is 36 mm, so f_px = f35 / 36 · long_side.
//    (Makers that match the diagonal instead, 43.3 mm, agree with this for 3:2 photos; for 4:3
//    photos the diagonal rule gives a focal 4% longer. It is a start: the focal is learned.)
//  - else FocalLength with the sensor's pixel pitch (FocalPlaneXResolution, its unit and
//    PixelXDimension): f_px = f_mm · (pixels per mm) · long_side / PixelXDimension.
// *how says which ("exif 26 mm (35 mm equivalent)", …).
double exif_focal_px(const ExifInfo& e, int long_side, std::string* how = nullptr);

// Writes an Exif APP1 segment's TIFF block (tests and the simulator's JPEG writer): orientation
// (0 = no tag), focal35 (0 = no tag); little_endian picks "II" or "MM".
std::string make_exif_tiff(bool little_endian, int orientation, int focal35_mm,
                           double focal_mm = 0);
// `jpeg` (a complete JPEG file) with an APP1 Exif segment holding `tiff` inserted after SOI.
std::string jpeg_with_exif(const std::string& jpeg, const std::string& tiff);

}  // namespace hashcc
