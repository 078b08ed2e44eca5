// tools/simulator.h — the built-in forward-facing scene, ray traced analytically.
//
// The quick start and the end-to-end tests need a scene with known cameras, focal and
// geometry. This one is made of a textured backdrop plane, a few textured rectangles and
// spheres at distinct depths (so parallax and texture make poses learnable), seen by a
// forward-facing rig of cameras. It is rendered by exact ray–surface intersection, not by a
// NeRF, and written exactly like real LLFF data (images/ + poses_bounds.npy), so everything
// downstream runs the same code path as on real photos.
//
// Effects are switched per scene ("simulate only the effects a scene calls for"):
// Lambertian colour by default; view-dependent specular highlights only with `specular`.
#pragma once
#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "core/llff.h"

namespace hashcc {

struct SimOptions {
  int views = 20;
  int width = 128, height = 96;
  uint64_t seed = 1;
  bool specular = false;     // view-dependent (Phong) highlights on the spheres
  double focal_ratio = 0.8;  // focal in pixels = focal_ratio · width (LLFF fern: ≈ 0.81)
  int supersample = 2;       // s×s samples per pixel around the pixel position
  // The rig: a hand-held forward-facing capture. Centres on a jittered spiral of radius
  // `baseline`; each camera looks down −z (look_at = false) or turns towards a focus point 5
  // units ahead (look_at = true, LLFF's capture advice), then gets an independent hand-held
  // rotation (a random axis-angle, `rot_jitter_deg` standard deviation per component).
  //
  // Why these defaults (measured): with look-at cameras a camera's rotation is tied
  // to its position, and at the focus depth a rotation and a translation move the image alike,
  // so a short run cannot tell them apart (relative rotation error 5.6° vs 4.8° for doing
  // nothing after 1,200 steps). Independent rotations over a small baseline are what a phone
  // held forward gives, and they make pose learning observable in minutes.
  bool look_at = false;
  double baseline = 0.2;     // world units; the surfaces are at depths 2.6–8
  double rot_jitter_deg = 3;

  // The capture effects that make real forward-facing scenes differ (the "zoo"), each off unless
  // asked: a default SimOptions renders exactly the built-in scene it always did.
  //
  // sweep (--rig sweep): the centres walk along a horizontal arc round the focus point, each
  // camera turned to keep it in the middle of the frame, as a person photographing an object
  // from left to right does (LLFF horns). `sweep_deg` is the arc's whole angle: the rotation
  // spread grows with it (62 views over 30° give a mean pairwise rotation near horns' 9.8°).
  // `baseline` is then the vertical wander of the centres. Hand-held jitter still applies.
  bool sweep = false;
  double sweep_deg = 30;
  double focus_depth = 5;    // the point the lookat/sweep cameras turn to (world units ahead)
  // fov_deg > 0: the horizontal field of view in degrees, overriding focal_ratio
  // (focal_ratio = 0.5 / tan(fov/2); LLFF's phones: 62-64°).
  double fov_deg = 0;
  // backdrop_depth: the depth of the far wall (the objects stay at 2.6–6). 8 is the built-in
  // scene (far/near ≈ 3, as fern's 4.7 roughly); 40 puts a near subject before a far wall
  // (far/near ≈ 16, as horns). The wall grows with its depth so that it still fills the view.
  double backdrop_depth = 8;
  // jpeg (--jpeg): the images as a phone writes them, images/*.jpg (quality 92) with an EXIF
  // block stating the focal as FocalLengthIn35mmFilm (rounded to whole mm, as the tag is) and
  // orientation 1, except image001, stored on its side with orientation 6 (it must load
  // upright). For the EXIF and --max-side paths (issue 51); the PNG scene is unchanged.
  bool jpeg = false;

  double focal_px() const;   // the focal in pixels this rig renders with
};

struct SimScene {
  struct Plane { Eigen::Vector3d centre, normal, u_axis, v_axis; double half_u, half_v; int texture; };
  struct Sphere { Eigen::Vector3d centre; double radius; int texture; };
  std::vector<Plane> planes;  // planes[0] is the backdrop
  std::vector<Sphere> spheres;
  Eigen::Vector3d light_dir;  // unit, towards the light
  bool specular = false;

  // Closest hit along o + t·d (d need not be unit) with t > 0: returns t, or -1.
  // Fills colour (seen from direction d) and world normal when hit.
  double trace(const Eigen::Vector3d& o, const Eigen::Vector3d& d, Eigen::Vector3d* rgb) const;
  // Distance from a world point to the nearest surface of the scene (for point-cloud tests).
  double surface_distance(const Eigen::Vector3d& p) const;
};

struct SimCamera {
  Mat34d c2w;  // OpenGL camera-to-world (original world units)
};

// The default scene and rig for the given options (deterministic in the seed).
SimScene make_sim_scene(const SimOptions& opt);
std::vector<SimCamera> make_sim_rig(const SimOptions& opt);

// Renders one view: rgb (H, W, 3) in [0,1] and z-depth (H, W) along the camera's −z axis.
// Pixel (u, v) is centred at its integer position, as NeRF--'s rays are (formulas.md §1).
void render_sim_view(const SimScene& scene, const SimCamera& cam, const SimOptions& opt,
                     std::vector<float>* rgb, std::vector<float>* zdepth);

// Writes dir/images/imageNNN.png, dir/poses_bounds.npy (LLFF convention, near/far from the
// rendered depth) and dir/scene.json (the options). Returns the rig.
std::vector<SimCamera> write_sim_scene(const std::string& dir, const SimOptions& opt,
                                       bool progress = true);

}  // namespace hashcc
