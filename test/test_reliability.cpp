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
