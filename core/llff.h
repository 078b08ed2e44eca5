// core/llff.h — scenes on disk: LLFF folders (images + poses_bounds.npy) and bare photo folders.
//
// Conventions (converted here, in one place):
//   LLFF poses_bounds.npy row = 3×5 matrix [c0 c1 c2 centre hwf] (row-major), axes in LLFF's
//   [down, right, back] order, then near, far. Ours (camera/README.md): camera-to-world,
//   OpenGL [right, up, back] = [c1, −c0, c2].
//   formulas.md §7: poses are centred (left-multiplied by the inverse of the average pose) and
//   translations scaled by 1 / (0.75 · min(near)), so that NDC's near plane (z = −1) lies in
//   front of every surface.
#pragma once
#include <Eigen/Core>
#include <string>
#include <vector>

#include "core/image.h"

namespace hashcc {

using Mat34d = Eigen::Matrix<double, 3, 4>;

// One poses_bounds.npy row (17 numbers) → OpenGL camera-to-world (unscaled), and back.
Mat34d llff_row_to_c2w(const double* row17, double* H = nullptr, double* W = nullptr,
                       double* focal = nullptr);
// llff_row_to_c2w for row i of the file `file`, after checking the row: 0 < near < far and
// positive H, W, focal; a hashcc::Error naming the file and row otherwise.
Mat34d llff_row_to_c2w_checked(const std::string& file, int64_t i, const double* row17,
                               double* H, double* W, double* focal);
void c2w_to_llff_row(const Mat34d& c2w, double H, double W, double focal, double near,
                     double far, double* row17);

// LLFF's average pose (mean centre, mean back axis, mean up) as a camera-to-world matrix.
Mat34d average_pose(const std::vector<Mat34d>& c2w);
// inv(avg) · pose for each pose: centres the rig on the average camera.
std::vector<Mat34d> recenter_poses(const std::vector<Mat34d>& c2w);
// 4×4 helpers
Eigen::Matrix4d to4(const Mat34d& m);

struct SceneOptions {
  std::string images_folder;  // "images", "images_4", "images_8"… ("" = the smallest present)
  bool load_pixels = true;    // false: sizes and names only
  // The working resolution (--max-side): images whose longer side exceeds it are downscaled on
  // load with an area filter, and only the small copy is kept; 0 keeps the files' size.
  int max_side = 0;
};

struct Scene {
  std::string dir;            // the folder given
  std::string image_dir;      // the folder the images came from
  int factor = 1;             // downscale of image_dir relative to the poses' H, W
  int width = 0, height = 0;  // of the loaded images: upright, after --max-side
  int file_width = 0, file_height = 0;  // as the files display (upright), before --max-side
  std::vector<std::string> names;  // file names, sorted
  // Files in image_dir skipped because their extension is not an image's (notes.txt,
  // Thumbs.db…; hidden files are skipped silently). The CLI prints them as a note. A file WITH
  // an image extension that does not decode is an error, never skipped.
  std::vector<std::string> ignored;
  std::vector<ImageU8> images;     // (H, W, 3) 8-bit, held until sampled
  std::vector<int> train, test;    // formulas.md §6: every 8th image (0, 8, 16…) is a test image

  // Reference cameras: only when poses_bounds.npy exists; used for evaluation, never training.
  bool has_reference = false;
  std::vector<Mat34d> ref_c2w_raw;  // OpenGL, world units of the file
  std::vector<Mat34d> ref_c2w;      // centred and scaled (formulas.md §7)
  std::vector<double> near, far;    // bounds, scaled like ref_c2w
  double ref_focal = 0;             // pixels at the loaded resolution
  double scale = 1;                 // 1 / (0.75 · min near)

  // From the JPEGs' EXIF (core/exif.h): a starting focal in pixels at the loaded size, 0 when
  // the files do not say (PNG, stripped JPEGs, LLFF's folders), and where it came from.
  double exif_focal = 0;
  std::string exif_focal_source;  // e.g. "exif 26 mm (35 mm equivalent)"
  int turned = 0;                 // photos whose EXIF orientation (2-8) was applied on load
  // Things worth a line that are not errors (EXIF blocks ignored, differing lenses); the CLI
  // prints them as notes.
  std::vector<std::string> notes;
};

// Loads an LLFF folder (dir/poses_bounds.npy + dir/images*/), or a bare folder of images
// (dir/images*/ or images directly in dir) with no poses. Throws hashcc::Error naming the file
// and the problem: missing/empty folder, fewer than 2 images, mixed sizes, corrupt images
// (including a .png/.jpg that is not an image),
// malformed poses_bounds.npy, pose/image count mismatch, size not matching H, W / factor.
Scene load_scene(const std::string& dir, const SceneOptions& opt = {});

// "" or a one-line note listing sc.ignored (at most a few names), for the CLI to print.
std::string ignored_files_note(const Scene& sc);

// The folders holding images in dir, smallest images first (by downscale factor).
std::vector<std::string> image_folders(const std::string& dir);

}  // namespace hashcc
