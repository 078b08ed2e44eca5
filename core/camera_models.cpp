#include "core/camera_models.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>

#include "core/error.h"
#include "core/stats.h"
#include "core/fileio.h"
#include "core/npy.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace hashcc {

// ---- the one place where other tools' conventions become ours -------------------------------

Mat34d c2w_from_colmap(const Eigen::Vector4d& qvec, const Eigen::Vector3d& tvec) {
  // COLMAP: x_cam = R_cw · x_world + t_cw, camera axes OpenCV [right, down, forward].
  Eigen::Quaterniond q(qvec[0], qvec[1], qvec[2], qvec[3]);
  const Eigen::Matrix3d R_cw = q.normalized().toRotationMatrix();
  const Eigen::Matrix3d R_wc = R_cw.transpose();
  Mat34d c2w;
  c2w.col(0) = R_wc.col(0);   // right   =  OpenCV x
  c2w.col(1) = -R_wc.col(1);  // up      = −OpenCV y (down)
  c2w.col(2) = -R_wc.col(2);  // back    = −OpenCV z (forward)
  c2w.col(3) = -R_wc * tvec;  // camera centre
  return c2w;
}

void colmap_from_c2w(const Mat34d& c2w, Eigen::Vector4d* qvec, Eigen::Vector3d* tvec) {
  Eigen::Matrix3d R_wc;
  R_wc << c2w.col(0), -c2w.col(1), -c2w.col(2);
  const Eigen::Matrix3d R_cw = R_wc.transpose();
  Eigen::Quaterniond q(R_cw);
  if (q.w() < 0) q.coeffs() *= -1;
  *qvec = Eigen::Vector4d(q.w(), q.x(), q.y(), q.z());
  *tvec = -R_cw * Eigen::Vector3d(c2w.col(3));
}

// ---- helpers ----------------------------------------------------------------------------------

namespace {

std::string trim(const std::string& s) {
  size_t a = s.find_first_not_of(" \t\r\n"), b = s.find_last_not_of(" \t\r\n");
  return a == std::string::npos ? std::string() : s.substr(a, b - a + 1);
}

std::vector<std::string> split_ws(const std::string& s) {
  std::vector<std::string> out;
  std::istringstream in(s);
  std::string w;
  while (in >> w) out.push_back(w);
  return out;
}

std::string line_field(int64_t n) { return fmt::format("line {}", n); }

double parse_double(const std::string& tok, const std::string& file, int64_t line,
                    const char* what) {
  double v = 0;
  const char* b = tok.data();
  const char* e = b + tok.size();
  if (!tok.empty() && *b == '+') ++b;
  auto [p, ec] = std::from_chars(b, e, v);
  HCC_REQUIRE(ec == std::errc() && p == e && std::isfinite(v), file, line_field(line),
              "{} is '{}'", what, tok, "a finite number");
  return v;
}

int64_t parse_int(const std::string& tok, const std::string& file, int64_t line, const char* what) {
  int64_t v = 0;
  auto [p, ec] = std::from_chars(tok.data(), tok.data() + tok.size(), v);
  HCC_REQUIRE(ec == std::errc() && p == tok.data() + tok.size(), file, line_field(line),
              "{} is '{}'", what, tok, "an integer");
  return v;
}

std::string base_name(const std::string& p) {
  std::string s = p;
  std::replace(s.begin(), s.end(), '\\', '/');
  return fs::path(s).filename().string();
}
std::string stem_of(const std::string& p) { return fs::path(base_name(p)).stem().string(); }

// Reads a text file's lines (1-based numbering is the caller's).
std::vector<std::string> read_lines(const std::string& path) {
  std::error_code ec;
  HCC_REQUIRE(fs::is_regular_file(path, ec), path, "", "no such file");
  std::ifstream in(path, std::ios::binary);
  HCC_REQUIRE(in.good(), path, "", "cannot be opened");
  std::vector<std::string> lines;
  std::string l;
  while (std::getline(in, l)) lines.push_back(l);
  return lines;
}

}  // namespace


// ---- COLMAP text model -----------------------------------------------------------------------

namespace {

struct ColmapCamera { int W, H; double fx, fy, cx, cy; std::string model; };

// One line of cameras.txt: CAMERA_ID MODEL WIDTH HEIGHT PARAMS[] (t: its fields, t.size() ≥ 4).
ColmapCamera parse_colmap_camera(const std::vector<std::string>& t, const std::string& path,
                                 int64_t ln) {
  const std::string& model = t[1];
  ColmapCamera c;
  c.model = model;
  c.W = int(parse_int(t[2], path, ln, "WIDTH"));
  c.H = int(parse_int(t[3], path, ln, "HEIGHT"));
  HCC_REQUIRE(c.W > 0 && c.H > 0, path, line_field(ln), "size {}x{}", c.W, c.H,
              "positive WIDTH and HEIGHT");
  std::vector<double> p;
  for (size_t i = 4; i < t.size(); ++i) p.push_back(parse_double(t[i], path, ln, "a parameter"));
  size_t want = 0;
  if (model == "PINHOLE") want = 4;               // fx fy cx cy
  else if (model == "SIMPLE_PINHOLE") want = 3;   // f cx cy
  else if (model == "SIMPLE_RADIAL") want = 4;    // f cx cy k
  else if (model == "RADIAL") want = 5;           // f cx cy k1 k2
  else
    throw Error(path, line_field(ln), fmt::format("unsupported camera model {}", model),
                "PINHOLE, SIMPLE_PINHOLE, SIMPLE_RADIAL or RADIAL");
  HCC_REQUIRE(p.size() == want, path, line_field(ln), "{} has {} parameters", model,
              p.size(), fmt::format("{}", want));
  if (model == "PINHOLE") { c.fx = p[0]; c.fy = p[1]; c.cx = p[2]; c.cy = p[3]; }
  else { c.fx = c.fy = p[0]; c.cx = p[1]; c.cy = p[2]; }
  HCC_REQUIRE(c.fx > 0 && c.fy > 0, path, line_field(ln), "focal {} {}", c.fx, c.fy, "positive");
  return c;
}

// cameras.txt: CAMERA_ID → camera. What hashcc's pinhole ignores (radial terms, an off-centre
// principal point) goes to m.notes.
std::map<int64_t, ColmapCamera> read_colmap_cameras(const std::string& path, CameraModel& m) {
  std::map<int64_t, ColmapCamera> cams;
  auto lines = read_lines(path);
  bool radial_noted = false;
  for (size_t k = 0; k < lines.size(); ++k) {
    const int64_t ln = int64_t(k) + 1;
    std::string l = trim(lines[k]);
    if (l.empty() || l[0] == '#') continue;
    auto t = split_ws(l);
    HCC_REQUIRE(t.size() >= 4, path, line_field(ln), "{} fields", t.size(),
                "CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]");
    const int64_t id = parse_int(t[0], path, ln, "CAMERA_ID");
    const ColmapCamera c = parse_colmap_camera(t, path, ln);
    if ((c.model == "SIMPLE_RADIAL" || c.model == "RADIAL") && !radial_noted) {
      m.notes.push_back(fmt::format("{}: {} radial distortion terms ignored (hashcc's camera is "
                                    "a pinhole)", path, c.model));
      radial_noted = true;
    }
    if (std::abs(c.cx - c.W / 2.0) > 0.02 * c.W || std::abs(c.cy - c.H / 2.0) > 0.02 * c.H)
      m.notes.push_back(fmt::format("{}: camera {} principal point ({}, {}) is off-centre; "
                                    "hashcc uses (W/2, H/2)", path, id, c.cx, c.cy));
    HCC_REQUIRE(cams.emplace(id, c).second, path, line_field(ln), "camera {} defined twice", id);
  }
  HCC_REQUIRE(!cams.empty(), path, "", "no cameras", "one line per camera");
  return cams;
}

// images.txt: appends each image (name, camera-to-world, its camera's focal and size) to m and
// returns IMAGE_ID → index in m.
std::map<int64_t, size_t> read_colmap_images(const std::string& path,
                                             const std::map<int64_t, ColmapCamera>& cams,
                                             CameraModel& m) {
  std::map<int64_t, size_t> image_index;
  auto lines = read_lines(path);
  for (size_t k = 0; k < lines.size(); ++k) {
    const int64_t ln = int64_t(k) + 1;
    std::string l = trim(lines[k]);
    if (l.empty() || l[0] == '#') continue;
    // Image line: IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME; the next line (possibly
    // empty) holds its POINTS2D as X Y POINT3D_ID triples (COLMAP's own reader does the same).
    auto t = split_ws(l);
    HCC_REQUIRE(t.size() >= 10, path, line_field(ln), "{} fields", t.size(),
                "IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME");
    const int64_t id = parse_int(t[0], path, ln, "IMAGE_ID");
    Eigen::Vector4d q;
    Eigen::Vector3d tv;
    for (int i = 0; i < 4; ++i) q[i] = parse_double(t[1 + i], path, ln, "a quaternion entry");
    for (int i = 0; i < 3; ++i) tv[i] = parse_double(t[5 + i], path, ln, "a translation entry");
    HCC_REQUIRE(q.norm() > 1e-6, path, line_field(ln), "zero quaternion", "a unit quaternion");
    const int64_t cam_id = parse_int(t[8], path, ln, "CAMERA_ID");
    auto c = cams.find(cam_id);
    HCC_REQUIRE(c != cams.end(), path, line_field(ln), "camera {} is not in cameras.txt", cam_id);
    std::string name = t[9];
    for (size_t i = 10; i < t.size(); ++i) name += " " + t[i];
    HCC_REQUIRE(image_index.emplace(id, m.c2w.size()).second, path, line_field(ln),
                "image {} defined twice", id);
    m.names.push_back(name);
    m.c2w.push_back(c2w_from_colmap(q, tv));
    m.fx.push_back(c->second.fx);
    m.fy.push_back(c->second.fy);
    m.width.push_back(c->second.W);
    m.height.push_back(c->second.H);
    ++k;  // the POINTS2D line
    if (k < lines.size()) {
      auto p = split_ws(trim(lines[k]));
      HCC_REQUIRE(p.size() % 3 == 0, path, line_field(int64_t(k) + 1),
                  "{} numbers in the POINTS2D line of image {}", p.size(), id,
                  "X Y POINT3D_ID triples");
    }
  }
  HCC_REQUIRE(!m.c2w.empty(), path, "", "no images", "two lines per image");
  return image_index;
}

// points3D.txt, as LLFF's imgs2poses: per image, the depths (along its viewing axis) of the
// points it sees; m.near gets each image's 0.1th percentile when every image sees a point.
void read_colmap_near(const std::string& path, const std::map<int64_t, size_t>& image_index,
                      CameraModel& m) {
  std::vector<std::vector<double>> depths(m.c2w.size());
  auto lines = read_lines(path);
  for (size_t k = 0; k < lines.size(); ++k) {
    const int64_t ln = int64_t(k) + 1;
    std::string l = trim(lines[k]);
    if (l.empty() || l[0] == '#') continue;
    // POINT3D_ID X Y Z R G B ERROR TRACK[] as (IMAGE_ID, POINT2D_IDX)
    auto t = split_ws(l);
    HCC_REQUIRE(t.size() >= 8 && (t.size() - 8) % 2 == 0, path, line_field(ln),
                "{} fields", t.size(), "POINT3D_ID X Y Z R G B ERROR (IMAGE_ID POINT2D_IDX)*");
    Eigen::Vector3d X;
    for (int i = 0; i < 3; ++i) X[i] = parse_double(t[1 + i], path, ln, "a coordinate");
    for (size_t i = 8; i < t.size(); i += 2) {
      const int64_t img = parse_int(t[i], path, ln, "IMAGE_ID");
      parse_int(t[i + 1], path, ln, "POINT2D_IDX");
      auto it = image_index.find(img);
      HCC_REQUIRE(it != image_index.end(), path, line_field(ln),
                  "track names image {}, not in images.txt", img);
      const Mat34d& p = m.c2w[it->second];
      depths[it->second].push_back(-(X - p.col(3)).dot(p.col(2)));  // forward = −back
    }
  }
  bool all = true;
  for (auto& d : depths) all = all && !d.empty();
  if (all) {
    for (auto& d : depths) m.near.push_back(percentile(d, 0.1));
  } else {
    m.notes.push_back(fmt::format("{}: some images observe no point; depth bounds not used", path));
  }
}

}  // namespace

CameraModel read_colmap_text(const std::string& folder) {
  CameraModel m;
  m.path = folder;
  m.format = "colmap";
  const auto cams = read_colmap_cameras((fs::path(folder) / "cameras.txt").string(), m);
  const auto image_index = read_colmap_images((fs::path(folder) / "images.txt").string(), cams, m);
  const std::string pts_path = (fs::path(folder) / "points3D.txt").string();
  std::error_code ec;
  if (fs::exists(pts_path, ec)) read_colmap_near(pts_path, image_index, m);
  return m;
}

// ---- LLFF poses_bounds.npy -------------------------------------------------------------------

CameraModel read_poses_bounds_model(const std::string& path) {
  CameraModel m;
  m.path = path;
  m.format = "llff";
  NpyArray a = read_npy(path);
  HCC_REQUIRE(a.shape.size() == 2 && a.shape[1] == 17 && a.shape[0] >= 1, path, "shape",
              "has shape {}", a.shape_str(), "(N, 17)");
  for (int64_t i = 0; i < a.shape[0]; ++i) {
    const double* row = a.data.data() + 17 * i;
    double H, W, f;
    m.c2w.push_back(llff_row_to_c2w_checked(path, i, row, &H, &W, &f));
    m.fx.push_back(f);
    m.fy.push_back(f);
    m.width.push_back(int(std::lround(W)));
    m.height.push_back(int(std::lround(H)));
    m.near.push_back(row[15]);
  }
  return m;
}

// ---- cameras.json (transforms.json convention) ------------------------------------------------

CameraModel read_cameras_json(const std::string& path) {
  CameraModel m;
  m.path = path;
  m.format = "json";
  json j;
  try {
    j = json::parse(read_file_bytes(path, int64_t(1) << 30));
  } catch (const json::exception& e) {
    throw Error(path, "", fmt::format("not valid JSON ({})", e.what()));
  }
  HCC_REQUIRE(j.is_object() && j.contains("frames") && j["frames"].is_array(), path, "frames",
              "missing", "an array of frames");
  auto num = [&](const json& o, const char* k, const std::string& where, double* v) {
    if (!o.contains(k)) return false;
    HCC_REQUIRE(o[k].is_number() && std::isfinite(o[k].get<double>()), path, where + k,
                "is not a finite number");
    *v = o[k].get<double>();
    return true;
  };
  double W0 = 0, H0 = 0, fx0 = 0, fy0 = 0, angle = 0;
  num(j, "w", "", &W0);
  num(j, "h", "", &H0);
  bool has_fx = num(j, "fl_x", "", &fx0);
  bool has_fy = num(j, "fl_y", "", &fy0);
  if (!has_fx && num(j, "camera_angle_x", "", &angle) && W0 > 0) {
    fx0 = 0.5 * W0 / std::tan(0.5 * angle);  // NeRF synthetic convention
    has_fx = true;
  }
  if (has_fx && !has_fy) fy0 = fx0, has_fy = true;
  m.prescaled = j.contains("ndc");  // written by hashcc: already in the formulas.md §7 frame
  for (size_t i = 0; i < j["frames"].size(); ++i) {
    const json& f = j["frames"][i];
    const std::string where = fmt::format("frames[{}].", i);
    HCC_REQUIRE(f.is_object() && f.contains("file_path") && f["file_path"].is_string(), path,
                where + "file_path", "missing", "a string");
    HCC_REQUIRE(f.contains("transform_matrix") && f["transform_matrix"].is_array() &&
                    (f["transform_matrix"].size() == 4 || f["transform_matrix"].size() == 3),
                path, where + "transform_matrix", "missing or not 3 or 4 rows", "a 4×4 matrix");
    Mat34d c2w;
    for (int r = 0; r < 3; ++r) {
      const json& row = f["transform_matrix"][r];
      HCC_REQUIRE(row.is_array() && row.size() == 4, path,
                  fmt::format("{}transform_matrix[{}]", where, r), "not 4 numbers", "4 numbers");
      for (int c = 0; c < 4; ++c) {
        HCC_REQUIRE(row[c].is_number() && std::isfinite(row[c].get<double>()), path,
                    fmt::format("{}transform_matrix[{}][{}]", where, r, c), "not a finite number");
        c2w(r, c) = row[c].get<double>();
      }
    }
    const Eigen::Matrix3d R = c2w.leftCols<3>();
    HCC_REQUIRE((R.transpose() * R - Eigen::Matrix3d::Identity()).norm() < 1e-3 && R.determinant() > 0,
                path, where + "transform_matrix", "rotation part is not a rotation",
                "an orthonormal, right-handed 3×3 block");
    double W = W0, H = H0, fx = fx0, fy = fy0;
    num(f, "w", where, &W);
    num(f, "h", where, &H);
    bool fxf = num(f, "fl_x", where, &fx), fyf = num(f, "fl_y", where, &fy);
    if (fxf && !fyf) fy = fx;
    m.names.push_back(f["file_path"].get<std::string>());
    m.c2w.push_back(c2w);
    m.fx.push_back(has_fx || fxf ? fx : 0);
    m.fy.push_back(has_fy || fxf || fyf ? fy : 0);
    m.width.push_back(int(std::lround(W)));
    m.height.push_back(int(std::lround(H)));
  }
  HCC_REQUIRE(!m.c2w.empty(), path, "frames", "empty", "at least one frame");
  return m;
}

CameraModel read_camera_model(const std::string& path) {
  std::error_code ec;
  HCC_REQUIRE(fs::exists(path, ec), path, "", "no such file or folder",
              "a COLMAP text model folder, poses_bounds.npy or cameras.json");
  if (fs::is_directory(path, ec)) {
    fs::path d(path);
    if (fs::exists(d / "cameras.txt", ec) || fs::exists(d / "images.txt", ec))
      return read_colmap_text(path);
    HCC_REQUIRE(!fs::exists(d / "cameras.bin", ec), path, "",
                "holds a binary COLMAP model",
                "a text model: colmap model_converter --output_type TXT");
    for (const char* f : {"poses_bounds.npy", "cameras.json", "transforms.json"})
      if (fs::exists(d / f, ec)) return read_camera_model((d / f).string());
    throw Error(path, "", "holds no camera model",
                "cameras.txt + images.txt, poses_bounds.npy or cameras.json");
  }
  const std::string ext = fs::path(path).extension().string();
  if (ext == ".npy") return read_poses_bounds_model(path);
  if (ext == ".json") return read_cameras_json(path);
  throw Error(path, "", "unknown camera file type",
              "a COLMAP text model folder, a .npy (LLFF) or a .json (transforms.json)");
}

// ---- into the scene's frame ------------------------------------------------------------------

namespace {

// For each scene image, the index of its pose in m (−1: not in the model): by position when
// the model has no names (poses_bounds.npy), else by file name, then by stem when unambiguous.
std::vector<int> match_images(const CameraModel& m, const Scene& scene) {
  const size_t n = scene.names.size();
  std::vector<int> match(n, -1);
  if (m.names.empty()) {
    HCC_REQUIRE(m.c2w.size() == n, m.path, "rows", "has {} poses but {} has {} images",
                m.c2w.size(), scene.image_dir, n, "one row per image, in sorted name order");
    for (size_t i = 0; i < n; ++i) match[i] = int(i);
    return match;
  }
  std::map<std::string, int> by_name, by_stem;
  for (size_t k = 0; k < m.names.size(); ++k) {
    by_name.emplace(base_name(m.names[k]), int(k));
    auto [it, fresh] = by_stem.emplace(stem_of(m.names[k]), int(k));
    if (!fresh) it->second = -2;  // ambiguous stem
  }
  for (size_t i = 0; i < n; ++i) {
    auto a = by_name.find(scene.names[i]);
    if (a != by_name.end()) { match[i] = a->second; continue; }
    auto b = by_stem.find(stem_of(scene.names[i]));
    if (b != by_stem.end() && b->second >= 0) match[i] = b->second;
  }
  return match;
}

// The matched poses in scene order; a note names the scene images the model lacks.
std::vector<Mat34d> matched_poses(const CameraModel& m, const Scene& scene,
                                  const std::vector<int>& match, InitPoses& out) {
  const size_t n = scene.names.size();
  std::vector<Mat34d> matched;
  std::vector<std::string> missing;
  for (size_t i = 0; i < n; ++i) {
    if (match[i] >= 0) matched.push_back(m.c2w[match[i]]);
    else missing.push_back(scene.names[i]);
  }
  HCC_REQUIRE(!matched.empty(), m.path, "", "no image in common with {} (model has e.g. '{}', "
              "scene has e.g. '{}')", scene.image_dir, m.names.empty() ? "" : m.names[0],
              scene.names[0], "images matched by file name");
  if (!missing.empty()) {
    std::string list;
    for (size_t k = 0; k < missing.size() && k < 8; ++k) list += (k ? ", " : "") + missing[k];
    if (missing.size() > 8) list += ", …";
    out.notes.push_back(fmt::format("{} of {} images not in {}: they start at the mean pose of "
                                    "the others ({})", missing.size(), n, m.path, list));
  }
  return matched;
}

// out.scale and out.scale_source (formulas.md §7: 1 / (0.75 · near)); without depth bounds the
// camera spread is scaled to LLFF fern's.
void choose_scale(const CameraModel& m, const std::vector<int>& match,
                  const std::vector<Mat34d>& matched, InitPoses& out) {
  if (m.prescaled) {
    out.scale = 1;
    out.scale_source = "already in hashcc's frame (cameras.json written by hashcc)";
  } else if (!m.near.empty()) {
    double near = 1e300;
    for (size_t i = 0; i < match.size(); ++i)
      if (match[i] >= 0) near = std::min(near, m.near[match[i]]);
    HCC_REQUIRE(near > 0 && std::isfinite(near), m.path, "", "near bound {}", near, "positive");
    out.scale = 1.0 / (0.75 * near);
    out.scale_source = m.format == "llff"
                           ? fmt::format("1/(0.75·min near) = 1/(0.75·{:.6g}) (poses_bounds.npy)", near)
                           : fmt::format("1/(0.75·near), near = {:.6g} = min over images of the "
                                         "0.1th percentile of sparse-point depths", near);
  } else {
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (auto& p : matched) mean += p.col(3);
    mean /= double(matched.size());
    double ss = 0;
    for (auto& p : matched) ss += (p.col(3) - mean).squaredNorm();
    const double rms = std::sqrt(ss / double(matched.size()));
    out.scale = rms > 1e-12 ? kTypicalSpread / rms : 1.0;
    out.scale_source = fmt::format("no depth information: camera spread scaled to LLFF fern's "
                                   "(RMS {} from the mean centre)", kTypicalSpread);
    out.notes.push_back(out.scale_source);
  }
}

// out.c2w: scaled by out.scale, then centred on the average of the matched poses (as the loader
// does; missing images sit at that average, i.e. at the identity after centring).
void centre_poses(const CameraModel& m, const std::vector<int>& match,
                  std::vector<Mat34d> matched, InitPoses& out) {
  const size_t n = match.size();
  for (auto& p : matched) p.col(3) *= out.scale;
  const Eigen::Matrix4d inv_avg = to4(average_pose(matched)).inverse();
  const Mat34d avg = average_pose(matched);
  out.c2w.resize(n);
  out.from_model.assign(n, false);
  for (size_t i = 0; i < n; ++i) {
    Mat34d p = avg;
    if (match[i] >= 0) {
      p = m.c2w[match[i]];
      p.col(3) *= out.scale;
      out.from_model[i] = true;
    }
    out.c2w[i] = (inv_avg * to4(p)).topRows<3>();
  }
}

// out.fx, out.fy: the mean over matched images, in pixels of the scene's loaded size.
void mean_focal(const CameraModel& m, const Scene& scene, const std::vector<int>& match,
                InitPoses& out) {
  double sfx = 0, sfy = 0, mn = 1e300, mx = 0;
  int cnt = 0;
  for (size_t i = 0; i < match.size(); ++i) {
    if (match[i] < 0) continue;
    const int k = match[i];
    if (!(m.fx[k] > 0 && m.fy[k] > 0)) continue;
    const double sx = m.width[k] > 0 ? double(scene.width) / m.width[k] : 1.0;
    const double sy = m.height[k] > 0 ? double(scene.height) / m.height[k] : 1.0;
    sfx += m.fx[k] * sx;
    sfy += m.fy[k] * sy;
    mn = std::min(mn, m.fx[k] * sx);
    mx = std::max(mx, m.fx[k] * sx);
    ++cnt;
  }
  if (cnt > 0) {
    out.has_focal = true;
    out.fx = sfx / cnt;
    out.fy = sfy / cnt;
    if (mx > 1.01 * mn)
      out.notes.push_back(fmt::format("focal differs between images ({:.2f} to {:.2f} px); hashcc "
                                      "learns one, starting at the mean {:.2f}", mn, mx, out.fx));
  }
}

}  // namespace

InitPoses init_poses_for_scene(const CameraModel& m, const Scene& scene) {
  InitPoses out;
  out.notes = m.notes;
  const std::vector<int> match = match_images(m, scene);
  std::vector<Mat34d> matched = matched_poses(m, scene, match, out);
  choose_scale(m, match, matched, out);
  centre_poses(m, match, std::move(matched), out);
  mean_focal(m, scene, match, out);
  return out;
}

// ---- writers ---------------------------------------------------------------------------------

void write_colmap_text(const std::string& folder, const std::vector<std::string>& names,
                       const std::vector<Mat34d>& c2w, double fx, double fy, int W, int H) {
  make_dirs(folder);
  std::string cams = "# Camera list with one line of data per camera:\n"
                     "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n";
  std::string imgs = "# Image list with two lines of data per image:\n"
                     "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n"
                     "#   POINTS2D[] as (X, Y, POINT3D_ID)\n";
  for (size_t i = 0; i < c2w.size(); ++i) {
    cams += fmt::format("{} PINHOLE {} {} {:.17g} {:.17g} {:.17g} {:.17g}\n", i + 1, W, H, fx, fy,
                        W / 2.0, H / 2.0);
    Eigen::Vector4d q;
    Eigen::Vector3d t;
    colmap_from_c2w(c2w[i], &q, &t);
    imgs += fmt::format("{} {:.17g} {:.17g} {:.17g} {:.17g} {:.17g} {:.17g} {:.17g} {} {}\n\n",
                        i + 1, q[0], q[1], q[2], q[3], t[0], t[1], t[2], i + 1, names[i]);
  }
  write_file_atomic((fs::path(folder) / "cameras.txt").string(), cams);
  write_file_atomic((fs::path(folder) / "images.txt").string(), imgs);
}

void write_cameras_json_file(const std::string& path, const std::vector<std::string>& names,
                             const std::vector<Mat34d>& c2w, double fx, double fy, int W, int H) {
  json frames = json::array();
  for (size_t i = 0; i < c2w.size(); ++i) {
    json mtx = json::array();
    for (int r = 0; r < 3; ++r) mtx.push_back({c2w[i](r, 0), c2w[i](r, 1), c2w[i](r, 2), c2w[i](r, 3)});
    mtx.push_back({0, 0, 0, 1});
    frames.push_back({{"file_path", names[i]}, {"transform_matrix", mtx}});
  }
  json j = {{"camera_model", "PINHOLE"}, {"fl_x", fx}, {"fl_y", fy}, {"cx", W / 2.0},
            {"cy", H / 2.0}, {"w", W}, {"h", H}, {"frames", frames}};
  write_file_atomic(path, j.dump(2) + "\n");
}

}  // namespace hashcc
