#include "model/golden_step.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <set>

#include "camera/camera.h"
#include "model/camera_step.h"
#include "core/error.h"
#include "core/fileio.h"
#include "core/npy.h"
#include "render/sampler.h"

namespace hashcc {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

std::string shape_text(const std::vector<int64_t>& shape) {
  NpyArray a;
  a.shape = shape;
  return a.shape_str();
}

// Reads dir/name.npy with a shape check. Every failure names the file and the expected shape.
NpyArray load(const std::string& dir, const std::string& name, const std::vector<int64_t>& shape,
              const std::string& what = "float64") {
  const std::string path = dir + "/" + name + ".npy";
  std::string want = "shape " + shape_text(shape) + " " + what;
  for (size_t p; (p = want.find("-1")) != std::string::npos;) want.replace(p, 2, "any");
  if (!fs::exists(path)) throw Error(path, "", "missing", want);
  try {
    return read_npy_shape(path, shape);
  } catch (const Error& e) {
    if (!e.expected.empty()) throw;
    throw Error(e.file, e.field, e.problem, want);  // malformed file: say what was wanted
  }
}

std::vector<int64_t> load_index(const std::string& dir, const std::string& name, int64_t limit,
                                const char* axis) {
  NpyArray a = load(dir, name, {-1}, "int64");
  const std::string path = dir + "/" + name + ".npy";
  HCC_REQUIRE(a.dtype.find('i') != std::string::npos, path, "dtype",
              "holds {} (expected int64 {} indices)", a.dtype, axis);
  HCC_REQUIRE(a.size() >= 1, path, "shape", "is empty (expected at least one {})", axis);
  std::vector<int64_t> v;
  for (double x : a.data) {
    HCC_REQUIRE(x >= 0 && x < double(limit), path, "", "{} {} outside the image (expected 0..{})",
                axis, int64_t(x), limit - 1);
    v.push_back(int64_t(x));
  }
  return v;
}

// config.json keys: required ones, then optional with the paper's values as defaults.
const std::vector<std::string> kConfigKeys = {
    "model", "H", "W", "samples", "ndc", "width", "rgb_width", "cc_levels", "cc_features",
    "cc_log2_table", "cc_base_res", "cc_max_res", "cc_hidden", "field", "grid_levels",
    "grid_features", "grid_log2_table", "grid_base_res", "grid_max_res", "grid_smooth",
    "grid_hidden", "grid_geo", "grid_rgb_hidden", "c2f_alpha", "fx_only"};

template <class V>
V get_key(const json& j, const std::string& key, const std::string& file, const char* expected) {
  try {
    return j.at(key).get<V>();
  } catch (const json::exception&) {
    throw Error(file, key, j.contains(key) ? "has the wrong type" : "missing", expected);
  }
}

int get_int(const json& j, const std::string& key, const std::string& file, int lo, int hi) {
  std::string want = fmt::format("an integer in [{}, {}]", lo, hi);
  HCC_REQUIRE(j.contains(key), file, key, "missing (expected {})", want);
  const json& v = j.at(key);
  if (!v.is_number_integer()) throw Error(file, key, "is not an integer", want);
  int64_t x = v.get<int64_t>();
  if (x < lo || x > hi) throw Error(file, key, fmt::format("is {}", x), want);
  return int(x);
}

double get_pos(const json& j, const std::string& key, const std::string& file) {
  HCC_REQUIRE(j.contains(key), file, key, "missing (expected a positive number)");
  const json& v = j.at(key);
  if (!v.is_number() || !(v.get<double>() > 0) || !std::isfinite(v.get<double>()))
    throw Error(file, key, "is not a positive number", "a positive number");
  return v.get<double>();
}

// "field" (default "mlp") and, for "grid", the grid field's keys (all required: a silent
// default would compare a different field); "c2f_alpha" (optional, default -1 = off): the
// coarse-to-fine α of ModelConfig::pos_c2f_alpha (Fourier bands, or grid levels).
void read_field_keys(const json& j, const std::string& cpath, ModelConfig& m) {
  if (j.contains("field")) {
    const std::string f = get_key<std::string>(j, "field", cpath, "\"mlp\" or \"grid\"");
    if (f != "mlp" && f != "grid") throw Error(cpath, "field", fmt::format("unknown field '{}'", f), "mlp or grid");
    m.field = parse_field(f);
  }
  if (m.field == Field::grid) {
    GridFieldConfig& g = m.gf;
    g.grid.levels = get_int(j, "grid_levels", cpath, 1, 64);
    g.grid.features = get_int(j, "grid_features", cpath, 1, 16);
    g.grid.log2_table = get_int(j, "grid_log2_table", cpath, 1, 26);
    g.grid.base_res = get_pos(j, "grid_base_res", cpath);
    g.grid.max_res = get_pos(j, "grid_max_res", cpath);
    HCC_REQUIRE(g.grid.max_res >= g.grid.base_res, cpath, "grid_max_res",
                "is {} (expected at least grid_base_res = {})", g.grid.max_res, g.grid.base_res);
    g.grid.smooth_dx = get_key<bool>(j, "grid_smooth", cpath, "true or false");
    g.hidden = get_int(j, "grid_hidden", cpath, 1, 4096);
    g.geo = get_int(j, "grid_geo", cpath, 1, 4096);
    g.rgb_hidden = get_int(j, "grid_rgb_hidden", cpath, 1, 4096);
  } else {
    for (const char* k : {"grid_levels", "grid_features", "grid_log2_table", "grid_base_res",
                          "grid_max_res", "grid_smooth", "grid_hidden", "grid_geo", "grid_rgb_hidden"})
      HCC_REQUIRE(!j.contains(k), cpath, k, "given without \"field\": \"grid\" (expected no grid_* key)");
  }
  if (j.contains("c2f_alpha")) {
    const json& v = j.at("c2f_alpha");
    if (!v.is_number() || !std::isfinite(v.get<double>()))
      throw Error(cpath, "c2f_alpha", "is not a number", "a number (< 0: off)");
    m.pos_c2f_alpha = v.get<double>();
  }
}

}  // namespace

std::vector<GoldenTensor> golden_parameter_files(const ModelLayout& L) {
  std::vector<GoldenTensor> t;
  for (const auto& tv : L.tensors) t.push_back({tv.name, tv.shape, tv.offset});
  t.push_back({"pose_r", {3}, -1});
  t.push_back({"pose_t", {3}, -1});
  t.push_back({"focal_ab", {2}, -1});
  return t;
}

std::string golden_config_json(const GoldenInputs& in) {
  const ModelConfig& m = in.model;
  json j = {{"model", variant_name(m.variant)},
            {"H", in.H},
            {"W", in.W},
            {"samples", in.S},
            {"ndc", in.ndc},
            {"width", m.width},
            {"rgb_width", m.rgb_width},
            {"cc_levels", m.cc.levels},
            {"cc_features", m.cc.features},
            {"cc_log2_table", m.cc.log2_table},
            {"cc_base_res", m.cc.base_res},
            {"cc_max_res", m.cc.max_res},
            {"cc_hidden", m.cc_hidden}};
  // Written only when they differ from the defaults, so the MLP inputs keep their config.
  if (m.field == Field::grid) {
    const GridFieldConfig& g = m.gf;
    j["field"] = "grid";
    j["grid_levels"] = g.grid.levels;
    j["grid_features"] = g.grid.features;
    j["grid_log2_table"] = g.grid.log2_table;
    j["grid_base_res"] = g.grid.base_res;
    j["grid_max_res"] = g.grid.max_res;
    j["grid_smooth"] = g.grid.smooth_dx;
    j["grid_hidden"] = g.hidden;
    j["grid_geo"] = g.geo;
    j["grid_rgb_hidden"] = g.rgb_hidden;
  }
  if (m.pos_c2f_alpha >= 0) j["c2f_alpha"] = m.pos_c2f_alpha;
  if (in.fx_only) j["fx_only"] = true;
  return j.dump(2) + "\n";
}

namespace {

// DIR/config.json into in (model, H, W, S, ndc, widths, hash grids, c2f); returns the model's name.
std::string read_golden_config(const std::string& cpath, GoldenInputs& in) {
  if (!fs::exists(cpath)) throw Error(cpath, "", "missing", "a JSON object (docs/golden-step.md)");
  json j;
  try {
    j = json::parse(read_file_bytes(cpath, 1 << 20));
  } catch (const json::exception& e) {
    throw Error(cpath, "", fmt::format("not valid JSON ({})", e.what()), "a JSON object");
  }
  if (!j.is_object()) throw Error(cpath, "", "not a JSON object", "a JSON object");
  for (auto it = j.begin(); it != j.end(); ++it)
    HCC_REQUIRE(std::find(kConfigKeys.begin(), kConfigKeys.end(), it.key()) != kConfigKeys.end(),
                cpath, it.key(), "unknown key (expected {})",
                fmt::format("{}", fmt::join(kConfigKeys.begin(), kConfigKeys.end(), ", ")));
  std::string model = get_key<std::string>(j, "model", cpath, "\"nerfmm\", \"sh\" or \"hashcc\"");
  try {
    in.model.variant = parse_variant(model);
  } catch (const Error&) {
    throw Error(cpath, "model", fmt::format("unknown model '{}'", model), "nerfmm, sh or hashcc");
  }
  in.H = get_int(j, "H", cpath, 1, 1 << 16);
  in.W = get_int(j, "W", cpath, 1, 1 << 16);
  in.S = get_int(j, "samples", cpath, 1, 4096);
  in.ndc = get_key<bool>(j, "ndc", cpath, "true or false");
  if (j.contains("fx_only")) in.fx_only = get_key<bool>(j, "fx_only", cpath, "true or false");
  ModelConfig& m = in.model;
  if (j.contains("width")) m.width = get_int(j, "width", cpath, 1, 4096);
  if (j.contains("rgb_width")) m.rgb_width = get_int(j, "rgb_width", cpath, 1, 4096);
  if (j.contains("cc_hidden")) m.cc_hidden = get_int(j, "cc_hidden", cpath, 1, 4096);
  // The hash-grid keys are required for hashcc (a silent default would compare different
  // grids); other models ignore them.
  if (m.has_cc() || j.contains("cc_levels")) m.cc.levels = get_int(j, "cc_levels", cpath, 1, 64);
  if (m.has_cc() || j.contains("cc_features")) m.cc.features = get_int(j, "cc_features", cpath, 1, 16);
  if (m.has_cc() || j.contains("cc_log2_table")) m.cc.log2_table = get_int(j, "cc_log2_table", cpath, 1, 26);
  if (m.has_cc() || j.contains("cc_base_res")) m.cc.base_res = get_pos(j, "cc_base_res", cpath);
  if (m.has_cc() || j.contains("cc_max_res")) m.cc.max_res = get_pos(j, "cc_max_res", cpath);
  HCC_REQUIRE(m.cc.max_res >= m.cc.base_res, cpath, "cc_max_res",
              "is {} (expected at least cc_base_res = {})", m.cc.max_res, m.cc.base_res);
  read_field_keys(j, cpath, m);
  return model;
}

// The image, the pixel grid and the sample positions (increasing along each ray).
void read_golden_data(const std::string& dir, GoldenInputs& in) {
  in.image = load(dir, "image", {in.H, in.W, 3}).data;
  in.rows = load_index(dir, "rows", in.H, "row");
  in.cols = load_index(dir, "cols", in.W, "column");
  const int64_t N = int64_t(in.rows.size()) * int64_t(in.cols.size());
  HCC_REQUIRE(N <= (int64_t(1) << 24), dir + "/rows.npy", "", "{} × {} rays is too many",
              in.rows.size(), in.cols.size());
  in.s = load(dir, "s", {N, in.S}).data;
  for (int64_t r = 0; r < N; ++r)
    for (int k = 0; k + 1 < in.S; ++k)
      HCC_REQUIRE(in.s[r * in.S + k + 1] >= in.s[r * in.S + k], dir + "/s.npy",
                  fmt::format("ray {}", r), "samples {} and {} decrease (expected increasing s along each ray)",
                  k, k + 1);
}

// The camera, then every tensor of the layout L; *known gets their names.
void read_golden_parameters(const std::string& dir, const ModelLayout& L, GoldenInputs& in,
                            std::set<std::string>* known) {
  in.params.assign(L.count, 0.0);
  for (const auto& t : golden_parameter_files(L)) {
    known->insert(t.name);
    NpyArray a = load(dir, t.name, t.shape);
    if (t.offset >= 0) std::copy(a.data.begin(), a.data.end(), in.params.begin() + t.offset);
    else if (t.name == "pose_r") std::copy(a.data.begin(), a.data.end(), in.pose_r);
    else if (t.name == "pose_t") std::copy(a.data.begin(), a.data.end(), in.pose_t);
    else std::copy(a.data.begin(), a.data.end(), in.focal_ab);
  }
}

}  // namespace

GoldenInputs read_golden_inputs(const std::string& dir) {
  if (!fs::is_directory(dir)) throw Error(dir, "", "not a folder", "an input folder of `hashcc step`");
  GoldenInputs in;
  const std::string model = read_golden_config(dir + "/config.json", in);
  read_golden_data(dir, in);
  const ModelLayout L = make_layout(in.model);
  std::set<std::string> known = {"image", "rows", "cols", "s", "cc_x", "P0"};
  read_golden_parameters(dir, L, in, &known);
  if (fs::exists(dir + "/cc_x.npy")) in.cc_x = load(dir, "cc_x", {int64_t(in.rays()) * in.S, 3}).data;
  if (fs::exists(dir + "/P0.npy")) {
    const std::vector<double> P = load(dir, "P0", {3, 4}).data;
    std::copy(P.begin(), P.end(), in.P0);
    in.has_P0 = true;
  }

  // An unknown .npy is most likely a misnamed tensor: refuse it rather than ignore it.
  for (const auto& e : fs::directory_iterator(dir)) {
    if (e.path().extension() != ".npy") continue;
    std::string stem = e.path().stem().string();
    if (!known.count(stem))
      throw Error(e.path().string(), "", fmt::format("unexpected file for model {}", model),
                  "only the inputs of docs/golden-step.md, e.g. trunk.0.weight.npy of shape " +
                      shape_text(L.tensors[0].shape));
  }
  return in;
}

void write_golden_inputs(const std::string& dir, const GoldenInputs& in) {
  make_dirs(dir);
  write_file_atomic(dir + "/config.json", golden_config_json(in));
  const int64_t N = in.rays();
  write_npy(dir + "/image.npy", in.image.data(), {in.H, in.W, 3});
  write_npy_i64(dir + "/rows.npy", in.rows.data(), {int64_t(in.rows.size())});
  write_npy_i64(dir + "/cols.npy", in.cols.data(), {int64_t(in.cols.size())});
  write_npy(dir + "/s.npy", in.s.data(), {N, in.S});
  ModelLayout L = make_layout(in.model);
  for (const auto& t : golden_parameter_files(L)) {
    const double* src = t.offset >= 0 ? in.params.data() + t.offset
                        : t.name == "pose_r"  ? in.pose_r
                        : t.name == "pose_t"  ? in.pose_t
                                              : in.focal_ab;
    write_npy(dir + "/" + t.name + ".npy", src, t.shape);
  }
  if (!in.cc_x.empty()) write_npy(dir + "/cc_x.npy", in.cc_x.data(), {N * in.S, 3});
  if (in.has_P0) write_npy(dir + "/P0.npy", in.P0, {3, 4});
}

GoldenInputs make_golden_inputs(const ModelConfig& cfg, const GoldenMakeOptions& o) {
  GoldenInputs in;
  in.model = cfg;
  in.H = o.H;
  in.W = o.W;
  in.S = o.S;
  in.ndc = o.ndc;
  in.fx_only = o.fx_only;
  Rng rng(o.seed, 0x601d);
  ModelLayout L = make_layout(cfg);
  in.params.assign(L.count, 0.0);
  init_params(in.params.data(), cfg, L, rng);
  if (cfg.has_cc())
    for (int64_t i = 0; i < cfg.cc.param_count(); ++i)
      in.params[L.cc_table + i] = rng.uniform(-o.cc_table_scale, o.cc_table_scale);
  // The grid field's table too: at ±1e-4 its encoding would be ~0, and a check would not see
  // the hash grid at all.
  if (cfg.field == Field::grid)
    for (int64_t i = 0; i < cfg.gf.grid.param_count(); ++i)
      in.params[L.grid_table + i] = rng.uniform(-o.cc_table_scale, o.cc_table_scale);
  for (int k = 0; k < 3; ++k) in.pose_r[k] = rng.uniform(-0.05, 0.05);
  for (int k = 0; k < 3; ++k) in.pose_t[k] = rng.uniform(-0.05, 0.05);
  for (int k = 0; k < 2; ++k) in.focal_ab[k] = rng.uniform(0.95, 1.05);
  auto distinct = [&](int n, int limit) {  // n distinct sorted values in [0, limit)
    std::vector<int64_t> all(limit);
    for (int i = 0; i < limit; ++i) all[i] = i;
    for (int i = 0; i < std::min(n, limit); ++i) std::swap(all[i], all[i + rng.below(uint32_t(limit - i))]);
    std::vector<int64_t> v(all.begin(), all.begin() + std::min(n, limit));
    std::sort(v.begin(), v.end());
    return v;
  };
  in.rows = distinct(o.R, o.H);
  in.cols = distinct(o.C, o.W);
  for (int64_t r = 0; r < in.rays(); ++r)
    for (int k = 0; k < o.S; ++k) in.s.push_back((k + rng.uniform(0.1, 0.9)) / o.S);
  // A smooth colourful target (any values in [0,1] would do).
  in.image.resize(size_t(o.H) * o.W * 3);
  for (int v = 0; v < o.H; ++v)
    for (int u = 0; u < o.W; ++u)
      for (int c = 0; c < 3; ++c)
        in.image[(size_t(v) * o.W + u) * 3 + c] =
            0.5 + 0.4 * std::sin(0.7 * u / o.W * 6.283 * (c + 1) + 0.9 * v / o.H * 6.283 + c);
  if (o.p0) {  // drawn last, so the other inputs of a seed do not change with --p0
    Vec3<double> axis(rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-1, 1));
    const Mat3<double> R0 = so3::exp(Vec3<double>(axis.normalized() * rng.uniform(0.1, 0.3)));
    for (int i = 0; i < 3; ++i) {
      for (int k = 0; k < 3; ++k) in.P0[4 * i + k] = R0(i, k);
      in.P0[4 * i + 3] = rng.uniform(-0.3, 0.3);
    }
    in.has_P0 = true;
  }
  return in;
}

template <class T>
GoldenOutputs golden_step(const GoldenInputs& in, CameraStepWorkspace<T>* ws_in) {
  const ModelLayout L = make_layout(in.model);
  HCC_ASSERT(int64_t(in.params.size()) == L.count);
  const int C = in.C(), S = in.S;
  const int64_t N = in.rays();
  HCC_ASSERT(N <= (int64_t(1) << 24));
  // Ray k is pixel (u = cols[k % C], v = rows[k / C]): row-major over the R × C grid.
  std::vector<int> px(2 * N);
  std::vector<T> target(3 * N);
  for (int64_t k = 0; k < N; ++k) {
    const int64_t u = in.cols[k % C], v = in.rows[k / C];
    px[2 * k] = int(u);
    px[2 * k + 1] = int(v);
    for (int c = 0; c < 3; ++c) target[3 * k + c] = T(in.image[(v * in.W + u) * 3 + c]);
  }
  PoseParams<T> pose;
  pose.r = Vec3<T>(T(in.pose_r[0]), T(in.pose_r[1]), T(in.pose_r[2]));
  pose.t = Vec3<T>(T(in.pose_t[0]), T(in.pose_t[1]), T(in.pose_t[2]));
  if (in.has_P0) {
    pose.has_P0 = true;
    for (int i = 0; i < 3; ++i)
      for (int k = 0; k < 4; ++k) pose.P0(i, k) = T(in.P0[4 * i + k]);
  }
  CameraBatch<T> batch;
  batch.focal.a = T(in.focal_ab[0]);
  batch.focal.b = T(in.focal_ab[1]);
  batch.focal.fx_only = in.fx_only;
  std::vector<T> params(in.params.begin(), in.params.end());
  std::vector<T> s(in.s.begin(), in.s.end()), cc_x(in.cc_x.begin(), in.cc_x.end());
  batch.px = px.data();
  batch.target = target.data();
  batch.s = s.data();
  batch.R = int(N);
  batch.S = S;
  batch.poses = &pose;
  batch.size = ImageSize{in.W, in.H};
  batch.ndc = in.ndc;
  batch.cc_x = cc_x.empty() ? nullptr : cc_x.data();

  CameraStepWorkspace<T> local;
  CameraStepWorkspace<T>& ws = ws_in ? *ws_in : local;
  std::vector<T> grad(L.count, T(0)), rgb(3 * N), rgb_cc(3 * N), depth(N);
  CameraStepGrads<T> g;
  g.d_params = grad.data();
  const StepResult<T> res = camera_step(ws, NetView<T>{params.data(), in.model, L}, batch,
                                        StepOptions{}, g, {rgb.data(), rgb_cc.data(), depth.data()});
  std::vector<T> x(3 * N * S);  // the step's samples, for x.npy
  sample_points_forward(x.data(), ws.o.data(), ws.d.data(), s.data(), N, S);

  GoldenOutputs out;
  auto to_d = [](const T* v, int64_t n) { return std::vector<double>(v, v + n); };
  out.rgb_main = to_d(rgb.data(), 3 * N);
  if (in.model.has_cc()) out.rgb_cc = to_d(rgb_cc.data(), 3 * N);
  out.depth = to_d(depth.data(), N);
  out.rays_o = to_d(ws.o.data(), 3 * N);
  out.rays_d = to_d(ws.d.data(), 3 * N);
  out.x = to_d(x.data(), 3 * N * S);
  out.loss = res.loss;
  out.grad_params = to_d(grad.data(), L.count);
  for (int k = 0; k < 3; ++k) out.grad_pose_r[k] = g.d_pose[k];
  for (int k = 0; k < 3; ++k) out.grad_pose_t[k] = g.d_pose[3 + k];
  for (int k = 0; k < 2; ++k) out.grad_focal_ab[k] = g.d_focal[k];
  return out;
}

void write_golden_outputs(const std::string& dir, const GoldenInputs& in, const GoldenOutputs& out) {
  make_dirs(dir);
  const int64_t N = in.rays();
  write_npy(dir + "/rgb_main.npy", out.rgb_main.data(), {N, 3});
  if (in.model.has_cc()) write_npy(dir + "/rgb_cc.npy", out.rgb_cc.data(), {N, 3});
  write_npy(dir + "/depth.npy", out.depth.data(), {N});
  write_npy(dir + "/loss.npy", &out.loss, {});
  write_npy(dir + "/rays_o.npy", out.rays_o.data(), {N, 3});
  write_npy(dir + "/rays_d.npy", out.rays_d.data(), {N, 3});
  write_npy(dir + "/x.npy", out.x.data(), {N * in.S, 3});
  ModelLayout L = make_layout(in.model);
  for (const auto& t : golden_parameter_files(L)) {
    const double* src = t.offset >= 0 ? out.grad_params.data() + t.offset
                        : t.name == "pose_r"  ? out.grad_pose_r
                        : t.name == "pose_t"  ? out.grad_pose_t
                                              : out.grad_focal_ab;
    write_npy(dir + "/grad." + t.name + ".npy", src, t.shape);
  }
}

template GoldenOutputs golden_step<float>(const GoldenInputs&, CameraStepWorkspace<float>*);
template GoldenOutputs golden_step<double>(const GoldenInputs&, CameraStepWorkspace<double>*);

}  // namespace hashcc
