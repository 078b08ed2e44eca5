// `hashcc study` (tools/study.h) and its SVG writer (tools/svg.h): tick positions on log axes,
// escaping, Pareto fronts, the CSV, the plan, the report on a hand-made results.csv (including
// the fern comparison), and end to end: a 2 variants × 2 budgets study on a tiny simulated scene
// run through child processes of the real binary — well-formed CSV and SVGs, and a restart that
// skips finished runs and redoes an interrupted one.
#include <catch2/catch.hpp>

#include <cmath>
#include <fmt/core.h>
#include <cstdlib>
#include <map>
#include <set>
#include <sstream>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/fileio.h"
#include "tools/study.h"
#include "tools/svg.h"
#include "tools/cli.h"
#include "test/fixtures.h"
#include "test/xml_check.h"
#include "tools/simulator.h"

namespace fs = std::filesystem;
using namespace hashcc;
using hashcc::test::cli;
using hashcc::test::tmp;
using hashcc::test::xml_problem;

namespace {

std::string slurp(const std::string& path) { return read_file_bytes(path, int64_t(1) << 26); }

void write_text(const std::string& path, const std::string& text) {
  std::ofstream f(path);
  f << text;
}

// One results.csv row: the cells of `v` in `cols` order, the rest empty.
std::string csv_row(const std::vector<std::string>& cols, std::map<std::string, std::string> v) {
  std::string row;
  for (size_t i = 0; i < cols.size(); ++i) {
    if (i) row += ',';
    if (v.count(cols[i])) row += v[cols[i]];
  }
  return row + "\n";
}

// The report.md that write_study_report makes from `csv` alone, in a fresh folder `name`.
std::string report_from_csv(const std::string& name, const std::string& csv) {
  const std::string dir = tmp(name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  write_text(dir + "/results.csv", csv);
  write_study_report(dir);
  return slurp(dir + "/report.md");
}

}  // namespace

TEST_CASE("svg: log-axis ticks and their pixel positions", "[study]") {
  CHECK(svg::log_ticks(1, 1000) ==
        std::vector<double>{1, 2, 5, 10, 20, 50, 100, 200, 500, 1000});
  CHECK(svg::log_ticks(1, 1e6) == std::vector<double>{1, 10, 100, 1000, 1e4, 1e5, 1e6});
  CHECK(svg::log_ticks(20, 90) == std::vector<double>{20, 30, 40, 50, 60, 70, 80, 90});
  CHECK(svg::log_ticks(0.05, 0.5) == std::vector<double>{0.05, 0.1, 0.2, 0.5});
  svg::Scale s{1, 1000, 0, 300, true};
  CHECK(s.map(1) == Approx(0));
  CHECK(s.map(10) == Approx(100));
  CHECK(s.map(100) == Approx(200));
  CHECK(s.map(1000) == Approx(300));
  CHECK(s.map(std::sqrt(10.0)) == Approx(50));
  svg::Scale y{10, 20, 400, 0, false};  // a y axis: pixels grow downwards
  CHECK(y.map(15) == Approx(200));
  CHECK(svg::linear_ticks(0, 1) == std::vector<double>{0, 0.2, 0.4, 0.6, 0.8, 1});
  CHECK(svg::linear_ticks(13.2, 18.7, 6) == std::vector<double>{14, 15, 16, 17, 18});
  double lo = 3.1, hi = 470;
  svg::nice_range(&lo, &hi, true);
  CHECK(lo == 2);
  CHECK(hi == 500);
  lo = 13.2, hi = 18.7;
  svg::nice_range(&lo, &hi, false);
  CHECK(lo == 13);
  CHECK(hi == 19);
  lo = hi = 5;  // a single value still gives a range
  svg::nice_range(&lo, &hi, false);
  CHECK(lo < 5);
  CHECK(hi > 5);
  CHECK(svg::tick_label(0.2) == "0.2");
  CHECK(svg::tick_label(20) == "20");
}

TEST_CASE("svg: text is escaped and the documents are well-formed", "[study]") {
  CHECK(svg::escape("a<b & \"c\" 'd' >") == "a&lt;b &amp; &quot;c&quot; &apos;d&apos; &gt;");
  CHECK(xml_problem("<a><b x=\"1\"/></a>") == "");
  CHECK(xml_problem("<a><b x=1/></a>") != "");       // the checker itself catches problems
  CHECK(xml_problem("<a>R&D</a>") != "");
  CHECK(xml_problem("<a><b></a></b>") != "");
  svg::Plot p;
  p.title = "PSNR <vs> time & \"more\"";
  p.x = {"time (s, log scale)", true};
  p.y = {"PSNR (dB)", false};
  p.notes = {"a note with < and &"};
  svg::Series a, b;
  a.name = "HashCC & co";
  a.x = {1, 10, 100};
  a.y = {12, 15, 18};
  b.name = "sh";
  b.x = {2, 20, std::nan("")};
  b.y = {11, 14, 99};
  b.dash = "6,4";
  p.series = {a, b};
  p.hlines = {{13.5, "do nothing <ref>"}};
  const std::string doc = svg::render(p);
  CHECK(xml_problem(doc) == "");
  CHECK(doc.find("PSNR &lt;vs&gt; time &amp; &quot;more&quot;") != std::string::npos);
  CHECK(doc.find("HashCC &amp; co") != std::string::npos);
  CHECK(doc.find("<polyline") != std::string::npos);
  // Log x axis 1..100: the tick labels 1, 2, 5, 10, 20, 50, 100 are drawn.
  for (const char* t : {">1<", ">2<", ">5<", ">10<", ">50<", ">100<"})
    CHECK(doc.find(t) != std::string::npos);
  svg::BarChart c;
  c.title = "step <time>";
  c.value_label = "ms per step";
  c.categories = {"render & composite", "backward"};
  c.series = {{"hashcc, 2 threads", {10, 20}}, {"sh", {5, std::nan("")}}};
  const std::string bars = svg::render(c);
  CHECK(xml_problem(bars) == "");
  CHECK(bars.find("render &amp; composite") != std::string::npos);
}

TEST_CASE("svg: Pareto front of less time, more PSNR", "[study]") {
  const std::vector<double> x = {10, 20, 20, 40, 5, 80, std::nan("")};
  const std::vector<double> y = {15, 14, 17, 16, 12, 18, 30};
  CHECK(svg::pareto_front(x, y) == std::vector<int>{4, 0, 2, 5});
}

TEST_CASE("study: knobs, plan order and ids, CSV round trip", "[study]") {
  StudyOptions o;
  o.budgets = {2, 1};
  o.variants = {"sh", "hashcc"};
  parse_study_knob("samples=32,64", &o);
  parse_study_knob("res=8", &o);
  CHECK(o.samples == std::vector<int>{32, 64});
  CHECK(o.images == std::vector<std::string>{"images_8"});
  CHECK_THROWS_AS(parse_study_knob("depth=3", &o), Error);
  CHECK_THROWS_AS(parse_study_knob("samples=abc", &o), Error);
  CHECK_THROWS_AS(parse_study_knob("width", &o), Error);
  CHECK_THROWS_AS(parse_number_list("--budgets", "1,,2"), Error);
  const auto plan = study_plan(o);
  REQUIRE(plan.size() == 8);
  CHECK(plan[0].id == "b1_sh_s32_images_8");
  CHECK(plan[1].id == "b1_hashcc_s32_images_8");
  CHECK(plan[2].id == "b1_sh_s64_images_8");
  CHECK(plan[7].id == "b2_hashcc_s64_images_8");
  CHECK(plan[7].budget_minutes == 2);
  // The preset knob: one more dimension, named in the id, before the variants.
  StudyOptions op;
  op.budgets = {15};
  op.variants = {"hashcc"};
  parse_study_knob("preset=paper,laptop", &op);
  CHECK_THROWS_AS(parse_study_knob("preset=turbo", &op), Error);
  const auto pplan = study_plan(op);
  REQUIRE(pplan.size() == 2);
  CHECK(pplan[0].id == "b15_hashcc_paper");
  CHECK(pplan[1].id == "b15_hashcc_laptop");
  CHECK(pplan[1].preset == "laptop");
  // The field and bootstrap knobs: a bootstrap only on the MLP, and only below the budget.
  StudyOptions of;
  of.budgets = {4, 15};
  of.variants = {"hashcc"};
  parse_study_knob("field=mlp,grid", &of);
  parse_study_knob("bootstrap=0,5", &of);
  CHECK_THROWS_AS(parse_study_knob("field=voxels", &of), Error);
  CHECK_THROWS_AS(parse_study_knob("bootstrap=-1", &of), Error);
  std::vector<std::string> ids;
  for (const auto& r : study_plan(of)) ids.push_back(r.id);
  CHECK(ids == std::vector<std::string>{"b4_hashcc_mlp", "b4_hashcc_grid", "b15_hashcc_mlp",
                                        "b15_hashcc_mlp_boot5", "b15_hashcc_grid"});
  CHECK(study_plan(of)[3].bootstrap == 5);
  CHECK(study_plan(of)[4].field == "grid");
  // Restarts cut a grid field's budget: a grid run's or a bootstrap's grid phase, not a plain
  // MLP run's.
  StudyOptions orr;
  orr.budgets = {15};
  orr.variants = {"hashcc"};
  parse_study_knob("field=mlp,grid", &orr);
  parse_study_knob("bootstrap=0,5", &orr);
  parse_study_knob("restarts=0,1", &orr);
  CHECK_THROWS_WITH(parse_study_knob("restarts=1.5", &orr), Catch::Contains("restarts"));
  ids.clear();
  for (const auto& r : study_plan(orr)) ids.push_back(r.id);
  CHECK(ids == std::vector<std::string>{"b15_hashcc_mlp", "b15_hashcc_mlp_boot5",
                                        "b15_hashcc_mlp_boot5_r1", "b15_hashcc_grid",
                                        "b15_hashcc_grid_r1"});
  CHECK(study_plan(orr)[4].restarts == 1);

  const std::string p = tmp("csv.csv");
  write_text(p, "a,b,c\n1,\"x, \"\"y\"\"\",\n2,,z\n");
  const CsvTable t = read_csv(p);
  REQUIRE(t.header == std::vector<std::string>{"a", "b", "c"});
  REQUIRE(t.rows.size() == 2);
  CHECK(t.rows[0][1] == "x, \"y\"");
  CHECK(t.rows[0][2] == "");
  CHECK(csv_field("x, \"y\"") == "\"x, \"\"y\"\"\"");
  write_text(p, "a,b\n1\n");
  CHECK_THROWS_AS(read_csv(p), Error);
  CHECK(read_csv(tmp("no_such.csv")).rows.empty());
  // Bad flags end as exit 2 before anything runs.
  CHECK(cli({"study", "--data", tmp("nowhere"), "--out", tmp("bad"), "--knobs", "depth=3"}) == 2);
  CHECK(cli({"study", "--data", tmp("nowhere"), "--out", tmp("bad"), "--variants", "nerf"}) == 2);
}

TEST_CASE("study: the report from a results.csv, with the fern comparison", "[study]") {
  const std::string dir = tmp("fern_report");
  fs::remove_all(dir);
  fs::create_directories(dir);
  write_text(dir + "/study.json", R"({"data": "/data/llff/fern", "refine_epochs": 20})");
  const auto& cols = study_columns();
  std::string csv;
  for (size_t i = 0; i < cols.size(); ++i) {
    if (i) csv += ',';
    csv += cols[i];
  }
  csv += "\n";
  struct R { const char* v; double b, sec, psnr, rel; };
  const R rs[] = {{"nerfmm", 1, 60, 15.0, 3.0}, {"hashcc", 1, 61, 15.5, 2.9},
                  {"nerfmm", 2, 120, 16.0, 2.5}, {"hashcc", 2, 119, 16.8, 2.0}};
  for (const R& r : rs) {
    std::map<std::string, std::string> v = {
        {"id", fmt::format("b{}_{}", r.b, r.v)}, {"variant", r.v}, {"budget_minutes", fmt::format("{}", r.b)},
        {"samples", "64"}, {"width", "128"}, {"images", "images_8"}, {"image_width", "126"},
        {"image_height", "94"}, {"steps", "100"}, {"seconds", fmt::format("{}", r.sec)},
        {"psnr", fmt::format("{}", r.psnr)}, {"ssim", "0.4"}, {"rel_rot_err_deg", fmt::format("{}", r.rel)},
        {"rel_rot_do_nothing_deg", "3.1"}, {"peak_rss_mb", "300"}, {"refine_epochs", "20"}};
    csv += csv_row(cols, v);
  }
  write_text(dir + "/results.csv", csv);
  const std::string bench = dir + "/my_bench.json";
  write_text(bench, R"({"runs": [{"variant": "hashcc", "threads": 2, "ms_per_step": 30,
      "stages": {"rays": 1, "forward": 12, "backward": 15}},
      {"variant": "sh", "threads": 2, "ms_per_step": 25, "stages": {"forward": 10, "backward": 13}}]})");
  const auto files = write_study_report(dir, bench);
  CHECK(files.size() == 7);  // 5 SVGs + report.md + report.html
  for (const auto& f : files)
    if (f.ends_with(".svg")) {
      INFO(f);
      CHECK(xml_problem(slurp(dir + "/" + f)) == "");
    }
  const std::string md = slurp(dir + "/report.md");
  CHECK(md.find("at 1 min: hashcc 15.50 dB (100 steps) > nerfmm 15.00 dB (100 steps)") != std::string::npos);
  CHECK(md.find("at 2 min: hashcc 16.80 dB (100 steps) > nerfmm 16.00 dB (100 steps)") != std::string::npos);
  CHECK(md.find("published fern") != std::string::npos);
  CHECK(md.find("| HashCC | 22.27") != std::string::npos);
  CHECK(md.find("LPIPS: not computed (no weights)") != std::string::npos);
  CHECK(md.find("![Where a step's time goes](step_time.svg)") != std::string::npos);
  // report.html: the same study as one page — every SVG inline (each with its own clip id),
  // the results table, report.md's text; nothing fetched from elsewhere.
  const std::string page = slurp(dir + "/report.html");
  for (const char* id : {"id=\"settings\"", "id=\"plots\"", "id=\"results\"", "id=\"findings\""}) {
    INFO(id);
    CHECK(page.find(id) != std::string::npos);
  }
  size_t svgs = 0;
  for (size_t at = 0; (at = page.find("<svg ", at)) != std::string::npos; ++at) ++svgs;
  CHECK(svgs == 5);
  CHECK(page.find("<?xml") == std::string::npos);
  CHECK(page.find("id=\"frame\"") == std::string::npos);  // renamed p0-frame, p1-frame, ...
  CHECK(page.find("id=\"p3-frame\"") != std::string::npos);
  CHECK(page.find("at 1 min: hashcc 15.50 dB (100 steps)") != std::string::npos);
  CHECK(page.find("src=\"http") == std::string::npos);
  // Without a bench file the bar chart is skipped with a note.
  const std::string dir2 = tmp("plain_report");
  fs::remove_all(dir2);
  fs::create_directories(dir2);
  fs::copy_file(dir + "/results.csv", dir2 + "/results.csv");
  const auto files2 = write_study_report(dir2);
  CHECK(files2.size() == 6);
  CHECK(slurp(dir2 + "/report.md").find("No step-time breakdown") != std::string::npos);
  CHECK(slurp(dir2 + "/report.md").find("published fern") == std::string::npos);
  CHECK(slurp(dir2 + "/report.md").find("Knobs compared") == std::string::npos);  // one knob set

  // With the runs' log.csv files: training curves of the largest budget that has logs (2 min
  // here, even though the 1-minute runs have logs too), and the reference focal as a line.
  auto write_log = [&](const std::string& id, int n, double fx0) {
    fs::create_directories(dir2 + "/runs/" + id);
    std::string log = "step,seconds,loss,psnr,psnr_cc,lr_net,lr_pose,lr_focal,fx,fy\n";
    for (int k = 1; k <= n; ++k)
      log += fmt::format("{},{},0.1,{},{},5e-4,{},{},{},{}\n", k, 0.5 * k, 10 + 0.01 * k, 10.5 + 0.01 * k,
                         1e-3 * std::pow(0.99, k), 1e-3 * std::pow(0.99, k), fx0 - 0.1 * k, fx0 - 0.2 * k);
    write_text(dir2 + "/runs/" + id + "/log.csv", log);
  };
  write_log("b1_nerfmm", 120, 130);
  write_log("b2_hashcc", 240, 128);
  write_log("b2_nerfmm", 240, 129);
  const auto files3 = write_study_report(dir2);
  CHECK(files3.size() == 9);  // + 3 curve plots
  for (const char* f : {"curves_psnr.svg", "curves_focal.svg", "curves_camera_lr.svg"}) {
    INFO(f);
    const std::string svg = slurp(dir2 + "/" + f);
    CHECK(xml_problem(svg) == "");
    CHECK(svg.find("the runs of the 2 min budget") != std::string::npos);
    CHECK(svg.find("HashCC") != std::string::npos);
  }
  CHECK(slurp(dir2 + "/report.md").find("![Train PSNR vs time](curves_psnr.svg)") != std::string::npos);
  CHECK(slurp(dir2 + "/report.md").find("curves_rotation.svg") == std::string::npos);  // no csv yet
  // With camera_error.csv in one 2-minute run: the rotation curve, its do-nothing line (the
  // step-0 row) and its link in report.md.
  write_text(dir2 + "/runs/b2_hashcc/camera_error.csv",
             "step,seconds,rel_rot_deg,sim3_dR_deg,sim3_dT,fx,fy,ref_focal\n"
             "0,0.000,7.7688,,,504,378,407.6\n25,12.5,6.5,9.1,0.03,500,380,407.6\n"
             "50,25.0,3.25,5.0,0.02,450,400,407.6\n");
  const auto files4 = write_study_report(dir2);
  CHECK(files4.size() == 10);  // + curves_rotation.svg
  const std::string rot = slurp(dir2 + "/curves_rotation.svg");
  CHECK(xml_problem(rot) == "");
  CHECK(rot.find("do nothing (7.77°)") != std::string::npos);
  CHECK(slurp(dir2 + "/report.md").find("](curves_rotation.svg)") != std::string::npos);

  // Two knob sets (here two presets): the side-by-side table.
  std::string csv3 = slurp(dir + "/results.csv");
  const size_t last_comma = csv3.find_last_of(',', csv3.find('\n') - 1);
  CHECK(csv3.substr(last_comma + 1, csv3.find('\n') - last_comma - 1) == "preset");  // preset is the last column
  std::string out3;
  std::istringstream in(csv3);
  std::string line;
  for (int k = 0; std::getline(in, line); ++k) out3 += line + (k == 0 ? "" : k % 2 ? "paper" : "laptop") + "\n";
  const std::string md3 = report_from_csv("knob_report", out3);
  CHECK(md3.find("## Knobs compared at each budget") != std::string::npos);
  CHECK(md3.find("| 2 min | HashCC | 64 samples, width 128, images_8, preset laptop | 100 | 16.80 dB") != std::string::npos);
  // The field and the bootstrap are knobs too: runs that differ only in them are told apart
  // (the fern study's 30-minute MLP, grid and bootstrapped runs were one line before).
  std::string csv4 = csv.substr(0, csv.find('\n') + 1);
  for (const R& r : rs) {
    std::map<std::string, std::string> v = {
        {"id", fmt::format("b{}_{}", r.b, r.v)}, {"variant", "hashcc"}, {"budget_minutes", "2"},
        {"samples", "64"}, {"width", "128"}, {"images", "images_8"}, {"steps", "100"},
        {"seconds", fmt::format("{}", r.sec)}, {"psnr", fmt::format("{}", r.psnr)},
        {"field", r.b == 2 && r.v == std::string("hashcc") ? "grid" : "mlp"},
        {"bootstrap_minutes", r.b == 2 && r.v == std::string("nerfmm") ? "1" : "0"}};
    csv4 += csv_row(cols, v);
  }
  const std::string md4 = report_from_csv("field_report", csv4);
  CHECK(md4.find("| 2 min | HashCC | 64 samples, width 128, images_8, grid field | 100 | 16.80 dB") != std::string::npos);
  CHECK(md4.find("| 2 min | HashCC | 64 samples, width 128, images_8, bootstrap 1 min | 100 | 16.00 dB") != std::string::npos);
  CHECK(md4.find("| 2 min | HashCC | 64 samples, width 128, images_8 | 100 | 15.") != std::string::npos);
}

TEST_CASE("study: 2 variants x 2 budgets on a tiny scene, then a restart", "[study][e2e]") {
  const std::string data = test::sim_scene("scene", 6, 32, 24, 1);
  const std::string out = tmp("out");
  fs::remove_all(out);
  StudyOptions o;
  o.data = data;
  o.out = out;
  o.budgets = {0.05, 0.1};
  o.variants = {"sh", "hashcc"};
  o.widths = {16};
  o.samples = {8};
  o.refine_epochs = 2;
  o.threads = 1;
  o.train_args = {"--rays", "64"};
  o.exe = HASHCC_BINARY;
  o.quiet = true;
  const StudySummary s = run_study(o);
  INFO((s.failed.empty() ? std::string() : s.failed[0]));
  REQUIRE(s.failed.empty());
  CHECK(s.planned == 4);
  CHECK(s.done == 4);
  CHECK(s.skipped == 0);

  const CsvTable t = read_csv(out + "/results.csv");
  CHECK(t.header == study_columns());
  for (const char* c : {"variant", "budget_minutes", "steps", "seconds", "psnr", "ssim", "lpips",
                        "rot_err_deg", "trans_err", "peak_rss_mb", "rel_rot_err_deg",
                        "rel_rot_do_nothing_deg", "samples", "width", "images"})
    CHECK(t.col(c) >= 0);
  REQUIRE(t.rows.size() == 4);
  for (const auto& r : t.rows) {
    auto at = [&](const char* c) { return r[size_t(t.col(c))]; };
    CHECK((at("variant") == "sh" || at("variant") == "hashcc"));
    CHECK((at("budget_minutes") == "0.05" || at("budget_minutes") == "0.1"));
    CHECK(std::stoi(at("steps")) > 0);
    CHECK(std::stod(at("seconds")) > 0);
    CHECK(std::isfinite(std::stod(at("psnr"))));
    CHECK(std::stod(at("ssim")) <= 1);
    CHECK(at("lpips").empty());  // no weights: null
    CHECK(std::stod(at("rel_rot_do_nothing_deg")) > 0);
    CHECK(std::stod(at("peak_rss_mb")) > 0);
    CHECK(at("samples") == "8");
    CHECK(at("width") == "16");
    CHECK(at("images") == "images");
    CHECK(at("refine_epochs") == "2");
    CHECK(fs::exists(out + "/runs/" + at("id") + "/eval/metrics.json"));
    // Each run has its own page (train wrote it, eval redrew it with the test views), and the
    // study's page links to it.
    const std::string run_page = slurp(out + "/runs/" + at("id") + "/report.html");
    CHECK(run_page.find("<section id=\"test-views\">") != std::string::npos);
    CHECK(run_page.find("Not evaluated yet") == std::string::npos);
    CHECK(slurp(out + "/report.html").find("href=\"runs/" + at("id") + "/report.html\"") != std::string::npos);
  }
  for (const char* f : {"psnr_vs_time.svg", "rot_err_vs_time.svg", "rel_rot_vs_time.svg", "pareto.svg"}) {
    INFO(f);
    REQUIRE(fs::exists(out + "/" + f));
    CHECK(xml_problem(slurp(out + "/" + f)) == "");
  }
  const std::string md = slurp(out + "/report.md");
  CHECK(md.find("at 3 s: ") != std::string::npos);
  CHECK(md.find("at 6 s: ") != std::string::npos);
  CHECK(md.find("No step-time breakdown") != std::string::npos);

  // Restart: everything is skipped, nothing is added.
  auto count_runs = [&] {
    int n = 0;
    for (auto& e : fs::directory_iterator(out + "/runs")) n += e.is_directory();
    return n;
  };
  CHECK(count_runs() == 4);
  const StudySummary s2 = run_study(o);
  CHECK(s2.skipped == 4);
  CHECK(s2.done == 0);
  CHECK(read_csv(out + "/results.csv").rows.size() == 4);
  CHECK(count_runs() == 4);

  // An interrupted run (folder present, no row) is redone from scratch.
  const std::string csv = slurp(out + "/results.csv");
  const std::string trimmed = csv.substr(0, csv.rfind('\n', csv.size() - 2) + 1);
  write_file_atomic(out + "/results.csv", trimmed);
  const std::string last_id = t.rows.back()[0];
  write_text(out + "/runs/" + last_id + "/junk.txt", "half-done");
  const StudySummary s3 = run_study(o);
  CHECK(s3.skipped == 3);
  CHECK(s3.done == 1);
  CHECK(read_csv(out + "/results.csv").rows.size() == 4);
  CHECK(read_csv(out + "/results.csv").rows.back()[0] == last_id);
  CHECK_FALSE(fs::exists(out + "/runs/" + last_id + "/junk.txt"));
  CHECK(count_runs() == 4);

  // Another scene in the same study folder is refused.
  StudyOptions other = o;
  other.refine_epochs = 3;
  CHECK_THROWS_AS(run_study(other), Error);
}

TEST_CASE("study: a results.csv from an older version is carried into this layout", "[study]") {
  const std::string data = test::sim_scene("migrate_scene", 6, 32, 24, 1);
  const std::string out = tmp("migrate_out");
  fs::remove_all(out);
  fs::create_directories(out);
  StudyOptions o;
  o.data = data;
  o.out = out;
  o.budgets = {0.05};
  o.variants = {"sh"};
  o.quiet = true;
  // An older header lacks the newest columns; its one row is the plan's only run, so the
  // restart trains nothing and only migrates + reports.
  std::vector<std::string> old_cols;
  for (const auto& c : study_columns())
    if (c != "preset" && c != "load_avg") old_cols.push_back(c);
  std::string text, row;
  for (size_t i = 0; i < old_cols.size(); ++i) {
    text += (i ? "," : "") + old_cols[i];
    const std::string& c = old_cols[i];
    row += (i ? "," : "") + (c == "id" ? std::string("b0.05_sh_images") : c == "variant" ? std::string("sh")
             : c == "budget_minutes" ? std::string("0.05") : c == "images" ? std::string("images")
             : std::string("1"));
  }
  write_text(out + "/results.csv", text + "\n" + row + "\n");
  const StudySummary s = run_study(o);
  CHECK(s.planned == 1);
  CHECK(s.skipped == 1);
  const CsvTable t = read_csv(out + "/results.csv");
  CHECK(t.header == study_columns());
  REQUIRE(t.rows.size() == 1);
  CHECK(t.rows[0][size_t(t.col("id"))] == "b0.05_sh_images");
  CHECK(t.rows[0][size_t(t.col("preset"))] == "");
  CHECK(t.rows[0][size_t(t.col("steps"))] == "1");
  // A column this version does not know is refused, naming it.
  write_text(out + "/results.csv", text + ",mystery\n" + row + ",1\n");
  CHECK_THROWS_AS(run_study(o), Error);
}

TEST_CASE("study: a bootstrapped run's seconds include its grid phase", "[study]") {
  const std::string dir = tmp("boot_seconds");
  fs::remove_all(dir);
  fs::create_directories(dir + "/bootstrap");
  const std::string header = "step,seconds,loss,psnr,psnr_cc,lr_net,lr_pose,lr_focal,fx,fy\n";
  write_text(dir + "/log.csv", header + "1,2.5,0.1,10,10,0,0,0,1,1\n140,597.0,0.1,10,10,0,0,0,1,1\n");
  auto [steps, seconds] = study_run_steps_seconds(dir);
  CHECK(steps == 140);
  CHECK(seconds == 597.0);  // no bootstrap/log.csv yet: the run's own clock
  write_text(dir + "/bootstrap/log.csv", header + "4750,1200.5,0.1,10,10,0,0,0,1,1\n");
  std::tie(steps, seconds) = study_run_steps_seconds(dir);
  CHECK(steps == 140);               // the paper network's steps
  CHECK(seconds == 597.0 + 1200.5);  // its whole budget
  // A bootstrap cut into stages by --restarts: every stage's seconds.
  fs::create_directories(dir + "/bootstrap/stage1");
  write_text(dir + "/bootstrap/stage1/log.csv", header + "2000,600.25,0.1,10,10,0,0,0,1,1\n");
  std::tie(steps, seconds) = study_run_steps_seconds(dir);
  CHECK(steps == 140);
  CHECK(seconds == 597.0 + 1200.5 + 600.25);
}

TEST_CASE("study: a run with restarts counts every stage's steps and seconds", "[study]") {
  const std::string dir = tmp("restart_seconds");
  fs::remove_all(dir);
  fs::create_directories(dir);
  const std::string header = "step,seconds,loss,psnr,psnr_cc,lr_net,lr_pose,lr_focal,fx,fy\n";
  write_text(dir + "/log.csv", header + "3000,600.0,0.1,10,10,0,0,0,1,1\n");
  for (int k : {1, 2}) {
    fs::create_directories(fmt::format("{}/stage{}", dir, k));
    write_text(fmt::format("{}/stage{}/log.csv", dir, k),
               header + fmt::format("{},{},0.1,10,10,0,0,0,1,1\n", 1000 * k, 300.5 * k));
  }
  const auto [steps, seconds] = study_run_steps_seconds(dir);
  CHECK(steps == 3000 + 1000 + 2000);
  CHECK(seconds == 600.0 + 300.5 + 601.0);
}

TEST_CASE("study: a staged run's steps and seconds come from its plan.json, no folder probed",
          "[study][plan]") {
  const std::string dir = tmp("plan_seconds");
  fs::remove_all(dir);
  fs::create_directories(dir + "/boot");
  const std::string header = "step,seconds,loss,psnr,psnr_cc,lr_net,lr_pose,lr_focal,fx,fy\n";
  // A bootstrap-like plan: a grid stage in boot/, then the MLP in the run folder; a stage1/ folder
  // the plan does not name is not counted.
  write_text(dir + "/plan.json", R"({"run": {"field": "mlp"}, "stages": [
      {"dir": "boot", "set": {"field": "grid"}}, {"dir": ".", "set": {}}]})");
  write_text(dir + "/boot/log.csv", header + "500,100.5,0.1,10,10,0,0,0,1,1\n");
  write_text(dir + "/log.csv", header + "40,200.0,0.1,10,10,0,0,0,1,1\n");
  fs::create_directories(dir + "/stage1");
  write_text(dir + "/stage1/log.csv", header + "999,999.0,0.1,10,10,0,0,0,1,1\n");
  const auto [steps, seconds] = study_run_steps_seconds(dir);
  CHECK(steps == 40);
  CHECK(seconds == 100.5 + 200.0);
}

namespace {

// Runs a command file as CI does: GNU parallel when on the PATH, else bash. Returns its status;
// *how says which ran it.
int run_command_file(const std::string& file, std::string* how) {
  const bool gnu = std::system("parallel --version 2>/dev/null | grep -q 'GNU parallel'") == 0;
  *how = gnu ? "GNU parallel -j 2" : "bash (GNU parallel is not on the PATH)";
  const std::string cmd = gnu ? "parallel --will-cite -j 2 < '" + file + "' > /dev/null 2>&1"
                              : "bash '" + file + "' > /dev/null 2>&1";
  return std::system(cmd.c_str());
}

std::vector<std::string> file_lines(const std::string& path) {
  std::istringstream in(slurp(path));
  std::vector<std::string> out;
  for (std::string l; std::getline(in, l);) if (!l.empty()) out.push_back(l);
  return out;
}

}  // namespace

TEST_CASE("study: --emit-commands + a scheduler + --collect = the direct study; a failed run is "
          "reported", "[study][e2e]") {
  const std::string data = test::sim_scene("fanout_scene", 6, 32, 24, 1);
  StudyOptions o;
  o.data = data;
  o.budgets = {15, 30};  // steps: deterministic, unlike minutes
  o.budget_steps = true;
  o.variants = {"sh", "hashcc"};
  o.widths = {16};
  o.samples = {8};
  o.refine_epochs = 2;
  o.threads = 1;
  o.train_args = {"--rays", "64"};
  o.exe = HASHCC_BINARY;
  o.quiet = true;

  // (a) directly.
  StudyOptions direct = o;
  direct.out = tmp("fanout_direct");
  fs::remove_all(direct.out);
  const StudySummary s = run_study(direct);
  INFO((s.failed.empty() ? std::string() : s.failed[0]));
  REQUIRE(s.done == 4);

  // (b) emitted, run by the scheduler, collected.
  StudyOptions fan = o;
  fan.out = tmp("fanout_emit");
  fs::remove_all(fan.out);
  const std::string file = tmp("fanout_cmds.txt");
  REQUIRE(write_study_commands(fan, file) == 4);
  const auto lines = file_lines(file);
  REQUIRE(lines.size() == 4);
  CHECK(read_csv(fan.out + "/results.csv").rows.empty());  // nothing run yet
  for (const auto& l : lines) {
    CHECK(l.rfind("rm -rf /", 0) == 0);  // absolute paths
    CHECK(l.find(std::string(HASHCC_BINARY) + " train ") != std::string::npos);
    CHECK(l.find(" && ") != std::string::npos);
    CHECK(l.find("eval.log") != std::string::npos);
  }
  std::string how;
  const int rc = run_command_file(file, &how);
  WARN("the emitted lines ran with " << how);
  CHECK(rc == 0);
  const StudySummary c = collect_study(fan.out);
  INFO((c.failed.empty() ? std::string() : c.failed[0]));
  CHECK(c.failed.empty());
  CHECK(c.done == 4);
  for (const char* f : {"results.csv", "report.md", "report.html", "psnr_vs_time.svg", "pareto.svg"})
    CHECK(fs::exists(fan.out + "/" + f));

  // The same results.csv but for what only the study's own children measure (clocks, memory,
  // load): every other cell is equal to the printed digit.
  const CsvTable a = read_csv(direct.out + "/results.csv"), b = read_csv(fan.out + "/results.csv");
  REQUIRE(a.header == b.header);
  REQUIRE(a.rows.size() == 4);
  REQUIRE(b.rows.size() == 4);
  const std::set<std::string> measured = {"seconds", "train_wall_seconds", "eval_seconds",
                                          "peak_rss_mb", "train_rss_mb", "eval_rss_mb",
                                          "train_cpu_seconds", "load_avg"};
  for (size_t i = 0; i < a.rows.size(); ++i)
    for (size_t k = 0; k < a.header.size(); ++k) {
      if (measured.count(a.header[k])) continue;
      INFO(a.rows[i][0] << " " << a.header[k]);
      CHECK(a.rows[i][k] == b.rows[i][k]);
    }
  CHECK(a.rows[0][size_t(a.col("steps"))] == "15");
  // Those the lines measured themselves (--rusage-json): filled in, not empty.
  for (const auto& row : b.rows)
    for (const char* m : {"train_wall_seconds", "eval_seconds", "peak_rss_mb", "train_cpu_seconds"})
      CHECK(study_number(row[size_t(b.col(m))]) >= (std::string(m) == "train_cpu_seconds" ? 0 : 1e-9));

  // A failed line and a line never run: collect names both (the failure with its log's last
  // line), gathers the other two and says so in its exit status.
  StudyOptions bad = o;
  bad.out = tmp("fanout_bad");
  fs::remove_all(bad.out);
  const std::string bad_file = tmp("fanout_bad_cmds.txt");
  REQUIRE(write_study_commands(bad, bad_file) == 4);
  auto bl = file_lines(bad_file);
  const size_t at = bl[0].find(" --seed 0 ");
  REQUIRE(at != std::string::npos);
  bl[0].replace(at, 10, " --seed not-a-number ");
  bl.pop_back();  // the last run is never started
  std::string text;
  for (const auto& l : bl) text += l + "\n";
  write_text(bad_file, text);
  std::string how2;
  CHECK(run_command_file(bad_file, &how2) != 0);
  const StudySummary cb = collect_study(bad.out);
  CHECK(cb.done == 2);
  REQUIRE(cb.failed.size() == 2);
  StudyOptions resolved = bad;
  resolved.images_default = "images";  // the smallest folder, as the study resolved it
  const auto plan = study_plan(resolved);
  CHECK(cb.failed[0].rfind(plan[0].id + ": train failed: ", 0) == 0);
  CHECK(cb.failed[0].find("seed") != std::string::npos);  // train's own error line
  CHECK(cb.failed[1] == plan[3].id + ": not run");
  CHECK(read_csv(bad.out + "/results.csv").rows.size() == 2);
  CHECK(fs::exists(bad.out + "/report.html"));
  // The command line: exit status 1 when a run is missing, 0 once all are there.
  const std::string collect = std::string(HASHCC_BINARY) + " study --collect '" + bad.out + "' > /dev/null 2>&1";
  CHECK(std::system(collect.c_str()) != 0);
  const std::string direct_collect = std::string(HASHCC_BINARY) + " study --collect '" + fan.out + "' > /dev/null 2>&1";
  CHECK(std::system(direct_collect.c_str()) == 0);
}
