#include "core/llff.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <filesystem>

#include "core/error.h"
#include "core/npy.h"
#include "core/parallel.h"

namespace fs = std::filesystem;

namespace hashcc {

Mat34d llff_row_to_c2w(const double* row, double* H, double* W, double* focal) {
  // row[0..14] is the 3×5 matrix in row-major order: m(i, j) = row[5 i + j].
  auto m = [&](int i, int j) { return row[5 * i + j]; };
  Mat34d c2w;
  for (int i = 0; i < 3; ++i) {
    c2w(i, 0) = m(i, 1);   // right  = c1
    c2w(i, 1) = -m(i, 0);  // up     = −down = −c0
    c2w(i, 2) = m(i, 2);   // back   = c2
    c2w(i, 3) = m(i, 3);   // centre
  }
  if (H) *H = m(0, 4);
  if (W) *W = m(1, 4);
  if (focal) *focal = m(2, 4);
  return c2w;
}

Mat34d llff_row_to_c2w_checked(const std::string& file, int64_t i, const double* row,
                               double* H, double* W, double* f) {
  Mat34d c2w = llff_row_to_c2w(row, H, W, f);
  HCC_REQUIRE(row[15] > 0 && row[16] > row[15], file, fmt::format("row {} bounds", i),
              "near {} far {}", row[15], row[16], "0 < near < far");
  HCC_REQUIRE(*H > 0 && *W > 0 && *f > 0, file, fmt::format("row {} hwf", i),
              "H {} W {} focal {}", *H, *W, *f, "positive values");
  return c2w;
}

void c2w_to_llff_row(const Mat34d& c2w, double H, double W, double focal, double near,
                     double far, double* row) {
  for (int i = 0; i < 3; ++i) {
    row[5 * i + 0] = -c2w(i, 1);  // down = −up
    row[5 * i + 1] = c2w(i, 0);   // right
    row[5 * i + 2] = c2w(i, 2);   // back
    row[5 * i + 3] = c2w(i, 3);
  }
  row[4] = H;
  row[9] = W;
  row[14] = focal;
  row[15] = near;
  row[16] = far;
}

Eigen::Matrix4d to4(const Mat34d& m) {
  Eigen::Matrix4d r = Eigen::Matrix4d::Identity();
  r.topRows<3>() = m;
  return r;
}

Mat34d average_pose(const std::vector<Mat34d>& c2w) {
  // LLFF poses_avg: centre = mean centre; z = normalize(Σ back); up = Σ up;
  // x = normalize(up × z); y = z × x.
  Eigen::Vector3d centre = Eigen::Vector3d::Zero(), z = Eigen::Vector3d::Zero(),
                  up = Eigen::Vector3d::Zero();
  for (auto& p : c2w) {
    centre += p.col(3);
    z += p.col(2);
    up += p.col(1);
  }
  centre /= double(c2w.size());
  z.normalize();
  Eigen::Vector3d x = up.cross(z).normalized();
  Eigen::Vector3d y = z.cross(x).normalized();
  Mat34d avg;
  avg << x, y, z, centre;
  return avg;
}

std::vector<Mat34d> recenter_poses(const std::vector<Mat34d>& c2w) {
  Eigen::Matrix4d inv_avg = to4(average_pose(c2w)).inverse();
  std::vector<Mat34d> out;
  for (auto& p : c2w) out.push_back((inv_avg * to4(p)).topRows<3>());
  return out;
}

namespace {

int folder_factor(const std::string& name) {
  if (name == "images") return 1;
  if (name.rfind("images_", 0) == 0) {
    std::string n = name.substr(7);
    if (!n.empty() && n.size() < 4 && n.find_first_not_of("0123456789") == std::string::npos)
      return std::stoi(n);
  }
  return 0;
}

std::vector<std::string> list_images(const std::string& dir,
                                     std::vector<std::string>* ignored = nullptr) {
  std::vector<std::string> names;
  std::error_code ec;
  for (auto& e : fs::directory_iterator(dir, ec)) {
    std::string n = e.path().filename().string();
    if (n.empty() || n[0] == '.') continue;
    // The error_code overload: without it a symbolic link loop (ELOOP) throws
    // std::filesystem::filesystem_error, which the CLI can only report as an internal error.
    std::error_code fec;
    const bool regular = e.is_regular_file(fec);
    if (!regular && is_image_filename(n) && e.is_symlink(fec)) {
      // A link named like a photo that leads nowhere (a loop, or a missing target) would
      // otherwise vanish from the scene without a word: the user meant it as a photo.
      std::error_code sec;
      (void)fs::status(e.path(), sec);  // for its error: ELOOP, ENOENT, …
      throw Error(e.path().string(), "",
                  sec ? fmt::format("is a symbolic link that cannot be followed ({})", sec.message())
                      : "is a symbolic link to a folder or device, not a file",
                  "a link to an image file, or the file itself");
    }
    if (!regular) continue;
    if (is_image_filename(n)) names.push_back(n);
    else if (ignored) ignored->push_back(n);
  }
  std::sort(names.begin(), names.end());
  if (ignored) std::sort(ignored->begin(), ignored->end());
  return names;
}

}  // namespace

std::vector<std::string> image_folders(const std::string& dir) {
  std::vector<std::pair<int, std::string>> found;
  std::error_code ec;
  for (auto& e : fs::directory_iterator(dir, ec)) {
    std::error_code dec;
    if (!e.is_directory(dec)) continue;  // a symbolic link loop is not a folder (and must not throw)
    std::string n = e.path().filename().string();
    int f = folder_factor(n);
    if (f > 0) found.push_back({-f, n});  // largest factor = smallest images first
  }
  std::sort(found.begin(), found.end());
  std::vector<std::string> out;
  for (auto& f : found) out.push_back(f.second);
  return out;
}

std::string ignored_files_note(const Scene& sc) {
  if (sc.ignored.empty()) return "";
  std::string list;
  for (size_t i = 0; i < sc.ignored.size() && i < 5; ++i) list += (i ? ", " : "") + sc.ignored[i];
  if (sc.ignored.size() > 5) list += fmt::format(", … ({} more)", sc.ignored.size() - 5);
  return fmt::format("note: ignored {} non-image file{} in {}: {}", sc.ignored.size(),
                     sc.ignored.size() == 1 ? "" : "s", sc.image_dir, list);
}

namespace {

// sc.image_dir, sc.factor, sc.names (sorted), sc.ignored: the image folder (opt's, else the
// smallest images_N present, else dir itself) and the images in it, at least 2.
void find_images(Scene& sc, const std::string& dir, const SceneOptions& opt) {
  std::error_code ec;
  std::string folder = opt.images_folder;
  if (folder.empty()) {
    auto folders = image_folders(dir);
    if (!folders.empty()) folder = folders.front();
  }
  if (folder.empty()) {
    sc.image_dir = dir;  // a bare folder of photos
    sc.factor = 1;
  } else {
    sc.image_dir = (fs::path(dir) / folder).string();
    HCC_REQUIRE(fs::is_directory(sc.image_dir, ec), sc.image_dir, "", "no such image folder");
    sc.factor = std::max(1, folder_factor(folder));
  }
  sc.names = list_images(sc.image_dir, &sc.ignored);
  HCC_REQUIRE(!sc.names.empty(), sc.image_dir, "", "no images found",
              "PNG or JPG files");
  HCC_REQUIRE(sc.names.size() >= 2, sc.image_dir, "", "only one image ({}); a radiance field "
              "and cameras need at least 2 views", sc.names[0]);
}

// sc.file_width/height (upright), sc.width/height (after max_side) and the EXIF focal, from the
// headers only, so a size mismatch is reported before decoding anything.
void read_image_sizes(Scene& sc, int max_side) {
  std::vector<double> focal35;  // the images' FocalLengthIn35mmFilm, where present
  ExifInfo first;
  for (size_t i = 0; i < sc.names.size(); ++i) {
    std::string p = (fs::path(sc.image_dir) / sc.names[i]).string();
    int w, h;
    ExifInfo e;
    image_size(p, &w, &h, &e);
    if (i == 0) { sc.file_width = w; sc.file_height = h; first = e; }
    HCC_REQUIRE(w == sc.file_width && h == sc.file_height, p, "size",
                "is {}x{} (upright) but {} is {}x{}", w, h, sc.names[0], sc.file_width,
                sc.file_height, "all images the same size and orientation");
    for (const std::string& note : e.notes)
      if (sc.notes.size() < 5) sc.notes.push_back(fmt::format("{}: {}", sc.names[i], note));
    if (e.focal35_mm > 0) focal35.push_back(e.focal35_mm);
    sc.turned += e.orientation != 1;
  }
  working_size(sc.file_width, sc.file_height, max_side, &sc.width, &sc.height);
  // One focal for the scene (the model has one): the median of the images' 35 mm equivalents,
  // so one zoomed photo does not move it; a note when they differ.
  const int long_side = std::max(sc.width, sc.height);
  if (!focal35.empty()) {
    std::sort(focal35.begin(), focal35.end());
    ExifInfo e;
    e.focal35_mm = focal35[focal35.size() / 2];
    sc.exif_focal = exif_focal_px(e, long_side, &sc.exif_focal_source);
    if (focal35.front() != focal35.back())
      sc.notes.push_back(fmt::format("EXIF 35 mm focal lengths differ ({:g}-{:g} mm): starting "
                                     "from their median, {:g} mm", focal35.front(),
                                     focal35.back(), e.focal35_mm));
    if (focal35.size() < sc.names.size())
      sc.notes.push_back(fmt::format("{} of {} images state no EXIF focal", sc.names.size() -
                                     focal35.size(), sc.names.size()));
  } else {
    // No 35 mm equivalent: the real focal length with the sensor's size, when the first image
    // gives both (exif_focal_px says why not otherwise).
    std::string how;
    sc.exif_focal = exif_focal_px(first, long_side, &how);
    if (sc.exif_focal > 0) sc.exif_focal_source = how;
    else if (!how.empty()) sc.notes.push_back(fmt::format("{}: {}", sc.names[0], how));
  }
}

// The reference cameras of poses_bounds.npy (path pb): raw, then scaled by 1/(0.75·min near)
// and recentred (formulas.md §7), with their near/far bounds and the focal at the loaded size.
void read_reference_cameras(Scene& sc, const std::string& pb) {
  NpyArray a = read_npy(pb);
  HCC_REQUIRE(a.shape.size() == 2 && a.shape[1] == 17, pb, "shape",
              "has shape {}", a.shape_str(), "(N, 17)");
  HCC_REQUIRE(a.shape[0] == int64_t(sc.names.size()), pb, "rows",
              "has {} poses but {} has {} images", a.shape[0], sc.image_dir, sc.names.size(),
              "one row per image");
  sc.has_reference = true;
  double minnear = 1e300;
  for (int64_t i = 0; i < a.shape[0]; ++i) {
    const double* row = a.data.data() + 17 * i;
    double H, W, f;
    sc.ref_c2w_raw.push_back(llff_row_to_c2w_checked(pb, i, row, &H, &W, &f));
    if (i == 0) {
      // Images in images_N are N× smaller than the H, W recorded in the poses.
      // (The files' size: --max-side scales the loaded images, and ref_focal with them.)
      double eh = H / sc.factor, ew = W / sc.factor;
      HCC_REQUIRE(std::abs(eh - sc.file_height) <= 1 && std::abs(ew - sc.file_width) <= 1,
                  sc.image_dir, "size",
                  "images are {}x{} but poses_bounds.npy says {}x{} / factor {} = {}x{}",
                  sc.file_width, sc.file_height, W, H, sc.factor, ew, eh, "matching sizes");
      sc.ref_focal = f * double(sc.width) / W;
    }
    sc.near.push_back(row[15]);
    sc.far.push_back(row[16]);
    minnear = std::min(minnear, row[15]);
  }
  sc.scale = 1.0 / (0.75 * minnear);
  std::vector<Mat34d> scaled = sc.ref_c2w_raw;
  for (auto& p : scaled) p.col(3) *= sc.scale;
  for (auto& n : sc.near) n *= sc.scale;
  for (auto& f : sc.far) f *= sc.scale;
  sc.ref_c2w = recenter_poses(scaled);
}

// Decodes every image, in parallel, each to the working size (a thread holds one full-size
// decode at a time); the first failing file (in name order) is the error.
void read_pixels(Scene& sc, int max_side) {
  sc.images.resize(sc.names.size());
  std::vector<std::string> errors(sc.names.size());
  parallel_for(int64_t(sc.names.size()), [&](int64_t i) {
    try {
      const std::string p = (fs::path(sc.image_dir) / sc.names[i]).string();
      sc.images[i] = read_image(p, max_side);
      HCC_REQUIRE(sc.images[i].width == sc.width && sc.images[i].height == sc.height, p, "",
                  "loaded at {}x{}, but its header said {}x{} (changed while loading?)",
                  sc.images[i].width, sc.images[i].height, sc.width, sc.height);
    } catch (const Error& e) {
      errors[i] = e.what();
    }
  });
  for (size_t i = 0; i < errors.size(); ++i)
    if (!errors[i].empty())
      throw Error((fs::path(sc.image_dir) / sc.names[i]).string(), "",
                  errors[i].substr(errors[i].find(": ") + 2));
}

}  // namespace

Scene load_scene(const std::string& dir, const SceneOptions& opt) {
  std::error_code ec;
  HCC_REQUIRE(fs::exists(dir, ec), dir, "", "no such folder");
  HCC_REQUIRE(fs::is_directory(dir, ec), dir, "", "not a folder", "a folder of images");
  Scene sc;
  sc.dir = dir;
  find_images(sc, dir, opt);
  read_image_sizes(sc, opt.max_side);
  const std::string pb = (fs::path(dir) / "poses_bounds.npy").string();
  if (fs::exists(pb, ec)) read_reference_cameras(sc, pb);
  // Every 8th image (0, 8, 16, …) is a test view (formulas.md §6), the rest train.
  for (int i = 0; i < int(sc.names.size()); ++i) (i % 8 == 0 ? sc.test : sc.train).push_back(i);
  if (opt.load_pixels) read_pixels(sc, opt.max_side);
  return sc;
}

}  // namespace hashcc
