// eval/metrics.h — image quality metrics of formulas.md §7: PSNR, SSIM (+ its per-pixel map) and an
// error heatmap for reports. Pure functions over float RGB images; no I/O.
//
// Images are (H, W, 3) row-major, interleaved RGB, values in [0, 1] (not clamped here: the
// metrics are defined on whatever values they are given). Two images passed to a metric must
// have the same size, otherwise hashcc::Error.
#pragma once
#include <cstddef>
#include <cstdint>
#include <vector>

namespace hashcc {

struct ImageF {
  int H = 0, W = 0;
  std::vector<float> rgb;  // (H, W, 3)
  ImageF() = default;
  ImageF(int H_, int W_, float fill = 0.f) : H(H_), W(W_), rgb(size_t(H_) * W_ * 3, fill) {}
  float& at(int y, int x, int c) { return rgb[(size_t(y) * W + x) * 3 + c]; }
  float at(int y, int x, int c) const { return rgb[(size_t(y) * W + x) * 3 + c]; }
};

struct ImageRGB8 {
  int H = 0, W = 0;
  std::vector<uint8_t> rgb;  // (H, W, 3)
};

// Mean squared error over all pixels and channels (accumulated in double).
double mse(const ImageF& a, const ImageF& b);

// formulas.md §7: PSNR = −10·log10(MSE) on [0,1] RGB. Identical images (MSE = 0) give +infinity
// (std::numeric_limits<double>::infinity()); callers averaging over images must decide how to
// report that (the honest report says "inf", it never clamps silently).
double psnr(const ImageF& a, const ImageF& b);

// formulas.md §7 SSIM: 11×11 Gaussian window (σ = 1.5, normalised to sum 1), C1 = 0.01², C2 = 0.03²,
// ZERO padding with a same-size map — exactly F.conv2d(x, g, padding=5, groups=3) per channel,
// as in the usual PyTorch ssim code — then the mean over pixels and channels. Near the border
// the windowed means shrink (the padding zeros are counted), which is part of the definition.
// The blur is separable (rows, then columns; exact for a product kernel with zero padding),
// computed in double, parallel over rows.
double ssim(const ImageF& a, const ImageF& b);

// The per-pixel, per-channel SSIM map, (H, W, 3); ssim() is its mean.
std::vector<float> ssim_map(const ImageF& a, const ImageF& b);

// The normalised 1-D Gaussian of the SSIM window: 11 taps, σ = 1.5 (exposed for tests).
std::vector<double> ssim_gaussian_1d();

// A heatmap of the per-pixel error e = mean over RGB of |a − b|, colour-mapped with Google's
// Turbo map (polynomial approximation): e = 0 → dark blue, e ≥ max_error → dark red, linear in
// between (the scale is fixed, not per image, so heatmaps of different runs are comparable;
// the default 0.25 saturates at a quarter of the full range).
ImageRGB8 error_heatmap(const ImageF& a, const ImageF& b, float max_error = 0.25f);

// Turbo colour of t ∈ [0, 1] (clamped) as RGB in [0, 1].
void turbo_colormap(float t, float rgb_out[3]);

}  // namespace hashcc
