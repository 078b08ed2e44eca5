// core/npy.h — NumPy .npy read/write (format versions 1.0–3.0).
//
// Reads float32/float64 (and int32/int64 for index arrays), little-endian, C or Fortran order;
// data come back as double in C (row-major) order whatever the file held. Every malformed
// file is a hashcc::Error naming the file and what was wrong; shapes are checked against what
// the caller expects (-1 = any length).
#pragma once
#include <cstdint>
#include <string>
#include <vector>

namespace hashcc {

struct NpyArray {
  std::vector<int64_t> shape;
  std::vector<double> data;  // C order
  std::string dtype;         // as in the file, e.g. "<f8"
  int64_t size() const;
  std::string shape_str() const;
};

// Reads a whole file. Throws hashcc::Error on anything malformed, including NaN/Inf when
// allow_nonfinite is false.
NpyArray read_npy(const std::string& path, bool allow_nonfinite = false);
// Parses .npy bytes already in memory (used by read_npy, the fuzzers and tests).
NpyArray parse_npy(const std::string& bytes, const std::string& name, bool allow_nonfinite = false);
// read_npy with the values as float (network weights): float32 files exactly, float64 files
// rounded once. Same checks and errors as read_npy.
struct NpyArrayF32 {
  std::vector<int64_t> shape;
  std::vector<float> data;  // C order
};
NpyArrayF32 read_npy_f32(const std::string& path, bool allow_nonfinite = false);
// read_npy plus a shape check; expected entries of -1 match any length.
NpyArray read_npy_shape(const std::string& path, const std::vector<int64_t>& expected,
                        bool allow_nonfinite = false);

// Writes C-order little-endian float64 ("<f8") or float32 ("<f4") or int64 ("<i8").
void write_npy(const std::string& path, const double* data, const std::vector<int64_t>& shape);
void write_npy(const std::string& path, const float* data, const std::vector<int64_t>& shape);
void write_npy_i64(const std::string& path, const int64_t* data, const std::vector<int64_t>& shape);

}  // namespace hashcc
