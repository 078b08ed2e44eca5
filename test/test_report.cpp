// The run report (tools/run_report.h, tools/html.h, docs/report.md) and `render --video`
// (tools/video.h).
//
// [report]: the builders on hand-made run folders (fast): escaping of what a command line or a
// path may hold, a NaN in a curve, an empty or torn log, base64, SVG ids made unique, the
// camera views, the one line of a section whose inputs are absent, the `report` command's
// errors; `render --video` refused before rendering without ffmpeg.
// [external]: programs hashcc does not depend on (CTest entry external_tools, skipped with a
// line saying so when they are absent; CI installs them): a real run on the simulated scene
// loaded in headless Chromium (no console error, every image decodes, the expected sections,
// a screenshot that is not blank), and a video encoded with ffmpeg.
#include <catch2/catch.hpp>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fmt/core.h>
#include <fstream>
#include <regex>

#include "core/fileio.h"
#include "core/image.h"
#include "test/fixtures.h"
#include "test/shared_data.h"
#include "test/xml_check.h"
#include "tools/html.h"
#include "tools/run_report.h"
#include "tools/video.h"

namespace fs = std::filesystem;
using namespace hashcc;
using hashcc::test::cli;
using hashcc::test::xml_problem;

namespace {

std::string slurp(const std::string& path) { return read_file_bytes(path, int64_t(1) << 28); }
void put(const std::string& path, const std::string& text) {
  fs::create_directories(fs::path(path).parent_path());
  std::ofstream(path, std::ios::binary) << text;
}
size_t count(const std::string& s, const std::string& what) {
  size_t n = 0;
  for (size_t at = 0; (at = s.find(what, at)) != std::string::npos; at += what.size()) ++n;
  return n;
}
// The text of <section id="id"> … </section> ("" when absent).
std::string section_of(const std::string& page, const std::string& id) {
  const size_t a = page.find("<section id=\"" + id + "\">");
  if (a == std::string::npos) return "";
  return page.substr(a, page.find("</section>", a) - a);
}
// Every points="…" of every polyline holds numbers only (no nan, no inf).
bool polylines_finite(const std::string& svg) {
  const std::regex pts("points=\"([^\"]*)\"");
  for (auto it = std::sregex_iterator(svg.begin(), svg.end(), pts); it != std::sregex_iterator(); ++it)
    for (char c : (*it)[1].str())
      if (!(std::isdigit(static_cast<unsigned char>(c)) || c == '.' || c == ',' || c == ' ' || c == '-'))
        return false;
  return true;
}

const char* kLogHeader = "step,seconds,loss,psnr,psnr_cc,lr_net,lr_pose,lr_focal,fx,fy\n";

// A run folder by hand: config.json naming a scene that does not exist, a log, commands.txt.
std::string fake_run(const std::string& name, const std::string& log) {
  const std::string run = test::fresh_dir(name);
  put(run + "/config.json", R"({"data": "/nonexistent/scene", "model": "hashcc", "field": "grid",
      "max_side": 504, "images_folder": "", "focal_source": "focal_fov 65"})");
  put(run + "/log.csv", log);
  return run;
}

}  // namespace

TEST_CASE("report: shell quoting and the escaping of a command line", "[report]") {
  CHECK(shell_quote("--out=/tmp/run_1") == "--out=/tmp/run_1");
  CHECK(shell_quote("a b") == "'a b'");
  CHECK(shell_quote("it's") == "'it'\\''s'");
  CHECK(shell_quote("") == "''");
  CHECK(command_text({"hashcc", "train", "--set", "last.samples=64"}) == "hashcc train --set last.samples=64");
  CHECK(html::escape("<b a=\"1\">&'") == "&lt;b a=&quot;1&quot;&gt;&amp;&apos;");
  CHECK(html::escape(std::string("a\x01z")) == "a z");

  // A command with every character HTML cares about reaches the page escaped, never as markup.
  const std::string run = fake_run("escape", std::string(kLogHeader) + "1,0.1,0.1,12,12,1e-3,1e-3,0,50,50\n");
  record_command(run, {"hashcc", "train", "--out", "x<script>alert(1)</script>&\"y\""});
  const std::string page = run_report_html(run);
  CHECK(page.find("<script>") == std::string::npos);
  CHECK(page.find("x&lt;script&gt;alert(1)&lt;/script&gt;&amp;&quot;y&quot;") != std::string::npos);
  CHECK(page.find("src=\"http") == std::string::npos);
}

TEST_CASE("report: base64 and SVG ids made unique for inlining", "[report]") {
  // RFC 4648 §10's test vectors.
  CHECK(html::base64("") == "");
  CHECK(html::base64("f") == "Zg==");
  CHECK(html::base64("fo") == "Zm8=");
  CHECK(html::base64("foo") == "Zm9v");
  CHECK(html::base64("foob") == "Zm9vYg==");
  CHECK(html::base64("fooba") == "Zm9vYmE=");
  CHECK(html::base64("foobar") == "Zm9vYmFy");
  CHECK(html::base64(std::string("\xff\x00\x80", 3)) == "/wCA");
  const std::string svg = "<?xml version=\"1.0\"?>\n<svg><defs><clipPath id=\"frame\"/></defs>"
                          "<g clip-path=\"url(#frame)\"/><use href=\"#frame\"/></svg>\n";
  const std::string in = html::inline_svg(svg, "p7");
  CHECK(in.find("<?xml") == std::string::npos);
  CHECK(in.find("id=\"p7-frame\"") != std::string::npos);
  CHECK(in.find("url(#p7-frame)") != std::string::npos);
  CHECK(in.find("href=\"#p7-frame\"") != std::string::npos);
  CHECK(in.find("\"frame\"") == std::string::npos);
  // A PNG through the data URI decodes back to the same pixels.
  ImageU8 im;
  im.width = 3;
  im.height = 2;
  im.rgb = {255, 0, 0, 0, 255, 0, 0, 0, 255, 10, 20, 30, 40, 50, 60, 70, 80, 90};
  const std::string png = encode_png(im.rgb.data(), 3, 2);
  const ImageU8 back = read_image_from_memory(png, "png");
  CHECK(back.rgb == im.rgb);
  CHECK(html::png_img(png, "a<b").find("alt=\"a&lt;b\"") != std::string::npos);
}

TEST_CASE("report: CSV rows, a NaN in a curve, an empty and a torn log", "[report]") {
  NumericCsv t = parse_numeric_csv("a,b\n1,2\n3,nan\n4,x\n5,6,7\n8");
  CHECK(t.header == std::vector<std::string>{"a", "b"});
  REQUIRE(t.rows.size() == 3);
  CHECK(std::isnan(t.rows[1][1]));
  CHECK(std::isnan(t.rows[2][1]));  // "x" is not a number
  CHECK(t.skipped == 2);            // three fields, and a last line without its newline
  CHECK(t.column("b").size() == 3);
  CHECK(t.column("c").empty());
  CHECK(parse_numeric_csv("").header.empty());

  std::vector<double> bx, by;
  bin_means({1, 2, 3, 4, 5}, {10, std::nan(""), 30, 40, 50}, 2, &bx, &by);
  REQUIRE(bx.size() == 2);
  CHECK(bx[0] == Approx(2));
  CHECK(by[0] == Approx(20));  // the NaN left out of its bin
  CHECK(by[1] == Approx(45));

  // A NaN loss and PSNR mid-log (a diverged step): the curve skips it, every coordinate is a number.
  std::string log = kLogHeader;
  for (int k = 1; k <= 30; ++k)
    log += k == 12 ? fmt::format("{},{},nan,nan,nan,1e-3,1e-3,0,inf,50\n", k, 0.1 * k)
                   : fmt::format("{},{},{},{},{},1e-3,1e-3,0,{},50\n", k, 0.1 * k, 0.1 / k, 10 + 0.3 * k,
                                 10 + 0.3 * k, 60 - 0.1 * k);
  log += "31,3.1,0.0";  // torn by a crash
  const std::string run = fake_run("nan", log);
  const std::vector<StageLogs> st = read_stage_logs(run);
  REQUIRE(st.size() == 1);
  CHECK(st[0].log.rows.size() == 30);
  CHECK(st[0].log.skipped == 1);
  const std::vector<std::string> svgs = training_curve_svgs(st, 62.5, 400);
  REQUIRE(svgs.size() == 3);
  for (const std::string& s : svgs) {
    CHECK(xml_problem(s) == "");
    CHECK(polylines_finite(s));
    CHECK(count(s, "<polyline") == 1);
  }
  CHECK(svgs[2].find("reference 62.5") != std::string::npos);
  const std::string page = run_report_html(run);
  CHECK(section_of(page, "curves").find("1 incomplete row(s) of log.csv skipped") != std::string::npos);
  CHECK(polylines_finite(page));

  // A run that has not made a step: the sections are there, each saying why it is empty.
  for (const std::string& empty_log : {std::string(kLogHeader), std::string()}) {
    const std::string e = fake_run("empty", empty_log);
    CHECK(training_curve_svgs(read_stage_logs(e), 0, 400).empty());
    const std::string p = run_report_html(e);
    for (const char* id : {"summary", "command", "curves", "camera-error", "cameras", "test-views", "spiral"}) {
      INFO(id);
      CHECK(!section_of(p, id).empty());
    }
    CHECK(section_of(p, "curves").find("log.csv has no rows yet") != std::string::npos);
    CHECK(section_of(p, "cameras").find("class=\"absent\"") != std::string::npos);
    CHECK(section_of(p, "test-views").find("Not evaluated yet") != std::string::npos);
    CHECK(section_of(p, "spiral").find("No render folder known") != std::string::npos);
    CHECK(section_of(p, "command").find("No commands.txt") != std::string::npos);
  }
}

TEST_CASE("report: a staged run's stages share one time axis", "[report]") {
  const std::string run = fake_run("staged", std::string(kLogHeader) + "1,5,0.1,20,20,0,0,0,50,50\n"
                                                                       "2,10,0.1,21,21,0,0,0,50,50\n");
  put(run + "/plan.json", R"({"plan": "x", "source": "recipe x", "base": {}, "stages": [
      {"dir": "stage1", "finished": true}, {"dir": "stage2", "kept_dir": "stage2/try2", "try": [{}, {}],
       "kept": 2, "finished": true}, {"dir": ".", "finished": false}]})");
  put(run + "/stage1/log.csv", std::string(kLogHeader) + "1,30,0.1,15,15,0,0,0,50,50\n");
  put(run + "/stage2/try2/log.csv", std::string(kLogHeader) + "1,12.5,0.1,17,17,0,0,0,50,50\n");
  put(run + "/stage2/try2/camera_error.csv", "step,seconds,rel_rot_deg,sim3_dR_deg,sim3_dT,fx,fy,ref_focal\n"
                                             "0,0,5,,,50,50,60\n25,12.5,2,3,0.1,50,50,60\n");
  // Stopped in stage 2: no config.json in the run folder yet; plan.json's "run" stands in.
  {
    const std::string early = test::fresh_dir("staged_early");
    put(early + "/plan.json", R"({"plan": "x", "source": "recipe x", "base": {}, "run": {"data": "/nowhere",
        "model": "sh"}, "stages": [{"dir": "stage1", "finished": true}, {"dir": ".", "finished": false}]})");
    put(early + "/stage1/log.csv", std::string(kLogHeader) + "1,30,0.1,15,15,0,0,0,50,50\n");
    const std::string p = run_report_html(early);
    CHECK(section_of(p, "summary").find("1 steps in 30.0 s") != std::string::npos);
    CHECK(section_of(p, "summary").find("sh, field") != std::string::npos);
  }
  const std::vector<StageLogs> st = read_stage_logs(run);
  REQUIRE(st.size() == 3);
  CHECK(st[0].name == "stage 1");
  CHECK(st[1].dir.ends_with("try2"));  // the kept alternative
  CHECK(st[2].name == "run");
  CHECK(st[1].offset == Approx(30));
  CHECK(st[2].offset == Approx(42.5));
  const std::string cam = camera_error_svg(st, 7.5);
  CHECK(xml_problem(cam) == "");
  CHECK(cam.find("do nothing 7.50") != std::string::npos);
  CHECK(camera_error_svg({st[0]}, 0).empty());  // no camera_error.csv rows
  const std::string page = run_report_html(run);
  CHECK(section_of(page, "summary").find("4 steps in 52.5 s") != std::string::npos);
  CHECK(section_of(page, "command").find("2 tried, kept stage2/try2") != std::string::npos);

  // A file that does not parse spoils its own section only, which names it.
  put(run + "/eval/metrics.json", "{\"psnr\": ");
  put(run + "/cameras.json", "{\"frames\": 3}");
  std::string bad = run_report_html(run);
  CHECK(section_of(bad, "test-views").find("eval/metrics.json could not be read") != std::string::npos);
  CHECK(section_of(bad, "cameras").find("could not be drawn") != std::string::npos);
  CHECK(section_of(bad, "cameras").find("cameras.json") != std::string::npos);
  CHECK(count(section_of(bad, "curves"), "<svg ") == 3);  // the logs still draw
  put(run + "/plan.json", "[");
  bad = run_report_html(run);
  CHECK(section_of(bad, "curves").find("The logs could not be read") != std::string::npos);
  CHECK(section_of(bad, "command").find("plan.json could not be read") != std::string::npos);
  CHECK(!section_of(bad, "summary").empty());
}

TEST_CASE("report: camera views from above and from the side", "[report]") {
  // Three cameras on the x axis looking down −z; the reference the same, shifted.
  std::vector<Mat34d> learned, ref;
  for (int i = 0; i < 3; ++i) {
    Mat34d m = Mat34d::Zero();
    m.leftCols<3>().setIdentity();
    m(0, 3) = i - 1.0;
    learned.push_back(m);
    m(2, 3) = 0.1;
    ref.push_back(m);
  }
  const std::string top = camera_view_svg(learned, ref, true, "Top <view>");
  CHECK(xml_problem(top) == "");
  CHECK(top.find("Top &lt;view&gt;") != std::string::npos);
  CHECK(count(top, "fill=\"none\" stroke=") >= 3);  // hollow reference rings
  CHECK(count(top, "stroke=\"#999999\"") == 3);      // each learned centre joined to its reference
  // From above, the learned centres lie on one row, spread left to right, each stroke pointing
  // up the page (−z forward).
  const std::regex dot("<circle cx=\"([-0-9.]+)\" cy=\"([-0-9.]+)\" r=\"3.5\"");
  std::vector<double> xs, ys;
  for (auto it = std::sregex_iterator(top.begin(), top.end(), dot); it != std::sregex_iterator(); ++it) {
    xs.push_back(std::stod((*it)[1]));
    ys.push_back(std::stod((*it)[2]));
  }
  REQUIRE(xs.size() == 3);
  CHECK(ys[0] == Approx(ys[2]));
  CHECK(xs[0] < xs[1]);
  CHECK(xs[1] < xs[2]);
  // A camera with a NaN is left out, not drawn at NaN; no reference: no joining lines.
  learned[1](0, 0) = std::nan("");
  const std::string side = camera_view_svg(learned, {}, false, "Side");
  CHECK(xml_problem(side) == "");
  CHECK(side.find("nan") == std::string::npos);
  CHECK(count(side, "r=\"3.5\"") == 2);
  CHECK(count(side, "stroke=\"#999999\"") == 0);
  CHECK(xml_problem(camera_view_svg({}, {}, true, "none")) == "");
}

TEST_CASE("report: the report command's errors and its page", "[report][cli]") {
  const std::string nowhere = test::tmp("no_such_run", true);
  CHECK(cli({"report", "--run", nowhere}) == 2);
  const std::string not_a_run = test::fresh_dir("not_a_run");
  CHECK(cli({"report", "--run", not_a_run}) == 2);  // no config.json
  const std::string run = fake_run("cli", std::string(kLogHeader) + "1,0.1,0.1,12,12,0,0,0,50,50\n");
  CHECK(cli({"report", "--run", run, "--render", nowhere}) == 2);
  const std::string out = test::tmp("cli_page.html", true);
  REQUIRE(cli({"report", "--run", run, "--out", out}) == 0);
  CHECK(slurp(out).starts_with("<!DOCTYPE html>"));
  CHECK(!fs::exists(run + "/report.html"));
  CHECK(!fs::exists(out + ".tmp"));
}

// Without ffmpeg on the PATH, --video stops before rendering: exit 2 and no frame written.
TEST_CASE("render --video: refused before rendering when ffmpeg is not on the PATH", "[report][video][cli]") {
  const std::string data = test::sim_scene("video", 6, 32, 24);
  const std::string run = test::tmp("video_refused_run", true);
  REQUIRE(cli({"train", "--data", data, "--out", run, "--field", "grid", "--steps", "3", "--rays", "64",
               "--samples", "8", "--no-progress", "--threads", "1"}) == 0);
  const std::string out = test::tmp("video_refused_frames", true);
  const std::string keep = std::getenv("PATH") ? std::getenv("PATH") : "";
  setenv("PATH", test::fresh_dir("empty_path").c_str(), 1);
  const int rc = cli({"render", "--run", run, "--out", out, "--frames", "2", "--video", out + ".mp4",
                      "--no-progress"});
  setenv("PATH", keep.c_str(), 1);
  CHECK(rc == 2);
  CHECK(!fs::exists(out + "/0000_rgb.png"));
  CHECK(cli({"render", "--run", run, "--out", out, "--frames", "2", "--video", out + ".avi",
             "--no-progress"}) == 2);
  CHECK(cli({"render", "--run", run, "--out", out, "--frames", "2", "--video",
             test::tmp("no_such_folder", true) + "/x.mp4", "--no-progress"}) == 2);
  // train wrote the report and the command: a 3-step run already has its page.
  CHECK(fs::exists(run + "/report.html"));
  CHECK(slurp(run + "/commands.txt").find("hashcc train --data") != std::string::npos);
}

TEST_CASE("render --video: the frames as an H.264 MP4 through ffmpeg", "[report][video][external]") {
  const std::string ffmpeg = find_on_path("ffmpeg");
  HASHCC_NEED_PROGRAM(ffmpeg, "ffmpeg", "ffmpeg");
  const std::string data = test::sim_scene("video", 6, 32, 24);
  const std::string run = test::tmp("video_run", true);
  REQUIRE(cli({"train", "--data", data, "--out", run, "--field", "grid", "--steps", "3", "--rays", "64",
               "--samples", "8", "--no-progress", "--threads", "1"}) == 0);
  const std::string out = test::tmp("video_frames", true), video = test::tmp("spiral.mp4", true);
  REQUIRE(cli({"render", "--run", run, "--out", out, "--frames", "5", "--video", video, "--fps", "10",
               "--no-progress"}) == 0);
  REQUIRE(fs::exists(video));
  CHECK(!fs::exists(video + ".tmp.mp4"));
  const std::string bytes = slurp(video);
  REQUIRE(bytes.size() > 12);
  CHECK(bytes.substr(4, 4) == "ftyp");  // an MP4 (ISO BMFF) file starts with its ftyp box
  const std::string ffprobe = find_on_path("ffprobe");
  if (!ffprobe.empty()) {
    const std::string txt = test::tmp("ffprobe.txt", true);
    const std::string cmd = fmt::format(
        "{} -v error -count_frames -select_streams v:0 -show_entries stream=nb_read_frames,codec_name "
        "-of default=noprint_wrappers=1 {} > {}", shell_quote(ffprobe), shell_quote(video), shell_quote(txt));
    REQUIRE(std::system(cmd.c_str()) == 0);
    const std::string probe = slurp(txt);
    INFO(probe);
    CHECK(probe.find("codec_name=h264") != std::string::npos);
    CHECK(probe.find("nb_read_frames=5") != std::string::npos);
  }
  // render remembered its folder: the run's page shows its frames.
  const std::string page = slurp(run + "/report.html");
  CHECK(section_of(page, "spiral").find("5 frames") != std::string::npos);
}

// A real run, its evaluation and its spiral, on the simulated scene; the page in a real browser.
TEST_CASE("report: a trained run's page in headless Chromium", "[report][browser][external]") {
  std::string chromium = find_on_path("chromium");
  if (chromium.empty()) chromium = find_on_path("chromium-browser");
  HASHCC_NEED_PROGRAM(chromium, "chromium", "chromium");
  const std::string data = test::tmp("browser_scene", true), run = test::tmp("browser_run", true);
  const std::string frames = test::tmp("browser_frames", true);
  REQUIRE(cli({"simulate", "--out", data, "--views", "12", "--width", "64", "--height", "48"}) == 0);
  // The default command (the forward recipe's five stages) in a few hundred small steps, on
  // small hash tables (2^12 entries a level: 17 s instead of 32 s, a 2 MB checkpoint, not 50).
  REQUIRE(cli({"train", "--data", data, "--out", run, "--steps", "300", "--rays", "256",
               "--no-progress", "--threads", "2", "--set", "grid_log2_table=12", "--set",
               "last.grid_log2_table=12"}) == 0);
  REQUIRE(cli({"eval", "--run", run, "--refine-epochs", "2", "--no-progress"}) == 0);
  REQUIRE(cli({"render", "--run", run, "--out", frames, "--frames", "6", "--no-progress"}) == 0);
  const std::string page_path = run + "/report.html";
  const std::string page = slurp(page_path);
  WARN("report.html: " << page.size() / 1024 << " KB");
  CHECK(page.size() < 3u << 20);
  // Every section drawn from its inputs: not one "absent" line on a complete run.
  for (const char* id : {"summary", "command", "curves", "camera-error", "cameras", "test-views", "spiral"}) {
    INFO(id);
    const std::string s = section_of(page, id);
    CHECK(!s.empty());
    CHECK(s.find("class=\"absent\"") == std::string::npos);
  }
  CHECK(count(section_of(page, "curves"), "<svg ") == 3);
  CHECK(count(section_of(page, "cameras"), "<svg ") == 2);
  CHECK(section_of(page, "command").find("hashcc eval --run") != std::string::npos);
  CHECK(section_of(page, "command").find("Plan forward") != std::string::npos);
  // Nothing on the page reaches for the network.
  for (const char* ref : {"src=\"http", "href=\"http", "url(http", "@import"}) {
    INFO(ref);
    CHECK(page.find(ref) == std::string::npos);
  }

  const std::string dir = test::fresh_dir("browser_out");
  const std::string base = fmt::format("timeout 120 {} --headless --disable-gpu --no-sandbox "
                                       "--user-data-dir={} --hide-scrollbars ",
                                       shell_quote(chromium), shell_quote(dir + "/profile"));
  // 1. A screenshot, with the browser's log on stderr: console messages are its CONSOLE lines.
  const std::string shot = dir + "/shot.png", log = dir + "/chromium.log";
  const std::string cmd1 = base + fmt::format("--enable-logging=stderr --v=0 --window-size=1280,2000 "
                                              "--screenshot={} file://{} > /dev/null 2> {}",
                                              shell_quote(shot), shell_quote(fs::absolute(page_path).string()),
                                              shell_quote(log));
  REQUIRE(std::system(cmd1.c_str()) == 0);
  const std::string console = slurp(log);
  std::string console_lines;
  for (size_t at = 0; (at = console.find(":CONSOLE", at)) != std::string::npos; ++at)
    console_lines += console.substr(at, console.find('\n', at) - at) + "\n";
  INFO("console: " << console_lines);
  CHECK(console_lines.empty());
  const ImageU8 im = read_image(shot);
  REQUIRE(im.width == 1280);
  double sum = 0, sum2 = 0;
  int64_t inked = 0;
  const int64_t n = int64_t(im.width) * im.height;
  for (int64_t k = 0; k < n; ++k) {
    const double y = (im.rgb[3 * k] + im.rgb[3 * k + 1] + im.rgb[3 * k + 2]) / 3.0;
    sum += y;
    sum2 += y * y;
    inked += y < 200;
  }
  const double var = sum2 / n - (sum / n) * (sum / n);
  WARN("screenshot: luminance variance " << var << ", " << 100.0 * inked / n << "% of pixels dark");
  CHECK(var > 100);              // a blank (one-colour) page has 0
  CHECK(inked > n / 50);         // text, plots and images: more than 2% of the page is ink

  // 2. The DOM after load, with a probe the test adds to a copy of the page (the page itself has
  // no script): JS errors, and images that did not decode (a bad data URI logs nothing).
  std::string probe = page;
  const std::string script =
      "<script>window.hccErrors=[];window.addEventListener('error',e=>hccErrors.push(String(e.message)));"
      "window.addEventListener('load',()=>{let b=0;for(const i of document.images)if(!i.complete||"
      "i.naturalWidth===0)b++;const d=document.createElement('div');d.id='hashcc-probe';"
      "d.dataset.images=document.images.length;d.dataset.broken=b;d.dataset.errors=hccErrors.length;"
      "d.dataset.sections=document.querySelectorAll('section').length;"
      "d.dataset.svgs=document.querySelectorAll('svg').length;document.body.appendChild(d);});</script>";
  probe.insert(probe.find("</body>"), script);
  put(dir + "/probe.html", probe);
  const std::string dom = dir + "/dom.html";
  const std::string cmd2 = base + fmt::format("--virtual-time-budget=10000 --dump-dom file://{} > {} 2> /dev/null",
                                              shell_quote(dir + "/probe.html"), shell_quote(dom));
  REQUIRE(std::system(cmd2.c_str()) == 0);
  const std::string d = slurp(dom);
  std::smatch m;
  REQUIRE(std::regex_search(d, m, std::regex("<div id=\"hashcc-probe\" data-images=\"(\\d+)\" data-broken=\"(\\d+)\" "
                                             "data-errors=\"(\\d+)\" data-sections=\"(\\d+)\" data-svgs=\"(\\d+)\"")));
  INFO(m[0].str());
  const int test_views = int(count(section_of(page, "test-views"), "<img "));
  CHECK(std::stoi(m[1]) == test_views + 2 * 6);  // photo, render, error a view; colour, depth a frame
  CHECK(test_views == 3 * 2);                     // 12 views: test views 0 and 8
  CHECK(std::stoi(m[2]) == 0);
  CHECK(std::stoi(m[3]) == 0);
  CHECK(std::stoi(m[4]) == 7);
  CHECK(std::stoi(m[5]) == 6);  // 3 curves, the camera error, top and side views
}
