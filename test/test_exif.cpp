// Phone photos (issue 51): the EXIF reader on blocks built in memory (both byte orders, the
// orientations, the focal tags, and every way a block can be broken), orientation applied on
// load, the working resolution (--max-side) and the starting focal the trainer takes from EXIF.
#include <catch2/catch.hpp>

#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "core/exif.h"
#include "core/fileio.h"
#include "core/image.h"
#include "core/llff.h"
#include "tools/simulator.h"
#include "train/trainer.h"
#include "test/fixtures.h"

namespace fs = std::filesystem;
using namespace hashcc;

namespace {

ExifInfo parse(const std::string& tiff) {
  return parse_exif_tiff(reinterpret_cast<const uint8_t*>(tiff.data()), tiff.size());
}

bool notes_contain(const ExifInfo& e, const std::string& what) {
  for (const std::string& n : e.notes)
    if (n.find(what) != std::string::npos) return true;
  return false;
}

// A w×h image of four flat quadrants (flat so that JPEG keeps them): top-left, top-right,
// bottom-left, bottom-right colours in that order.
ImageU8 quadrants(int w, int h, const std::array<std::array<uint8_t, 3>, 4>& col) {
  ImageU8 im;
  im.width = w;
  im.height = h;
  im.rgb.resize(size_t(w) * h * 3);
  for (int r = 0; r < h; ++r)
    for (int c = 0; c < w; ++c)
      for (int k = 0; k < 3; ++k)
        im.rgb[(size_t(r) * w + c) * 3 + k] = col[(r >= h / 2) * 2 + (c >= w / 2)][k];
  return im;
}

// The colour at the centre of each quadrant.
std::array<std::array<int, 3>, 4> quadrant_centres(const ImageU8& im) {
  std::array<std::array<int, 3>, 4> out{};
  for (int q = 0; q < 4; ++q) {
    const int r = (q / 2) * im.height / 2 + im.height / 4, c = (q % 2) * im.width / 2 + im.width / 4;
    for (int k = 0; k < 3; ++k) out[q][k] = im.rgb[(size_t(r) * im.width + c) * 3 + k];
  }
  return out;
}

constexpr std::array<uint8_t, 3> kRed = {230, 20, 20}, kGreen = {20, 230, 20},
                                 kBlue = {20, 20, 230}, kWhite = {240, 240, 240};

void write_jpeg(const std::string& path, const ImageU8& im, const std::string& tiff) {
  const std::string jpg = encode_jpeg(im.rgb.data(), im.width, im.height, 95);
  write_file_atomic(path, tiff.empty() ? jpg : jpeg_with_exif(jpg, tiff));
}

}  // namespace

TEST_CASE("exif: orientation and 35 mm focal, little- and big-endian", "[exif]") {
  for (bool le : {true, false})
    for (int orientation : {1, 3, 6, 8})
      for (int f35 : {0, 26}) {
        INFO("little-endian " << le << " orientation " << orientation << " f35 " << f35);
        const ExifInfo e = parse(make_exif_tiff(le, orientation, f35));
        CHECK(e.present);
        CHECK(e.notes.empty());
        CHECK(e.orientation == orientation);
        CHECK(e.focal35_mm == f35);
      }
  // No orientation tag: upright. The real focal length is a RATIONAL stored past the IFD.
  const ExifInfo e = parse(make_exif_tiff(false, 0, 0, 4.25));
  CHECK(e.orientation == 1);
  CHECK(e.focal_mm == Approx(4.25));
  CHECK(e.focal35_mm == 0);
}

TEST_CASE("exif: the focal in pixels, 35 mm film's long side is 36 mm", "[exif]") {
  ExifInfo e;
  std::string how;
  CHECK(exif_focal_px(e, 4032, &how) == 0);
  e.focal35_mm = 26;
  CHECK(exif_focal_px(e, 4032, &how) == Approx(26.0 / 36.0 * 4032));  // 2912 px
  CHECK(how == "exif 26 mm (35 mm equivalent)");
  CHECK(exif_focal_px(e, 504) == Approx(26.0 / 36.0 * 504));
  // FocalLength alone says nothing in pixels; with the sensor's pixel pitch it does:
  // 4.25 mm · 1000 px/mm at a 4032-wide file = 4250 px there, 531.25 px at 504.
  ExifInfo r;
  r.focal_mm = 4.25;
  CHECK(exif_focal_px(r, 504, &how) == 0);
  CHECK(how.find("not used") != std::string::npos);
  r.plane_xres = 1000;
  r.plane_unit_mm = 1;
  r.pixel_x = 4032;
  r.pixel_y = 3024;
  CHECK(exif_focal_px(r, 504) == Approx(531.25));
}

TEST_CASE("exif: broken blocks are ignored with a note, never read past", "[exif]") {
  const std::string good = make_exif_tiff(true, 6, 26, 4.25);
  SECTION("every truncation: no crash, values in range, a note once anything is missing") {
    for (size_t n = 0; n < good.size(); ++n) {
      INFO("first " << n << " of " << good.size() << " bytes");
      // A copy of exactly n bytes, so a read past it is a heap overflow under ASan.
      std::vector<uint8_t> cut(good.begin(), good.begin() + n);
      const ExifInfo e = parse_exif_tiff(cut.data(), cut.size());
      CHECK(e.orientation >= 1);
      CHECK(e.orientation <= 8);
      CHECK_FALSE(e.notes.empty());
    }
    CHECK(parse(good.substr(0, 5)).notes[0].find("too short") != std::string::npos);
    CHECK(notes_contain(parse(good.substr(0, 14)), "IFD0 is truncated"));
  }
  SECTION("wrong byte-order mark") {
    for (std::string bad : {std::string("IM") + good.substr(2), std::string("MM") + good.substr(2)}) {
      // "MM" with a little-endian 42 reads as 10752: not a TIFF block either.
      const ExifInfo e = parse(bad);
      CHECK_FALSE(e.present);
      CHECK(e.orientation == 1);
      CHECK(notes_contain(e, "byte-order mark"));
    }
  }
  SECTION("an Exif IFD pointer back at IFD0 is a loop, not followed") {
    std::string loop = make_exif_tiff(true, 8, 26);
    // IFD0 at 8: count (2 bytes), entry 0 = orientation, entry 1 = the 0x8769 pointer, whose
    // value field is at 8 + 2 + 12 + 8.
    const size_t value = 8 + 2 + 12 + 8;
    loop[value] = 8;
    loop[value + 1] = loop[value + 2] = loop[value + 3] = 0;
    const ExifInfo e = parse(loop);
    CHECK(e.present);
    CHECK(e.orientation == 8);  // what IFD0 says still counts
    CHECK(e.focal35_mm == 0);
    CHECK(notes_contain(e, "loop"));
  }
  SECTION("an IFD offset far past the end") {
    std::string far = good;
    far[4] = far[5] = far[6] = far[7] = char(0xF0);
    const ExifInfo e = parse(far);
    CHECK_FALSE(e.present);
    CHECK(notes_contain(e, "past the end"));
  }
  SECTION("orientation outside 1-8, a zero denominator") {
    ExifInfo e = parse(make_exif_tiff(true, 9, 0));
    CHECK(e.orientation == 1);
    CHECK(notes_contain(e, "not 1-8"));
    std::string zero = make_exif_tiff(true, 0, 0, 4.25);
    zero.replace(zero.size() - 4, 4, std::string(4, '\0'));  // the denominator
    e = parse(zero);
    CHECK(e.focal_mm == 0);
    CHECK(notes_contain(e, "/0"));
  }
}

TEST_CASE("exif: found in a JPEG's APP1 segment; other files have none", "[exif]") {
  const ImageU8 im = quadrants(16, 8, {kRed, kGreen, kBlue, kWhite});
  const std::string jpg = encode_jpeg(im.rgb.data(), im.width, im.height, 90);
  CHECK_FALSE(read_exif_from_jpeg(jpg).present);  // stb writes no EXIF
  CHECK(read_exif_from_jpeg(jpg).notes.empty());
  const ExifInfo e = read_exif_from_jpeg(jpeg_with_exif(jpg, make_exif_tiff(false, 6, 28)));
  CHECK(e.present);
  CHECK(e.orientation == 6);
  CHECK(e.focal35_mm == 28);
  // Another APP1 (XMP) before it is skipped.
  const std::string xmp = "http://ns.adobe.com/xap/1.0/" + std::string(1, '\0') + "<x/>";
  std::string with_xmp = jpeg_with_exif(jpg, make_exif_tiff(true, 3, 0));
  with_xmp.insert(2, std::string("\xFF\xE1") + char(0) + char(xmp.size() + 2) + xmp);
  CHECK(read_exif_from_jpeg(with_xmp).orientation == 3);
  // A segment whose length runs past the end of the file: a note, nothing read.
  std::string cut = jpeg_with_exif(jpg, make_exif_tiff(true, 6, 0)).substr(0, 12);
  const ExifInfo c = read_exif_from_jpeg(cut);
  CHECK_FALSE(c.present);
  CHECK(notes_contain(c, "runs past the end"));
  CHECK_FALSE(read_exif_from_jpeg("\x89PNG\r\n\x1a\n").present);
}

TEST_CASE("images: the eight EXIF orientations", "[io][exif]") {
  // A 3×2 image whose six pixels are 0..5 in reading order.
  ImageU8 s;
  s.width = 3;
  s.height = 2;
  for (int i = 0; i < 6; ++i) s.rgb.insert(s.rgb.end(), {uint8_t(i), uint8_t(i), uint8_t(i)});
  auto px = [](const ImageU8& im) {
    std::vector<int> v;
    for (size_t i = 0; i < im.rgb.size(); i += 3) v.push_back(im.rgb[i]);
    return v;
  };
  // Stored 0 1 2 / 3 4 5, shown as EXIF 2.3's figure for each value.
  CHECK(px(apply_orientation(s, 1)) == std::vector<int>{0, 1, 2, 3, 4, 5});
  CHECK(px(apply_orientation(s, 2)) == std::vector<int>{2, 1, 0, 5, 4, 3});
  CHECK(px(apply_orientation(s, 3)) == std::vector<int>{5, 4, 3, 2, 1, 0});
  CHECK(px(apply_orientation(s, 4)) == std::vector<int>{3, 4, 5, 0, 1, 2});
  CHECK(px(apply_orientation(s, 5)) == std::vector<int>{0, 3, 1, 4, 2, 5});
  CHECK(px(apply_orientation(s, 6)) == std::vector<int>{3, 0, 4, 1, 5, 2});  // turned clockwise
  CHECK(px(apply_orientation(s, 7)) == std::vector<int>{5, 2, 4, 1, 3, 0});
  CHECK(px(apply_orientation(s, 8)) == std::vector<int>{2, 5, 1, 4, 0, 3});  // anticlockwise
  for (int o = 5; o <= 8; ++o) CHECK(apply_orientation(s, o).width == 2);
}

TEST_CASE("images: a JPEG with orientation 6 loads upright", "[io][exif]") {
  const std::string d = test::fresh_dir("exif_orient");
  // The photo as it should look, 40 wide × 30 high: red, green / blue, white. Orientation 6
  // means "row 0 is the visual right side, column 0 the visual top", so the camera stored it
  // 30 wide × 40 high with: stored top-left = shown top-right (green), stored top-right = shown
  // bottom-right (white), stored bottom-left = shown top-left (red), bottom-right = blue.
  write_jpeg(d + "/a.jpg", quadrants(30, 40, {kGreen, kWhite, kRed, kBlue}),
             make_exif_tiff(true, 6, 26));
  int w = 0, h = 0;
  image_size(d + "/a.jpg", &w, &h);
  CHECK(w == 40);
  CHECK(h == 30);
  const ImageU8 im = read_image(d + "/a.jpg");
  REQUIRE(im.width == 40);
  REQUIRE(im.height == 30);
  const auto got = quadrant_centres(im);
  const std::array<std::array<uint8_t, 3>, 4> want = {kRed, kGreen, kBlue, kWhite};
  for (int q = 0; q < 4; ++q)
    for (int k = 0; k < 3; ++k) CHECK(std::abs(got[q][k] - want[q][k]) <= 12);
}

TEST_CASE("images: the area filter averages, max-side keeps the aspect", "[io][exif]") {
  int w, h;
  working_size(4032, 3024, 504, &w, &h);
  CHECK((w == 504 && h == 378));
  working_size(2000, 1500, 500, &w, &h);
  CHECK((w == 500 && h == 375));
  working_size(1500, 2000, 500, &w, &h);
  CHECK((w == 375 && h == 500));
  working_size(504, 378, 504, &w, &h);  // LLFF's images_8: untouched
  CHECK((w == 504 && h == 378));
  working_size(4032, 3024, 0, &w, &h);
  CHECK((w == 4032 && h == 3024));
  // A one-pixel checkerboard: an area filter gives grey everywhere; point sampling would give
  // black or white. 8 → 2 (integer ratio) and 12 → 5 (fractional).
  for (int n : {2, 5}) {
    const int W = n == 2 ? 8 : 12;
    std::vector<uint8_t> checker(size_t(W) * W * 3);
    for (int r = 0; r < W; ++r)
      for (int c = 0; c < W; ++c)
        for (int k = 0; k < 3; ++k) checker[(size_t(r) * W + c) * 3 + k] = (r + c) % 2 ? 255 : 0;
    const ImageU8 small = resize_area(checker.data(), W, W, n, n);
    for (uint8_t v : small.rgb) CHECK(std::abs(int(v) - 128) <= 8);
  }
}

namespace {
// n synthetic 2000×1500 JPEGs (a smooth gradient, a different one each) with an EXIF block
// stating a 26 mm lens; no poses.
std::string large_jpeg_folder(int n) {
  const std::string d = test::fresh_dir("exif_large");
  for (int i = 0; i < n; ++i) {
    ImageU8 im;
    im.width = 2000;
    im.height = 1500;
    im.rgb.resize(size_t(2000) * 1500 * 3);
    for (int r = 0; r < 1500; ++r)
      for (int c = 0; c < 2000; ++c) {
        uint8_t* p = &im.rgb[(size_t(r) * 2000 + c) * 3];
        p[0] = uint8_t(c * 255 / 1999);
        p[1] = uint8_t(r * 255 / 1499);
        p[2] = uint8_t(40 * i);
      }
    write_jpeg(fmt::format("{}/photo{}.jpg", d, i), im, make_exif_tiff(i % 2 == 0, 1, 26));
  }
  return d;
}
}  // namespace

TEST_CASE("scene: --max-side 500 loads 2000x1500 JPEGs at 500x375, the EXIF focal with them",
          "[io][exif]") {
  const std::string d = large_jpeg_folder(3);
  const Scene full = load_scene(d, {"", true, 0});
  CHECK((full.width == 2000 && full.height == 1500));
  CHECK(full.exif_focal == Approx(26.0 / 36.0 * 2000));
  const Scene sc = load_scene(d, {"", true, 500});
  CHECK((sc.file_width == 2000 && sc.file_height == 1500));
  REQUIRE((sc.width == 500 && sc.height == 375));
  for (const ImageU8& im : sc.images) CHECK(im.rgb.size() == size_t(500) * 375 * 3);
  CHECK(sc.exif_focal == Approx(full.exif_focal / 4));
  CHECK(sc.exif_focal_source == "exif 26 mm (35 mm equivalent)");
  // The small image is the big one averaged: the gradient's middle stays in the middle.
  CHECK(std::abs(sc.images[0].at(187, 250, 0) - full.images[0].at(750, 1000, 0)) < 0.02);
  CHECK(test::cli({"info", "--data", d, "--max-side", "500"}) == 0);
}

TEST_CASE("scene: simulated phone JPEGs load as the PNG scene does, image001 upright",
          "[io][exif]") {
  SimOptions o;
  o.views = 3;
  o.width = 160;
  o.height = 120;
  o.supersample = 1;
  const std::string png = test::fresh_dir("exif_sim_png"), jpg = test::fresh_dir("exif_sim_jpg");
  write_sim_scene(png, o, false);
  o.jpeg = true;
  write_sim_scene(jpg, o, false);
  int w, h;
  image_size(jpg + "/images/image001.jpg", &w, &h);
  CHECK((w == 160 && h == 120));  // stored 120×160, orientation 6
  const Scene a = load_scene(png), b = load_scene(jpg);
  REQUIRE((b.width == 160 && b.height == 120));
  CHECK(a.exif_focal == 0);  // PNG: no EXIF
  CHECK(a.turned == 0);
  CHECK(b.turned == 1);
  // 0.8 · 160 = 128 px is 28.8 mm on 35 mm film, stated as 29 mm (a whole number).
  CHECK(b.exif_focal == Approx(29.0 / 36.0 * 160));
  CHECK(b.ref_focal == a.ref_focal);
  for (int i = 0; i < 3; ++i) {
    double err = 0;
    for (size_t k = 0; k < a.images[i].rgb.size(); ++k)
      err += std::abs(int(a.images[i].rgb[k]) - int(b.images[i].rgb[k]));
    err /= a.images[i].rgb.size();
    INFO("image " << i << " mean abs difference " << err);
    CHECK(err < 4);  // JPEG at quality 92; a turned or mirrored image differs by tens
  }
  // At half size the reference focal halves with the images.
  const Scene half = load_scene(jpg, {"", true, 80});
  CHECK((half.width == 80 && half.height == 60));
  CHECK(half.ref_focal == Approx(a.ref_focal / 2));
}

TEST_CASE("trainer: the starting focal from EXIF beats the prior, --focal beats EXIF",
          "[exif][trainer]") {
  test::ThreadGuard one(1);
  SimOptions o;
  o.views = 4;
  o.width = 64;
  o.height = 48;
  o.supersample = 1;
  o.jpeg = true;
  const std::string jpg = test::fresh_dir("exif_train_jpg");
  write_sim_scene(jpg, o, false);
  const std::string png = test::sim_scene("exif_train_png", 4, 64, 48, 1);
  auto source = [](const std::string& out) {
    return nlohmann::json::parse(read_file_bytes(out + "/config.json", 1 << 20))
        .at("focal_source").get<std::string>();
  };
  auto fx = [](const Trainer& t) { return double(t.focal().a) * t.focal().a * t.scene().width; };
  {
    TrainConfig c = test::tiny_train_config(jpg, test::fresh_dir("exif_run_exif"), 1);
    c.focal_fov = 65;
    const Trainer t(c);
    CHECK(fx(t) == Approx(29.0 / 36.0 * 64).epsilon(1e-5));  // not the prior's 50.2 px
    CHECK(source(c.out) == "exif 29 mm (35 mm equivalent)");
  }
  {
    TrainConfig c = test::tiny_train_config(jpg, test::fresh_dir("exif_run_focal"), 1);
    c.focal_fov = 65;
    c.focal_fx = c.focal_fy = 40;
    const Trainer t(c);
    CHECK(fx(t) == Approx(40).epsilon(1e-5));
    CHECK(source(c.out) == "--focal");
  }
  {
    TrainConfig c = test::tiny_train_config(png, test::fresh_dir("exif_run_png"), 1);
    c.focal_fov = 65;
    const Trainer t(c);
    CHECK(fx(t) == Approx(0.5 * 64 / std::tan(65.0 / 2 * M_PI / 180)).epsilon(1e-5));
    CHECK(source(c.out) == "fov prior 65 deg");
  }
  {
    // --max-side 32 halves the 64×48 images: the run trains at 32×24, the EXIF focal halves.
    TrainConfig c = test::tiny_train_config(jpg, test::fresh_dir("exif_run_small"), 1);
    c.max_side = 32;
    c.rays = 16;
    Trainer t(c);
    CHECK((t.scene().width == 32 && t.scene().height == 24));
    CHECK(fx(t) == Approx(29.0 / 36.0 * 32).epsilon(1e-5));
    REQUIRE(t.run());
    // eval and render open the run through its config.json: the same working size.
    const Trainer back = Trainer::open(c.out);
    CHECK((back.scene().width == 32 && back.scene().height == 24));
    // A later run from its cameras must work at its size, and is told which --max-side that is.
    TrainConfig d = test::tiny_train_config(jpg, test::fresh_dir("exif_run_from"), 1);
    d.cameras_from = c.out;
    CHECK_THROWS_WITH(Trainer(d), Catch::Contains("trained at 32x24, this run at 64x48") &&
                                      Catch::Contains("--max-side 32"));
  }
  // A config.json from before --max-side means the files' size.
  CHECK(train_config_from_json("{}", "config.json").max_side == 0);
  CHECK(train_config_from_json(R"({"max_side": 504})", "config.json").max_side == 504);
}

TEST_CASE("scene: a broken EXIF block is a note naming the photo, not an error", "[io][exif]") {
  const std::string d = test::fresh_dir("exif_broken");
  const ImageU8 im = quadrants(32, 24, {kRed, kGreen, kBlue, kWhite});
  write_jpeg(d + "/a.jpg", im, make_exif_tiff(true, 1, 26));
  write_jpeg(d + "/b.jpg", im, make_exif_tiff(false, 6, 26).substr(0, 14));  // IFD0 cut short
  write_jpeg(d + "/c.jpg", im, "");                                           // stripped
  const Scene sc = load_scene(d);
  REQUIRE(sc.images.size() == 3);
  CHECK((sc.width == 32 && sc.height == 24));  // b's orientation was never read: upright
  CHECK(sc.turned == 0);
  CHECK(sc.exif_focal == Approx(26.0 / 36.0 * 32));  // from a alone
  std::string all;
  for (const std::string& n : sc.notes) all += n + "\n";
  INFO(all);
  CHECK(all.find("b.jpg: EXIF IFD0 is truncated") != std::string::npos);
  CHECK(all.find("2 of 3 images state no EXIF focal") != std::string::npos);
}

TEST_CASE("trainer: a plan's reloads reuse the decoded scene until a photo changes",
          "[exif][trainer]") {
  test::ThreadGuard one(1);
  const std::string d = test::fresh_dir("exif_cache");
  for (int i = 0; i < 4; ++i)
    write_jpeg(fmt::format("{}/p{}.jpg", d, i), quadrants(64, 48, {kRed, kGreen, kBlue, kWhite}),
               make_exif_tiff(true, 1, 26));
  TrainConfig c = test::tiny_train_config(d, "", 1);
  const Trainer a(c), b(c);
  CHECK(a.scene().images[1].rgb == b.scene().images[1].rgb);
  // Rewritten with other colours (same size): the next load must see them.
  write_jpeg(d + "/p1.jpg", quadrants(64, 48, {kWhite, kWhite, kWhite, kWhite}),
             make_exif_tiff(true, 1, 26));
  const Trainer after(c);
  CHECK(after.scene().images[1].at(5, 5, 1) > 0.85f);   // was red: green 20/255
  CHECK(after.scene().images[0].rgb == a.scene().images[0].rgb);
  CHECK(a.scene().images[1].at(5, 5, 1) < 0.2f);
}
