// core/stb_impl.cpp — the one translation unit holding stb_image / stb_image_write (Debian's
// libstb-dev, v2.27), used only through core/image.cpp.
//
// Kept apart so the sanitizer builds can compile it with -fno-sanitize=signed-integer-overflow,
// shift (CMakeLists.txt, tools/fuzz.sh): stb 2.27's JPEG decoder does int arithmetic on
// corrupt coefficients that overflows (fuzz finding image/crash-67c1e263: stb_image.h:2197
// "-65579 * 32896 cannot be represented in type 'int'"; fixed upstream in 2.28, not in Debian).
// The result is a wrong pixel in a corrupt file, never a memory error — and memory errors stay
// fully checked (ASan and the rest of UBSan are on). The other stb 2.27 bugs the fuzzer found
// are stopped before stb runs, in core/image.cpp's front-end checks.
#define STB_IMAGE_IMPLEMENTATION
// Only the formats hashcc accepts (is_image_filename): stb's PSD/GIF/HDR/PIC/PNM decoders are
// attack surface a photo folder never needs.
#define STBI_ONLY_PNG
#define STBI_ONLY_JPEG
#define STBI_ONLY_BMP
#define STBI_ONLY_TGA
#define STBI_NO_STDIO_BUFFER_HACK
#include <stb_image.h>
#define STB_IMAGE_WRITE_IMPLEMENTATION
#include <stb_image_write.h>
// stb_image_resize (v1, libstb-dev): the area (box) filter of --max-side (core/image.cpp).
#define STB_IMAGE_RESIZE_IMPLEMENTATION
#include <stb_image_resize.h>
