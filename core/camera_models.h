// core/camera_models.h — approximate cameras from other tools, for `hashcc train --init-poses`.
//
// Three formats are read:
//   * a COLMAP text model folder: cameras.txt, images.txt (and points3D.txt when present);
//   * an LLFF poses_bounds.npy;
//   * a cameras.json in the transforms.json convention (instant-ngp / nerfstudio; hashcc writes
//     one at the end of every run).
//
// Conventions are converted in ONE place, camera_models.cpp (`c2w_from_colmap`, and
// `llff_row_to_c2w` in core/llff.cpp for LLFF), into ours (camera/README.md): camera-to-world,
// OpenGL axes [right, up, back].
//   COLMAP   images.txt holds world-to-camera (QW QX QY QZ = R_cw, TX TY TZ = t_cw), OpenCV
//            axes [right, down, forward]:  c2w_cv = [R_cwᵀ | −R_cwᵀ t_cw],
//            c2w = c2w_cv · diag(1, −1, −1)  (flip the camera's y and z axes).
//   LLFF     columns [down, right, back] → [right, up, back] = [c1, −c0, c2].
//   JSON     transform_matrix is already OpenGL camera-to-world; used as is.
//
// Then `init_poses_for_scene` matches the model's images to the scene's by file name and puts
// them in the formulas.md §7 frame so NDC works unchanged: translations scaled by 1 / (0.75 · near),
// then centred on the average pose (the loader's recipe for poses_bounds.npy, applied to these
// cameras). Where `near` comes from, by format:
//   poses_bounds.npy  min of its near bounds, exactly as the loader (core/llff.cpp).
//   COLMAP            LLFF's imgs2poses recipe on the sparse points: per image, the depths of
//                     the 3D points it observes (images.txt POINTS2D ids → points3D.txt);
//                     near_i = 0.1th percentile (numpy's linear interpolation); near = min near_i.
//   cameras.json      written by hashcc ("ndc" key present): already in this frame, scale 1;
//                     any other cameras.json has no bounds: the fallback below.
//   none of these     the fallback: scale so that the RMS distance of the camera centres from
//                     their mean is kTypicalSpread (fern's, measured in the formulas.md §7 frame), and
//                     a note says so. It assumes a hand-held forward-facing capture like LLFF's
//                     (scene depth ≈ 10–50× the camera spread); for other captures give
//                     COLMAP's points3D.txt or a poses_bounds.npy.
// Every malformed file, line or value is a hashcc::Error naming the file and the line.
#pragma once
#include <Eigen/Core>
#include <string>
#include <vector>

#include "core/llff.h"

namespace hashcc {

// RMS distance of the camera centres from their mean in the formulas.md §7 frame, LLFF fern
// (poses_bounds.npy, 20 images): used only when a model has no depth information.
inline constexpr double kTypicalSpread = 0.2750;

struct CameraModel {
  std::string path;            // file or folder read
  std::string format;          // "colmap", "llff", "json"
  std::vector<std::string> names;  // image file names (may be empty for "llff": by position)
  std::vector<Mat34d> c2w;     // OpenGL camera-to-world, the model's world units
  std::vector<double> fx, fy;  // focal in pixels at (width, height)
  std::vector<int> width, height;  // image size the focal refers to (0 = unknown)
  std::vector<double> near;    // per image near depth (model units), empty when unknown
  bool prescaled = false;      // already in the formulas.md §7 frame (a hashcc cameras.json)
  std::vector<std::string> notes;  // things reported to the user (ignored radial terms, …)
};

// COLMAP (world-to-camera, OpenCV axes) → ours (camera-to-world, OpenGL). q = (w, x, y, z),
// normalised here.
Mat34d c2w_from_colmap(const Eigen::Vector4d& qvec, const Eigen::Vector3d& tvec);
// The inverse, for writers and tests: c2w (OpenGL) → COLMAP qvec (w ≥ 0), tvec.
void colmap_from_c2w(const Mat34d& c2w, Eigen::Vector4d* qvec, Eigen::Vector3d* tvec);

CameraModel read_colmap_text(const std::string& folder);
CameraModel read_poses_bounds_model(const std::string& npy_path);
CameraModel read_cameras_json(const std::string& path);
// Dispatch on PATH: a folder → COLMAP text (or, if it holds poses_bounds.npy / cameras.json /
// transforms.json and no cameras.txt, that file); *.npy → LLFF; *.json → cameras.json.
CameraModel read_camera_model(const std::string& path);

// Percentile with numpy's default linear interpolation (p in [0, 100]); v is copied.
double percentile(std::vector<double> v, double p);

struct InitPoses {
  std::vector<Mat34d> c2w;       // one per scene image (scene order), formulas.md §7 frame
  std::vector<bool> from_model;  // false: started at the mean pose of the others
  double scale = 1;              // applied to the model's translations
  std::string scale_source;      // how the scale was found (for the report)
  bool has_focal = false;
  double fx = 0, fy = 0;         // pixels at the scene's loaded size
  std::vector<std::string> notes;
};

// Matches by file name (exact base name first, else the name without its extension, so a
// model built on images/IMG_1.JPG matches images_8/IMG_1.png); a poses_bounds.npy matches by
// position (row i = i-th image in sorted order, as LLFF itself) and must have one row per
// image. Images missing from the model start at the average pose of the others (reported).
// No image in common → hashcc::Error.
InitPoses init_poses_for_scene(const CameraModel& m, const Scene& scene);

// Writers (tests, tools): a COLMAP text model of PINHOLE cameras (one per image) with no
// points, and a transforms.json-style cameras.json.
void write_colmap_text(const std::string& folder, const std::vector<std::string>& names,
                       const std::vector<Mat34d>& c2w, double fx, double fy, int W, int H);
void write_cameras_json_file(const std::string& path, const std::vector<std::string>& names,
                             const std::vector<Mat34d>& c2w, double fx, double fy, int W, int H);

}  // namespace hashcc
