// eval/lpips.h — LPIPS-VGG (Zhang et al. 2018, v0.1 linear heads) on the CPU, formulas.md §7.
//
// Pipeline per image pair (both images run through the network in lockstep, so only one
// layer's activations per image are alive at a time):
//   x ∈ [0,1] → 2x − 1 → scaling layer (x − shift)/scale, shift = (−.030, −.088, −.188),
//   scale = (.458, .448, .450) → VGG16 `features` up to relu5_3 (conv3×3 pad 1 + ReLU,
//   2×2 max-pool stride 2 between blocks) with taps after relu1_2, relu2_2, relu3_3,
//   relu4_3, relu5_3 (torchvision indices 3, 8, 15, 22, 29) → per tap: unit-normalise over
//   channels, x / (sqrt(Σ_c x²) + 1e-10), squared difference, 1×1 linear head (non-negative
//   weights w_k, no bias), mean over space → sum over the 5 taps.
//
// Weights (one .npy per tensor, float32 or float64, C order, little-endian) in one folder:
//   features.{0,2,5,7,10,12,14,17,19,21,24,26,28}.{weight,bias}.npy  — torchvision vgg16
//       ImageNet weights, shapes (out, in, 3, 3) and (out,)
//   vgg.lin{0..4}.model.1.weight.npy                                 — LPIPS v0.1 heads,
//       shape (1, C_k, 1, 1)
// tools/export_lpips_weights.py writes that folder (needs PyTorch + internet, run once).
// The linear heads ship in /work/shared/data/lpips/weights/v0.1_npy/; the VGG backbone is
// not redistributable here, so callers check lpips_available(dir) and otherwise report
// "LPIPS: not computed (no weights)".
//
// Tensors are planar (C, H, W), like PyTorch's NCHW with N = 1.
#pragma once
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "eval/metrics.h"

namespace hashcc {

// y (O, H, W) = conv3×3(x (C, H, W), Wt (O, C, 3, 3)) + b (O), zero padding 1, stride 1
// (cross-correlation, as torch.nn.Conv2d). im2col over row tiles + one Eigen GEMM per tile;
// a tile's column matrix holds at most max_col_floats values (bounds memory on large images).
void conv3x3_forward(float* y, const float* x, const float* Wt, const float* b, int C, int O,
                     int H, int W, int64_t max_col_floats = int64_t(1) << 24);
// In place ReLU over n values.
void relu_inplace(float* x, int64_t n);
// y (C, H/2, W/2) = 2×2 max-pool, stride 2, floor mode (torch.nn.MaxPool2d(2, 2)) of x (C, H, W).
void maxpool2x2_forward(float* y, const float* x, int C, int H, int W);

struct LpipsVgg {
  struct Conv {
    int in = 0, out = 0;
    std::vector<float> weight;  // (out, in, 3, 3)
    std::vector<float> bias;    // (out)
  };
  // VGG16 conv layers per block: 2, 2, 3, 3, 3.
  static constexpr std::array<int, 5> kConvsPerBlock = {2, 2, 3, 3, 3};
  // torchvision `features` indices of the 13 convs (their .npy names).
  static constexpr std::array<int, 13> kFeatureIndex = {0, 2, 5, 7, 10, 12, 14, 17, 19, 21, 24, 26, 28};

  std::array<int, 5> widths;           // channels of each block (VGG16: 64, 128, 256, 512, 512)
  std::vector<Conv> convs;             // 13 layers
  std::array<std::vector<float>, 5> lin;  // head k: (widths[k]) non-negative weights

  // Zero-weight network of the given block widths (tests use small widths with random weights).
  explicit LpipsVgg(std::array<int, 5> widths = {64, 128, 256, 512, 512});

  // Reads the full weight set from dir (names above). Missing or malformed file, or a shape
  // that does not chain (in of layer l+1 ≠ out of layer l, heads ≠ tap widths) → hashcc::Error
  // naming the file.
  static LpipsVgg load(const std::string& dir);

  // LPIPS distance of two same-size images in [0,1] (≥ 0; 0 for identical images; symmetric).
  // Images must be at least 16×16 (four 2× poolings before relu5_3).
  double distance(const ImageF& a, const ImageF& b) const;
  // The 5 per-tap terms whose sum is distance().
  std::array<double, 5> distance_per_tap(const ImageF& a, const ImageF& b) const;
};

// Reads the five v0.1 VGG linear heads vgg.lin{k}.model.1.weight.npy from dir; shape (1, C, 1, 1)
// with C = 64, 128, 256, 512, 512 required, values finite and ≥ 0; otherwise hashcc::Error.
std::array<std::vector<float>, 5> load_lpips_vgg_heads(const std::string& dir);

// True when dir holds every file LpipsVgg::load needs (existence only; load() validates).
bool lpips_available(const std::string& dir);

// File names LpipsVgg::load reads, in order (backbone weight/bias pairs, then the 5 heads).
std::vector<std::string> lpips_vgg_file_names();

}  // namespace hashcc
