// Reliability (docs/reliability.md): bad input ends with exit status 2 and one line naming the file or flag
// and the problem, leaves no run folder behind; every kept fuzz input parses or is a clean
// hashcc::Error; a training process killed (SIGKILL) or interrupted (SIGINT) at random points
// leaves a loadable checkpoint and `--resume` ends with the parameters of an uninterrupted run.
// Loader cases already covered in test_io.cpp (missing folder, truncated npy, corrupt PNG,
// mixed sizes, count mismatch, one image, empty folder) are not repeated here.
#include <catch2/catch.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <functional>
#include <array>
#include <csignal>
#include <cstdio>
#include <fcntl.h>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>
#include <sys/wait.h>
#include <thread>
#include <tuple>
#include <unistd.h>

#include "core/error.h"
#include "core/fileio.h"
#include "core/image.h"
#include "core/llff.h"
#include "core/npy.h"
#include "train/checkpoint.h"
#include "train/trainer.h"
#include "tools/cli.h"
#include "tools/fuzz/targets.h"
#include "tools/simulator.h"
#include "test/fixtures.h"
#include "test/shared_data.h"

#define STB_IMAGE_WRITE_STATIC
#define STB_IMAGE_WRITE_IMPLEMENTATION
#include <stb_image_write.h>

namespace fs = std::filesystem;
using namespace hashcc;

namespace {

std::string read_bytes(const std::string& path) { return read_file_bytes(path, int64_t(1) << 32); }
void write_bytes(const std::string& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary | std::ios::trunc) << bytes;
}

struct CliResult {
  int status;
  std::string err;  // what went to stderr
  int lines() const { return int(std::count(err.begin(), err.end(), '\n')); }
};

// Runs the CLI in-process with stderr captured (fd 2 redirected to a file meanwhile).
CliResult cli(std::vector<std::string> args) {
  args.insert(args.begin(), "hashcc");
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  std::string errfile = (fs::temp_directory_path() / "hashcc_rel_stderr.txt").string();
  std::fflush(stderr);
  int saved = ::dup(2);
  int fd = ::open(errfile.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  ::dup2(fd, 2);
  ::close(fd);
  int status = run_cli(int(argv.size()), argv.data());
  std::fflush(stderr);
  ::dup2(saved, 2);
  ::close(saved);
  return {status, read_bytes(errfile)};
}

// Bad input: exit 2, exactly one line, naming `what` (the file or flag) and the problem.
void require_bad(const CliResult& r, const std::string& what, const std::string& problem) {
  INFO("stderr: " << r.err);
  REQUIRE(r.status == 2);
  CHECK(r.lines() <= 2);  // the reason (+ "run 'hashcc --help'" for flag errors)
  CHECK(r.err.find(what) != std::string::npos);
  CHECK(r.err.find(problem) != std::string::npos);
}

std::string small_sim(const std::string& name, int views = 4, int w = 32, int h = 24) {
  std::string d = test::fresh_dir(name);
  SimOptions o;
  o.views = views;
  o.width = w;
  o.height = h;
  o.supersample = 1;
  write_sim_scene(d, o, false);
  return d;
}

// ---- a minimal PNG writer (stored deflate blocks), for the bit depths stb cannot write ----
uint32_t crc32(const std::string& s) {
  uint32_t c = 0xFFFFFFFFu;
  for (unsigned char ch : s) {
    c ^= ch;
    for (int k = 0; k < 8; ++k) c = (c >> 1) ^ (0xEDB88320u & (0u - (c & 1u)));
  }
  return ~c;
}
void put_be32(std::string& s, uint32_t v) {
  for (int k = 3; k >= 0; --k) s += char((v >> (8 * k)) & 0xFF);
}
std::string png_chunk(const std::string& type, const std::string& data) {
  std::string out;
  put_be32(out, uint32_t(data.size()));
  out += type + data;
  put_be32(out, crc32(type + data));
  return out;
}
std::string zlib_stored(const std::string& raw) {
  std::string z = "\x78\x01";
  for (size_t i = 0; i == 0 || i < raw.size(); i += 65535) {
    size_t n = std::min<size_t>(65535, raw.size() - i);
    z += char(i + n >= raw.size() ? 1 : 0);
    z += char(n & 0xFF);
    z += char(n >> 8);
    z += char(~n & 0xFF);
    z += char((~n >> 8) & 0xFF);
    z += raw.substr(i, n);
  }
  uint32_t a = 1, b = 0;
  for (unsigned char ch : raw) { a = (a + ch) % 65521; b = (b + a) % 65521; }
  put_be32(z, (b << 16) | a);
  return z;
}
// samples: row-major, channels of colour type ctype (0 grey, 2 RGB, 4 grey+alpha, 6 RGBA).
std::string png_bytes(int w, int h, int depth, int ctype, const std::vector<uint16_t>& samples) {
  const int ch = ctype == 0 ? 1 : ctype == 2 ? 3 : ctype == 4 ? 2 : 4;
  REQUIRE(samples.size() == size_t(w) * h * ch);
  std::string raw;
  for (int y = 0; y < h; ++y) {
    raw += char(0);  // filter: none
    for (int i = 0; i < w * ch; ++i) {
      uint16_t v = samples[size_t(y) * w * ch + i];
      if (depth == 16) raw += char(v >> 8);
      raw += char(v & 0xFF);
    }
  }
  std::string ihdr;
  put_be32(ihdr, uint32_t(w));
  put_be32(ihdr, uint32_t(h));
  ihdr += char(depth);
  ihdr += char(ctype);
  ihdr += std::string(3, '\0');
  return std::string("\x89PNG\r\n\x1a\n", 8) + png_chunk("IHDR", ihdr) +
         png_chunk("IDAT", zlib_stored(raw)) + png_chunk("IEND", "");
}

std::string jpg_bytes(int w, int h) {
  std::vector<uint8_t> px(size_t(w) * h * 3);
  for (size_t i = 0; i < px.size(); ++i) px[i] = uint8_t((i * 7) % 251);
  std::string out;
  stbi_write_jpg_to_func([](void* ctx, void* data, int size) {
    static_cast<std::string*>(ctx)->append(static_cast<char*>(data), size_t(size));
  }, &out, w, h, 3, px.data(), 90);
  return out;
}

uint8_t to8(uint16_t v) { return uint8_t((v * 255u + 32767u) / 65535u); }

// ---- a minimal JPEG writer, for the kinds stb cannot write (progressive, CMYK) ----------------
// Every 8×8 block is one flat colour, so only DC coefficients are non-zero: with a quantisation
// table of ones, a flat block of sample v has DC = 8·(v − 128) exactly and decodes back to v
// (±1 of the decoder's IDCT rounding). Huffman tables: DC categories 0–11 as 4-bit codes
// (code = category), AC a single 1-bit code for end-of-block. That is all a valid baseline
// (SOF0) or progressive (SOF2) file of flat blocks needs, in a few hundred bytes.
struct JpegBits {
  std::string out;
  uint32_t acc = 0;
  int n = 0;
  void put(uint32_t v, int len) {
    for (int i = len - 1; i >= 0; --i) {
      acc = (acc << 1) | ((v >> i) & 1u);
      if (++n == 8) {
        out += char(acc);
        if (acc == 0xFF) out += '\0';  // byte stuffing: FF in entropy-coded data is FF 00
        acc = 0;
        n = 0;
      }
    }
  }
  void flush() { while (n) put(1, 1); }  // pad the last byte with 1 bits
  void dc(int diff) {                    // category, then the diff's bits (negatives: diff − 1)
    int cat = 0;
    for (int a = std::abs(diff); a; a >>= 1) ++cat;
    put(uint32_t(cat), 4);
    if (cat) put(uint32_t(diff >= 0 ? diff : diff + (1 << cat) - 1), cat);
  }
};
void put_be16(std::string& s, size_t v) { s += char((v >> 8) & 0xFF); s += char(v & 0xFF); }
void jpeg_segment(std::string& o, uint8_t marker, const std::string& body) {
  o += '\xFF';
  o += char(marker);
  put_be16(o, body.size() + 2);
  o += body;
}
// w, h: multiples of 8; comps: 1 (grey), 3 (YCbCr) or 4 (CMYK, with Adobe's APP14 marker,
// transform 0, as Photoshop writes it); block(bx, by) gives the components' samples.
std::string jpeg_flat(int w, int h, int comps, bool progressive,
                      const std::function<std::array<int, 4>(int, int)>& block) {
  REQUIRE(w % 8 == 0);
  REQUIRE(h % 8 == 0);
  std::string o = "\xFF\xD8";
  if (comps == 4) jpeg_segment(o, 0xEE, std::string("Adobe\0\x64\0\0\0\0\0", 12));
  jpeg_segment(o, 0xDB, std::string(1, '\0') + std::string(64, '\1'));  // table 0: all ones
  std::string sof(1, '\x08');
  put_be16(sof, size_t(h));
  put_be16(sof, size_t(w));
  sof += char(comps);
  for (int c = 0; c < comps; ++c) sof += std::string{char(c + 1), '\x11', '\0'};  // 1×1, table 0
  jpeg_segment(o, progressive ? 0xC2 : 0xC0, sof);
  std::string dht = std::string{'\x00', 0, 0, 0, 12} + std::string(12, '\0');  // DC 0: 12 × 4 bits
  for (int k = 0; k < 12; ++k) dht += char(k);
  dht += std::string{'\x10', 1} + std::string(15, '\0') + std::string(1, '\0');  // AC 0: EOB, 1 bit
  jpeg_segment(o, 0xC4, dht);
  auto scan = [&](const std::vector<int>& cs, int ss, int se, bool ac) {
    std::string sos(1, char(cs.size()));
    for (int c : cs) sos += std::string{char(c + 1), '\0'};
    sos += std::string{char(ss), char(se), '\0'};
    jpeg_segment(o, 0xDA, sos);
    JpegBits b;
    std::array<int, 4> pred = {0, 0, 0, 0};
    for (int by = 0; by < h / 8; ++by)
      for (int bx = 0; bx < w / 8; ++bx) {
        const std::array<int, 4> v = block(bx, by);
        for (int c : cs) {
          if (ss == 0) {
            const int dc = 8 * (v[size_t(c)] - 128);
            b.dc(dc - pred[size_t(c)]);
            pred[size_t(c)] = dc;
          }
          if (ac) b.put(0, 1);  // end of block: every AC coefficient is 0
        }
      }
    b.flush();
    o += b.out;
  };
  std::vector<int> all;
  for (int c = 0; c < comps; ++c) all.push_back(c);
  if (!progressive) {
    scan(all, 0, 63, true);
  } else {  // a DC scan of all components, then one AC scan (1–63) per component
    scan(all, 0, 0, false);
    for (int c = 0; c < comps; ++c) scan({c}, 1, 63, true);
  }
  return o + "\xFF\xD9";
}
// The JFIF YCbCr of an RGB colour (what a camera's JPEG stores).
std::array<int, 4> ycbcr(int r, int g, int b) {
  auto q = [](double x) { return int(std::lround(std::clamp(x, 0.0, 255.0))); };
  return {q(0.299 * r + 0.587 * g + 0.114 * b), q(-0.168736 * r - 0.331264 * g + 0.5 * b + 128),
          q(0.5 * r - 0.418688 * g - 0.081312 * b + 128), 0};
}

}  // namespace

TEST_CASE("reliability: non-image files are skipped with a note; a .png that is not a PNG is an error",
          "[reliability][io]") {
  // Decision: the loader reads files with an image extension (png, jpg, jpeg, bmp, tga) and
  // skips everything else (notes, Thumbs.db, sidecar files), listing them in a one-line note;
  // hidden files are skipped silently. A file with an image extension that does not decode is
  // an error: it is almost certainly a photo that was damaged, not a file to ignore.
  std::string d = small_sim("nonimage");
  write_bytes(d + "/images/notes.txt", "shot on a tripod");
  write_bytes(d + "/images/Thumbs.db", std::string(64, '\0'));
  write_bytes(d + "/images/.DS_Store", "junk");
  fs::create_directories(d + "/images/raw");
  Scene sc = load_scene(d);
  CHECK(sc.names.size() == 4);
  CHECK(sc.ignored == std::vector<std::string>{"Thumbs.db", "notes.txt"});
  CHECK_THAT(ignored_files_note(sc), Catch::Contains("ignored 2 non-image files") &&
                                         Catch::Contains("notes.txt"));
  CHECK(cli({"info", "--data", d}).status == 0);

  write_bytes(d + "/images/image004.png", "this is a text file renamed to .png\n");
  REQUIRE_THROWS_WITH(load_scene(d), Catch::Contains("image004.png") &&
                                         Catch::Contains("not an image"));
  require_bad(cli({"info", "--data", d}), "image004.png", "not an image");
}

TEST_CASE("reliability: zero-byte and truncated JPGs are errors naming the file", "[reliability][io]") {
  std::string d = test::fresh_dir("jpg");
  const std::string good = jpg_bytes(16, 12);
  for (int i = 0; i < 3; ++i) write_bytes(fmt::format("{}/v{}.jpg", d, i), good);
  Scene sc = load_scene(d);
  REQUIRE(sc.names.size() == 3);
  CHECK(sc.width == 16);

  write_bytes(d + "/v1.jpg", "");
  REQUIRE_THROWS_WITH(read_image(d + "/v1.jpg"), Catch::Contains("empty file"));
  require_bad(cli({"info", "--data", d}), "v1.jpg", "empty file");

  for (double frac : {0.3, 0.6, 0.95}) {
    write_bytes(d + "/v1.jpg", good.substr(0, size_t(good.size() * frac)));
    INFO("truncated to " << frac);
    REQUIRE_THROWS_WITH(read_image(d + "/v1.jpg"), Catch::Contains("v1.jpg") &&
                                                        Catch::Contains("truncated"));
    require_bad(cli({"info", "--data", d}), "v1.jpg", "truncated");
  }
}

TEST_CASE("reliability: 16-bit, RGBA, grey and grey+alpha PNGs load as 8-bit RGB", "[reliability][io]") {
  std::string d = test::fresh_dir("pngkinds");
  SECTION("16-bit RGB: rounded to 8 bits") {
    std::vector<uint16_t> s = {0, 65535, 32896, 2570, 1000, 65000};
    write_bytes(d + "/a.png", png_bytes(2, 1, 16, 2, s));
    ImageU8 im = read_image(d + "/a.png");
    REQUIRE(im.width == 2);
    REQUIRE(im.height == 1);
    for (int i = 0; i < 6; ++i) CHECK(int(im.rgb[i]) == int(to8(s[i])));
    CHECK(im.rgb[1] == 255);
    CHECK(im.rgb[3] == 10);  // 2570 = 10 · 257
  }
  SECTION("16-bit grey: replicated") {
    std::vector<uint16_t> s = {0, 30000, 65535};
    write_bytes(d + "/g.png", png_bytes(3, 1, 16, 0, s));
    ImageU8 im = read_image(d + "/g.png");
    for (int x = 0; x < 3; ++x)
      for (int c = 0; c < 3; ++c) CHECK(int(im.rgb[3 * x + c]) == int(to8(s[x])));
  }
  SECTION("8-bit RGBA: alpha dropped, colour kept as stored") {
    std::vector<uint16_t> s = {10, 20, 30, 0, 200, 100, 50, 255};
    write_bytes(d + "/r.png", png_bytes(2, 1, 8, 6, s));
    ImageU8 im = read_image(d + "/r.png");
    CHECK(im.rgb == std::vector<uint8_t>{10, 20, 30, 200, 100, 50});
  }
  SECTION("8-bit grey and grey+alpha: replicated") {
    write_bytes(d + "/g8.png", png_bytes(2, 1, 8, 0, {7, 250}));
    CHECK(read_image(d + "/g8.png").rgb == std::vector<uint8_t>{7, 7, 7, 250, 250, 250});
    write_bytes(d + "/ga.png", png_bytes(2, 1, 8, 4, {9, 0, 99, 128}));
    CHECK(read_image(d + "/ga.png").rgb == std::vector<uint8_t>{9, 9, 9, 99, 99, 99});
  }
  SECTION("a scene of 16-bit PNGs loads and trains from 8-bit pixels") {
    std::vector<uint16_t> s(8 * 6 * 3);
    for (size_t i = 0; i < s.size(); ++i) s[i] = uint16_t(i * 1361);
    for (int i = 0; i < 3; ++i) write_bytes(fmt::format("{}/p{}.png", d, i), png_bytes(8, 6, 16, 2, s));
    Scene sc = load_scene(d);
    REQUIRE(sc.images.size() == 3);
    CHECK(sc.images[2].rgb.size() == 8 * 6 * 3);  // 3 bytes a pixel
    CHECK(int(sc.images[2].rgb[5]) == int(to8(s[5])));
  }
}

namespace {

// A folder of n good 24×16 PNGs v0.png … (each a different gradient), for the bad-photo matrix.
std::string photo_folder(const std::string& name, int n = 4, int w = 24, int h = 16) {
  std::string d = test::fresh_dir(name);
  for (int i = 0; i < n; ++i) {
    std::vector<uint8_t> px(size_t(w) * h * 3);
    for (size_t k = 0; k < px.size(); ++k) px[k] = uint8_t((k * (3 + i) + 40 * i) % 256);
    write_png(fmt::format("{}/v{}.png", d, i), px.data(), w, h);
  }
  return d;
}
std::vector<uint8_t> flat_rgb(int w, int h, uint8_t v) { return std::vector<uint8_t>(size_t(w) * h * 3, v); }

// One row of the matrix: how the folder is spoiled, and what `hashcc info` must then say. An
// empty `file` means the folder loads (exit 0); `check` then looks at the decoded pixels.
struct BadPhoto {
  std::string name;
  std::function<void(const std::string& dir)> spoil;
  std::string file, problem, accepted;  // the one line: file, what is wrong, what is accepted
  std::function<void(const Scene&)> check = nullptr;
};

// Four flat blocks per 24×16 JPEG (3×2 blocks): the colours a decoder must reproduce.
const int kBlockRGB[6][3] = {{200, 30, 40}, {20, 180, 60}, {30, 40, 220},
                             {250, 250, 250}, {0, 0, 0}, {128, 100, 60}};

}  // namespace

TEST_CASE("reliability: a bad-photo matrix — each folder loads or stops with one line naming "
          "the file, what is wrong and what is accepted", "[reliability][io][photos]") {
  // The photos a user's folder really holds (issue 52). The base folder is four good 24×16
  // PNGs; each row changes one thing. Every row runs `hashcc info` (header + pixel decode, no
  // training: well under a second) and, for the refusals, load_scene must throw hashcc::Error —
  // anything else (a crash, std::filesystem_error as "internal error", exit 1) fails here.
  const std::vector<BadPhoto> rows = {
      {"truncated JPEG (cut before its end-of-image marker)",
       [](const std::string& d) {
         fs::remove(d + "/v1.png");
         std::string j = jpeg_flat(24, 16, 3, false, [](int bx, int by) {
           const int* c = kBlockRGB[by * 3 + bx];
           return ycbcr(c[0], c[1], c[2]);
         });
         write_bytes(d + "/v1.jpg", j.substr(0, j.size() - 2));
       },
       "v1.jpg", "truncated JPEG (no end-of-image marker)", "a complete JPEG file"},
      {"truncated JPEG (cut inside its header)",
       [](const std::string& d) {
         fs::remove(d + "/v1.png");
         write_bytes(d + "/v1.jpg", jpg_bytes(24, 16).substr(0, 100));
       },
       "v1.jpg", "runs past the end of the file (truncated or corrupt)", "a complete JPEG file"},
      {"a PNG cut in half",
       [](const std::string& d) {
         const std::string b = read_bytes(d + "/v1.png");
         write_bytes(d + "/v1.png", b.substr(0, b.size() / 2));
       },
       "v1.png", "corrupt or truncated image", "a complete PNG, JPG, BMP or TGA file"},
      {"CMYK JPEG (Adobe APP14, inverted as Photoshop stores it): converted to RGB",
       [](const std::string& d) {
         fs::remove(d + "/v1.png");
         // Stored C', M', Y', K' = 255 − ink; RGB = C'·K'/255 etc. (stb's Adobe rule).
         write_bytes(d + "/v1.jpg", jpeg_flat(24, 16, 4, false, [](int bx, int by) {
           const int* c = kBlockRGB[by * 3 + bx];
           return std::array<int, 4>{c[0], c[1], c[2], by == 0 ? 255 : 128};
         }));
       },
       "", "", "",
       [](const Scene& sc) {
         const ImageU8& im = sc.images[1];
         for (int by = 0; by < 2; ++by)
           for (int bx = 0; bx < 3; ++bx)
             for (int c = 0; c < 3; ++c) {
               const int want = (kBlockRGB[by * 3 + bx][c] * (by == 0 ? 255 : 128) + 127) / 255;
               INFO("block " << bx << "," << by << " channel " << c);
               CHECK(std::abs(int(im.rgb[size_t((8 * by + 4) * 24 + 8 * bx + 4) * 3 + c]) - want) <= 2);
             }
       }},
      {"progressive JPEG: decoded like a baseline one",
       [](const std::string& d) {
         fs::remove(d + "/v2.png");
         write_bytes(d + "/v2.jpg", jpeg_flat(24, 16, 3, true, [](int bx, int by) {
           const int* c = kBlockRGB[by * 3 + bx];
           return ycbcr(c[0], c[1], c[2]);
         }));
       },
       "", "", "",
       [](const Scene& sc) {
         const ImageU8& im = sc.images[2];
         for (int by = 0; by < 2; ++by)
           for (int bx = 0; bx < 3; ++bx)
             for (int c = 0; c < 3; ++c) {
               INFO("block " << bx << "," << by << " channel " << c);
               // YCbCr rounding on the way in and out: within 3 levels of the colour written.
               CHECK(std::abs(int(im.rgb[size_t((8 * by + 4) * 24 + 8 * bx + 4) * 3 + c]) -
                              kBlockRGB[by * 3 + bx][c]) <= 3);
             }
       }},
      {"16-bit PNG with alpha: rounded to 8 bits, alpha dropped",
       [](const std::string& d) {
         std::vector<uint16_t> s(24 * 16 * 4);
         for (size_t i = 0; i < s.size(); ++i) s[i] = uint16_t(i % 4 == 3 ? 0 : i * 331);
         write_bytes(d + "/v3.png", png_bytes(24, 16, 16, 6, s));
       },
       "", "", "",
       [](const Scene& sc) {
         const ImageU8& im = sc.images[3];
         for (size_t p = 0; p < 24 * 16; p += 37)
           for (size_t c = 0; c < 3; ++c)
             CHECK(int(im.rgb[3 * p + c]) == int(to8(uint16_t((4 * p + c) * 331))));
       }},
      {"an image turned on its side (16x24 among 24x16)",
       [](const std::string& d) {
         auto px = flat_rgb(16, 24, 90);
         write_png(d + "/v2.png", px.data(), 16, 24);
       },
       "v2.png", "is 16x24 (upright) but v0.png is 24x16", "all images the same size and orientation"},
      {"an image of another size (12x8)",
       [](const std::string& d) {
         auto px = flat_rgb(12, 8, 90);
         write_png(d + "/v2.png", px.data(), 12, 8);
       },
       "v2.png", "is 12x8 (upright) but v0.png is 24x16", "all images the same size and orientation"},
      {"a 1x1 image",
       [](const std::string& d) {
         auto px = flat_rgb(1, 1, 90);
         write_png(d + "/v3.png", px.data(), 1, 1);
       },
       "v3.png", "is 1x1 (upright) but v0.png is 24x16", "all images the same size and orientation"},
      {"a symbolic link loop named like a photo",
       [](const std::string& d) { fs::create_symlink("v9.png", d + "/v9.png"); },
       "v9.png", "is a symbolic link that cannot be followed",
       "a link to an image file, or the file itself"},
      {"a broken symbolic link named like a photo",
       [](const std::string& d) { fs::create_symlink("gone.png", d + "/v8.png"); },
       "v8.png", "is a symbolic link that cannot be followed",
       "a link to an image file, or the file itself"},
      {"a link loop with another name and a link to the folder itself: not photos, loads",
       [](const std::string& d) {
         fs::create_symlink("loop", d + "/loop");
         fs::create_symlink(".", d + "/again");
       },
       "", "", "",
       [](const Scene& sc) { CHECK(sc.names.size() == 4); }},
      {"a .png that is a GIF",
       [](const std::string& d) { write_bytes(d + "/v1.png", std::string("GIF89a\x18\0\x10\0", 10)); },
       "v1.png", "not an image (unrecognised file signature)", "PNG, JPG, BMP or TGA"},
      {"a JPEG named .png: the signature decides, it loads",
       [](const std::string& d) { write_bytes(d + "/v1.png", jpg_bytes(24, 16)); },
       "", "", "",
       [](const Scene& sc) { CHECK(sc.images[1].width == 24); }},
  };
  for (const BadPhoto& row : rows) {
    INFO("row: " << row.name);
    const std::string d = photo_folder("matrix");
    row.spoil(d);
    const CliResult r = cli({"info", "--data", d});
    if (row.file.empty()) {
      INFO("stderr: " << r.err);
      CHECK(r.status == 0);
      const Scene sc = load_scene(d);
      if (row.check) row.check(sc);
    } else {
      require_bad(r, row.file, row.problem);
      CHECK(r.lines() == 1);
      CHECK_THAT(r.err, Catch::Contains("(expected " + row.accepted + ")"));
      CHECK_THROWS_AS(load_scene(d), Error);
    }
  }
}

namespace {

// A camera-less folder of n photos from the simulator (32×24), photo i a copy of
// source[i] (so identical photos are a repeated index).
std::string thin_folder(const std::string& name, const std::vector<int>& source) {
  const std::string sim = small_sim(name + "_src", 4, 32, 24);
  const std::string d = test::fresh_dir(name);
  for (size_t i = 0; i < source.size(); ++i)
    fs::copy_file(fmt::format("{}/images/image{:03d}.png", sim, source[i]),
                  fmt::format("{}/p{}.png", d, i));
  return d;
}

// A run that ended with exit 0 must have learned finite numbers: every loss in log.csv and
// every camera entry in cameras.json (a zero baseline must not turn into a silent NaN).
void require_finite_run(const std::string& out) {
  std::ifstream log(out + "/log.csv");
  std::string line;
  REQUIRE(std::getline(log, line));  // header: step,seconds,loss,...
  int rows = 0;
  while (std::getline(log, line)) {
    const size_t a = line.find(',', line.find(',') + 1), b = line.find(',', a + 1);
    const double loss = std::strtod(line.substr(a + 1, b - a - 1).c_str(), nullptr);
    INFO(line);
    CHECK(std::isfinite(loss));
    ++rows;
  }
  CHECK(rows > 0);
  const auto cams = nlohmann::json::parse(read_bytes(out + "/cameras.json"));
  REQUIRE(cams.contains("frames"));
  for (const auto& f : cams["frames"])
    for (const auto& row : f["transform_matrix"])
      for (const auto& v : row) CHECK(std::isfinite(v.get<double>()));
  CHECK(std::isfinite(cams["fl_x"].get<double>()));
}

}  // namespace

TEST_CASE("reliability: thin folders (2 photos, identical photos, 1x1 photos) train or are "
          "refused with the way out; never a crash, never a NaN", "[reliability][photos][trainer]") {
  const std::string out = (fs::temp_directory_path() / "hashcc_rel_thin_run").string();
  auto train = [&](const std::string& d, std::vector<std::string> extra) {
    fs::remove_all(out);
    // 20 steps: the fewest the default recipe splits into its five stages.
    std::vector<std::string> a = {"train", "--data", d, "--out", out, "--steps", "20",
                                  "--width", "16", "--samples", "16", "--no-progress"};
    a.insert(a.end(), extra.begin(), extra.end());
    return cli(a);
  };
  // Two photos: one trains, one is the test view (every 8th from the first). The default
  // recipe's grid field takes min(4, photos) images a step: it trains, one image a step. The
  // same 4 given by hand is refused in terms of the photos, with the flag to pass; nothing is
  // written. One image a step (--preset paper) trains.
  for (const auto& [name, src] : {std::pair{"two", std::vector<int>{0, 2}},
                                  std::pair{"identical", std::vector<int>{1, 1}}}) {
    INFO(name);
    const std::string d = thin_folder(name, src);
    REQUIRE(train(d, {"--rays", "64"}).status == 0);
    require_finite_run(out);
    const CliResult r = train(d, {"--rays", "64", "--images-per-step", "4"});
    require_bad(r, "--images-per-step", "4 is more than the 1 training image (every 8th photo");
    CHECK_THAT(r.err, Catch::Contains("pass --images-per-step 1"));
    CHECK_FALSE(fs::exists(out));
    REQUIRE(train(d, {"--rays", "64", "--preset", "paper"}).status == 0);
    require_finite_run(out);
  }
  // Three identical photos: two training views with zero baseline, both from identity. The
  // photos agree with any pair of equal cameras: the run must stay finite.
  {
    const std::string d = thin_folder("identical3", {3, 3, 3});
    REQUIRE(train(d, {"--rays", "64", "--preset", "paper", "--images-per-step", "2"}).status == 0);
    require_finite_run(out);
  }
  // Photos of one pixel load (hashcc info says so); the default 32×32 ray grid cannot fit
  // them, and the refusal gives the largest --rays that does. With it, they train.
  {
    const std::string d = test::fresh_dir("pixels");
    for (int i = 0; i < 6; ++i) {
      const uint8_t px[3] = {uint8_t(40 * i), 100, 200};
      write_png(fmt::format("{}/p{}.png", d, i), px, 1, 1);
    }
    CHECK(cli({"info", "--data", d}).status == 0);
    const CliResult r = train(d, {});
    require_bad(r, "--rays", "does not fit 1x1 images");
    CHECK_THAT(r.err, Catch::Contains("(expected --rays 1 or fewer)"));
    CHECK_FALSE(fs::exists(out));
    REQUIRE(train(d, {"--rays", "1", "--preset", "paper"}).status == 0);
    require_finite_run(out);
  }
  fs::remove_all(out);
}

TEST_CASE("reliability: a huge image header is rejected from the header, before allocation",
          "[reliability][io]") {
  std::string d = small_sim("huge");
  // A 100000 × 100000 RGB PNG would need 30 GB; the file is 60 bytes.
  std::string ihdr;
  put_be32(ihdr, 100000);
  put_be32(ihdr, 100000);
  ihdr += std::string("\x08\x02\0\0\0", 5);
  std::string huge = std::string("\x89PNG\r\n\x1a\n", 8) + png_chunk("IHDR", ihdr) +
                     png_chunk("IDAT", zlib_stored("\0\0\0\0")) + png_chunk("IEND", "");
  write_bytes(d + "/huge.png", huge);
  try {
    read_image(d + "/huge.png");
    FAIL("no error");
  } catch (const Error& e) {
    CHECK(e.field == "header");  // from check_header: stb's decoder never ran
    CHECK_THAT(e.what(), Catch::Contains("huge.png") && Catch::Contains("100000x100000") &&
                             Catch::Contains("out of range"));
  }
  fs::copy_file(d + "/huge.png", d + "/images/image001.png", fs::copy_options::overwrite_existing);
  require_bad(cli({"info", "--data", d}), "image001.png", "100000x100000");
}

TEST_CASE("reliability: poses_bounds.npy with a wrong dtype, wrong shape, NaN or Inf", "[reliability][io]") {
  std::string d = small_sim("poses");
  const std::string pb = d + "/poses_bounds.npy";
  const std::string good = read_bytes(pb);
  SECTION("wrong dtype") {
    for (std::string dt : {"<c8", ">f8", "|b1", "<U4"}) {
      std::string bad = good;
      bad.replace(bad.find("<f8"), 3, dt);
      write_bytes(pb, bad);
      INFO(dt);
      require_bad(cli({"info", "--data", d}), "poses_bounds.npy", "unsupported dtype '" + dt + "'");
    }
  }
  SECTION("wrong shape") {
    std::vector<double> v(4 * 15, 1.0);
    write_npy(pb, v.data(), {4, 15});
    require_bad(cli({"info", "--data", d}), "poses_bounds.npy", "has shape (4, 15)");
    std::vector<double> flat(4 * 17, 1.0);
    write_npy(pb, flat.data(), {68});
    require_bad(cli({"info", "--data", d}), "poses_bounds.npy", "has shape (68,)");
  }
  SECTION("NaN and Inf") {
    const size_t data0 = good.size() - 4 * 17 * 8;
    for (double bad_value : {std::nan(""), HUGE_VAL, -HUGE_VAL}) {
      std::string bad = good;
      std::memcpy(bad.data() + data0 + 8 * 20, &bad_value, 8);  // row 1, element 3
      write_bytes(pb, bad);
      INFO(bad_value);
      require_bad(cli({"info", "--data", d}), "poses_bounds.npy", "element 20: non-finite value");
    }
  }
}

TEST_CASE("reliability: a bad checkpoint or config stops `train --resume` with exit 2 and is left as it was",
          "[reliability][cli]") {
  std::string d = small_sim("ckscene");
  std::string run = test::fresh_dir("ckrun");
  fs::remove_all(run);
  REQUIRE(cli({"train", "--data", d, "--out", run, "--steps", "3", "--width", "16", "--rays", "64",
               "--samples", "16", "--threads", "1", "--no-progress", "--preset", "paper"}).status == 0);
  const std::string ck = run + "/checkpoint.bin";
  const std::string good = read_bytes(ck);
  struct Case { const char* name; std::string bytes; const char* problem; };
  std::string version = good, flipped = good;
  version[8] = 7;                        // u32 version after the 8-byte magic
  flipped[good.size() / 2] ^= 0x04;      // one bit in the middle of the parameters
  std::vector<Case> cases = {
      {"truncated", good.substr(0, good.size() - 1000), "truncated"},
      {"zero bytes", "", "not a hashcc checkpoint"},
      {"other version", version, "checkpoint version 7"},
      {"bit-flipped", flipped, "checksum mismatch"},
  };
  for (auto& c : cases) {
    INFO(c.name);
    write_bytes(ck, c.bytes);
    require_bad(cli({"train", "--resume", run}), "checkpoint.bin", c.problem);
    CHECK(read_bytes(ck) == c.bytes);  // not overwritten by the failed resume
  }
  write_bytes(ck, good);
  CHECK(cli({"train", "--resume", run, "--steps", "5"}).status == 0);

  // config.json: out-of-range and wrong-typed values are named, never converted.
  const std::string cfg = run + "/config.json";
  const std::string good_cfg = read_bytes(cfg);
  for (auto [key, value, problem] : {std::tuple{"rays", "1e300", "out of range"},
                                     std::tuple{"samples", "-3", "out of range"},
                                     std::tuple{"width", "16.5", "out of range"},
                                     std::tuple{"ndc", "\"yes\"", "wrong type"}}) {
    auto j = nlohmann::json::parse(good_cfg);
    j[key] = nlohmann::json::parse(value);
    write_bytes(cfg, j.dump());
    INFO(key << " = " << value);
    require_bad(cli({"train", "--resume", run}), std::string("config.json: ") + key, problem);
  }
  write_bytes(cfg, "{ not json");
  require_bad(cli({"train", "--resume", run}), "config.json", "not valid JSON");
}

TEST_CASE("reliability: bad flags and bad scenes exit 2 naming the flag or file; no run folder is left",
          "[reliability][cli]") {
  std::string d = small_sim("flags");
  const std::string out = (fs::temp_directory_path() / "hashcc_rel_flags_run").string();
  auto train = [&](std::vector<std::string> extra) {
    fs::remove_all(out);
    // One stage (--preset paper): this scene has 3 training images, fewer than the 4 a step of
    // the default recipe's grid field takes (that case: test_plan.cpp, the default's test).
    std::vector<std::string> a = {"train", "--data", d, "--out", out, "--steps", "2", "--width",
                                  "16", "--samples", "16", "--no-progress", "--preset", "paper"};
    a.insert(a.end(), extra.begin(), extra.end());
    return cli(a);
  };
  for (auto [flag, value] : {std::pair{"--rays", "0"}, std::pair{"--samples", "1"},
                             std::pair{"--minutes", "-1"}, std::pair{"--threads", "0"},
                             std::pair{"--chunk-rays", "-1"}, std::pair{"--rays", "many"},
                             std::pair{"--lr-net", "nan"}}) {
    INFO(flag << " " << value);
    require_bad(train({flag, value}), flag, value);
    CHECK_FALSE(fs::exists(out));
  }
  require_bad(train({"--no-such-flag"}), "--no-such-flag", "");
  CHECK_FALSE(fs::exists(out));
  // Holding cameras needs cameras to hold: --refine-poses off from identity is refused.
  require_bad(train({"--refine-poses", "off"}), "--refine-poses", "without cameras to start from");
  CHECK_FALSE(fs::exists(out));
  // Valid flag, impossible value for this scene: a 1024×1024 ray grid on 32×24 images.
  require_bad(train({"--rays", "1048576"}), "--rays", "does not fit");
  CHECK_FALSE(fs::exists(out));
  // A scene that fails to load (a corrupt image) creates nothing either.
  write_bytes(d + "/images/image002.png", std::string("\x89PNG\r\n\x1a\n broken", 16));
  require_bad(train({"--rays", "64"}), "image002.png", "corrupt");
  CHECK_FALSE(fs::exists(out));
}

TEST_CASE("reliability: a fresh run in an old run's folder drops the old checkpoint first",
          "[reliability][trainer]") {
  std::string d = small_sim("stale");
  std::string out = test::fresh_dir("stale_run");
  write_bytes(out + "/checkpoint.bin", "an older run's checkpoint");
  write_bytes(out + "/cameras.json", "{}");
  TrainConfig c;
  c.data = d;
  c.out = out;
  c.model.width = 16;
  c.rays = 64;
  c.samples = 16;
  c.steps = 2;
  c.progress = false;
  Trainer t(c);  // a crash right now must not leave this config beside the old checkpoint
  CHECK(fs::exists(out + "/config.json"));
  CHECK_FALSE(fs::exists(out + "/checkpoint.bin"));
  CHECK_FALSE(fs::exists(out + "/cameras.json"));
}

TEST_CASE("reliability: every kept fuzz input parses or fails with hashcc::Error", "[reliability][fuzz]") {
  // test/data/fuzz/<target>/ holds the inputs the fuzzers crashed on (each fixed since);
  // test/data/fuzz/seeds/<target>/ the valid seeds, which must parse.
  const fs::path root = fs::path(test::repo_root()) / "test/data/fuzz";
  const std::vector<std::pair<std::string, bool (*)(const std::string&)>> targets = {
      {"npy", fuzz::npy}, {"checkpoint", fuzz::checkpoint}, {"config", fuzz::config},
      {"image", fuzz::image}, {"exif", fuzz::exif}};
  int replayed = 0;
  for (auto& [name, one] : targets) {
    for (bool seeds : {false, true}) {
      fs::path dir = seeds ? root / "seeds" / name : root / name;
      if (!fs::is_directory(dir)) continue;
      for (auto& e : fs::directory_iterator(dir)) {
        INFO(e.path().string());
        bool ok = one(read_bytes(e.path().string()));  // anything but hashcc::Error fails here
        if (seeds) CHECK(ok);
        ++replayed;
      }
    }
  }
  CHECK(replayed >= 20);
}

// ---- interrupted runs: the real binary, killed and resumed ------------------------------------

namespace {

pid_t spawn(const std::vector<std::string>& args, const std::string& log) {
  std::vector<std::string> a = args;
  a.insert(a.begin(), HASHCC_BINARY);
  std::vector<char*> argv;
  for (auto& s : a) argv.push_back(s.data());
  argv.push_back(nullptr);
  pid_t pid = ::fork();
  if (pid == 0) {
    int fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
    ::dup2(fd, 1);
    ::dup2(fd, 2);
    ::execv(HASHCC_BINARY, argv.data());
    ::_exit(127);
  }
  return pid;
}

// Exit status, or 128 + signal; -1 if still running after timeout_s (then killed).
int wait_for(pid_t pid, double timeout_s) {
  auto t0 = std::chrono::steady_clock::now();
  for (;;) {
    int st = 0;
    pid_t r = ::waitpid(pid, &st, WNOHANG);
    if (r == pid) return WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
    if (std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() > timeout_s) {
      ::kill(pid, SIGKILL);
      ::waitpid(pid, &st, 0);
      return -1;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
}

void sleep_s(double s) { std::this_thread::sleep_for(std::chrono::duration<double>(s)); }

int64_t checkpoint_step(const Checkpoint& c, const std::string& file) {
  return nlohmann::json::parse(c.text("state", file)).value("step", int64_t(-1));
}

// The step of the last complete line of a run's log.csv (the trainer writes and flushes one
// line per step, "step,elapsed,…"), or -1 if there is none yet.
int64_t logged_step(const std::string& log_csv) {
  std::ifstream in(log_csv, std::ios::binary);
  std::string text((std::istreambuf_iterator<char>(in)), {});
  const size_t end = text.rfind('\n');
  if (end == std::string::npos || end == 0) return -1;
  const size_t begin = text.rfind('\n', end - 1);
  const size_t b = begin == std::string::npos ? 0 : begin + 1;
  const std::string line = text.substr(b, end - b);
  if (line.empty() || !std::isdigit(static_cast<unsigned char>(line[0]))) return -1;  // header
  return std::stoll(line);
}

// Waits until the process reports step k or later in its log.csv; returns the step seen, or -1
// if the process exited first or 120 s passed (a hang guard, not a measure of speed).
int64_t wait_logged_step(const std::string& log_csv, int64_t k, pid_t pid) {
  auto t0 = std::chrono::steady_clock::now();
  for (;;) {
    const int64_t s = logged_step(log_csv);
    if (s >= k) return s;
    int st = 0;
    if (::waitpid(pid, &st, WNOHANG) == pid) return -1;
    if (std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() > 120) return -1;
    sleep_s(0.001);
  }
}

}  // namespace

TEST_CASE("reliability: SIGKILL at random points and SIGINT lose nothing; resume ends bitwise "
          "like an uninterrupted run (1 thread)", "[reliability][e2e]") {
  const std::string data = small_sim("interrupt_scene", 6, 40, 30);
  const std::string root = test::fresh_dir("interrupt");
  const std::string log = root + "/processes.log";
  const int steps = 300;
  const std::vector<std::string> common = {
      "--data", data, "--width", "16", "--rays", "64", "--samples", "16", "--threads", "1",
      "--steps", std::to_string(steps), "--no-progress", "--preview-minutes", "1e6",
      "--preset", "paper"};  // one stage (the staged resume: the test after this one)
  auto train_args = [&](const std::string& out, const std::string& ckpt_minutes) {
    std::vector<std::string> a = {"train", "--out", out, "--checkpoint-minutes", ckpt_minutes};
    a.insert(a.end(), common.begin(), common.end());
    return a;
  };
  auto net_of = [](const std::string& run) {
    return load_checkpoint(run + "/checkpoint.bin").text("net", run);
  };

  // The reference: uninterrupted.
  const std::string ref = root + "/ref";
  REQUIRE(wait_for(spawn(train_args(ref, "1e6"), log), 120) == 0);
  const std::string ref_net = net_of(ref);
  REQUIRE(checkpoint_step(load_checkpoint(ref + "/checkpoint.bin"), ref) == steps);

  // Kills happen at step counts the process reports (its log.csv line of step k), never at
  // wall-clock fractions: on a quiet or a loaded machine the run is killed mid-way the same.
  std::mt19937 rng(Catch::rngSeed());
  SECTION("SIGKILL at random points, resumed each time") {
    // A checkpoint every ~6 ms (≈ every step) and a random 0–5 ms wait after the reported step:
    // kills land before, during and after checkpoint writes.
    const std::string out = root + "/killed";
    int64_t last_step = 0, target = 0;
    int kills = 0;
    for (int round = 0; round < 5; ++round) {
      pid_t pid = spawn(round == 0 ? train_args(out, "0.0001")
                                   : std::vector<std::string>{"train", "--resume", out}, log);
      // Round r waits for a step in (50r, 50r + 50]: all five rounds end before step 300.
      target = 50 * round + std::uniform_int_distribution<int64_t>(10, 50)(rng);
      const int64_t seen = wait_logged_step(out + "/log.csv", target, pid);
      INFO("round " << round << ": waited for step " << target << ", saw " << seen);
      REQUIRE(seen >= target);
      sleep_s(std::uniform_real_distribution<double>(0, 0.005)(rng));
      ::kill(pid, SIGKILL);
      REQUIRE(wait_for(pid, 60) == 128 + SIGKILL);
      ++kills;
      // Whatever the moment, the checkpoint on disk is complete and never goes backwards.
      Checkpoint c = load_checkpoint(out + "/checkpoint.bin");
      int64_t s = checkpoint_step(c, out);
      INFO("round " << round << " checkpoint at step " << s);
      CHECK(s >= last_step);
      CHECK(s < steps);
      last_step = s;
    }
    CHECK(kills == 5);
    REQUIRE(wait_for(spawn({"train", "--resume", out}, log), 120) == 0);
    CHECK(checkpoint_step(load_checkpoint(out + "/checkpoint.bin"), out) == steps);
    // Randomness is keyed by the step and Adam's state is in the checkpoint, so replaying from
    // any checkpoint reproduces the uninterrupted run exactly at 1 thread.
    CHECK(net_of(out) == ref_net);
  }
  SECTION("SIGINT: exit 130 with a checkpoint at the interrupt; resume finishes it") {
    const std::string out = root + "/sigint";
    pid_t pid = spawn(train_args(out, "1e6"), log);  // no periodic checkpoints: only the interrupt's
    const int64_t target = std::uniform_int_distribution<int64_t>(60, 200)(rng);
    const int64_t seen = wait_logged_step(out + "/log.csv", target, pid);  // handler installed by now
    REQUIRE(seen >= target);
    ::kill(pid, SIGINT);
    REQUIRE(wait_for(pid, 60) == 130);
    int64_t s = checkpoint_step(load_checkpoint(out + "/checkpoint.bin"), out);
    INFO("interrupted after step " << seen << ", checkpoint at step " << s);
    CHECK(s >= seen);
    CHECK(s < steps);
    REQUIRE(wait_for(spawn({"train", "--resume", out}, log), 120) == 0);
    CHECK(checkpoint_step(load_checkpoint(out + "/checkpoint.bin"), out) == steps);
    CHECK(net_of(out) == ref_net);  // bitwise
  }
}

// A staged run (train/plan.h) killed with SIGKILL inside stage 2 of 3 and resumed with
// `train --resume RUN` ends bit for bit like an uninterrupted run at one thread: plan.json says
// stage 1 finished, stage 2 continues from its checkpoint, stage 3 starts from its cameras.
TEST_CASE("reliability: a 3-stage plan killed inside stage 2 resumes from it, bitwise (1 thread)",
          "[reliability][e2e][plan]") {
  const std::string data = small_sim("plan_kill_scene", 6, 40, 30);
  const std::string root = test::fresh_dir("plan_kill");
  const std::string log = root + "/processes.log";
  write_file_atomic(root + "/three.json", R"({
    "stages": [
      {"budget": {"share": 0.1}},
      {"budget": {"steps": 100}, "set": {"c2f_end": 0}},
      {"budget": "rest", "set": {"c2f_end": 0, "samples": 16}}
    ]})");
  auto train_args = [&](const std::string& out) {
    return std::vector<std::string>{
        "train", "--out", out, "--data", data, "--field", "grid", "--rays", "64", "--samples",
        "8", "--threads", "1", "--steps", "160", "--plan", root + "/three.json", "--no-progress",
        "--checkpoint-minutes", "0", "--preview-minutes", "1e6"};
  };
  auto learned = [](const std::string& run) {
    const Checkpoint c = load_checkpoint(run + "/checkpoint.bin");
    return std::vector<std::string>{c.text("net", run), c.text("poses", run), c.text("focal", run)};
  };
  const std::string ref = root + "/ref", out = root + "/killed";
  REQUIRE(wait_for(spawn(train_args(ref), log), 300) == 0);
  // Killed at a step the process reports in stage 2's log.csv (a checkpoint every step).
  const pid_t pid = spawn(train_args(out), log);
  const int64_t seen = wait_logged_step(out + "/stage2/log.csv", 20, pid);
  REQUIRE(seen >= 20);
  ::kill(pid, SIGKILL);
  REQUIRE(wait_for(pid, 60) == 128 + SIGKILL);
  const nlohmann::json plan = nlohmann::json::parse(read_file_bytes(out + "/plan.json", 1 << 20));
  CHECK(plan.at("stages")[0].at("finished") == true);
  REQUIRE(plan.at("stages")[1].at("finished") == false);  // killed inside stage 2
  CHECK_FALSE(std::filesystem::exists(out + "/checkpoint.bin"));  // stage 3 never started
  REQUIRE(wait_for(spawn({"train", "--resume", out}, log), 300) == 0);
  for (const std::string& s : {"/stage1", "/stage2", ""}) {
    INFO(s);
    CHECK(learned(ref + s) == learned(out + s));
  }
  CHECK(checkpoint_step(load_checkpoint(out + "/stage2/checkpoint.bin"), out) == 100);
}
