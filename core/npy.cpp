#include "core/npy.h"

#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>

#include "core/error.h"
#include "core/fileio.h"

namespace hashcc {

int64_t NpyArray::size() const {
  int64_t n = 1;
  for (auto s : shape) n *= s;
  return n;
}

std::string NpyArray::shape_str() const {
  std::string s = "(";
  for (size_t i = 0; i < shape.size(); ++i) s += (i ? ", " : "") + std::to_string(shape[i]);
  if (shape.size() == 1) s += ",";
  return s + ")";
}

namespace {

// Finds the value text of 'key' in the header dict: {'descr': '<f8', 'fortran_order': False, 'shape': (3, 4), }
std::string dict_value(const std::string& header, const std::string& key, const std::string& name) {
  auto k = header.find("'" + key + "'");
  HCC_REQUIRE(k != std::string::npos, name, "header", "no '{}' key in the .npy header", key);
  auto colon = header.find(':', k);
  HCC_REQUIRE(colon != std::string::npos, name, "header", "malformed '{}' entry", key);
  size_t b = colon + 1;
  while (b < header.size() && header[b] == ' ') ++b;
  HCC_REQUIRE(b < header.size(), name, "header", "malformed '{}' entry", key);
  if (header[b] == '(') {
    auto e = header.find(')', b);
    HCC_REQUIRE(e != std::string::npos, name, "header", "unterminated shape tuple");
    return header.substr(b, e - b + 1);
  }
  if (header[b] == '\'') {
    auto e = header.find('\'', b + 1);
    HCC_REQUIRE(e != std::string::npos, name, "header", "unterminated string for '{}'", key);
    return header.substr(b + 1, e - b - 1);
  }
  auto e = header.find_first_of(",}", b);
  HCC_REQUIRE(e != std::string::npos, name, "header", "malformed '{}' entry", key);
  return header.substr(b, e - b);
}

std::vector<int64_t> parse_shape(const std::string& tuple, const std::string& name) {
  std::vector<int64_t> shape;
  // fuzz finding (npy/crash-c25c457f): "'shape': ," gave "" here and substr(1) threw.
  HCC_REQUIRE(tuple.size() >= 2 && tuple.front() == '(' && tuple.back() == ')', name, "shape",
              "'{}' is not a shape tuple", tuple.substr(0, 40), "e.g. (20, 17)");
  std::string inner = tuple.substr(1, tuple.size() - 2);
  std::stringstream ss(inner);
  std::string tok;
  while (std::getline(ss, tok, ',')) {
    size_t b = tok.find_first_not_of(' '), e = tok.find_last_not_of(' ');
    if (b == std::string::npos) continue;
    tok = tok.substr(b, e - b + 1);
    HCC_REQUIRE(!tok.empty() && tok.find_first_not_of("0123456789") == std::string::npos, name,
                "shape", "'{}' is not a dimension", tok);
    HCC_REQUIRE(tok.size() <= 12, name, "shape", "dimension {} is too large", tok);
    shape.push_back(std::stoll(tok));
  }
  return shape;
}

}  // namespace

NpyArray parse_npy(const std::string& bytes, const std::string& name, bool allow_nonfinite) {
  HCC_REQUIRE(bytes.size() >= 10, name, "", "file too short to be .npy ({} bytes)", bytes.size());
  HCC_REQUIRE(std::memcmp(bytes.data(), "\x93NUMPY", 6) == 0, name, "",
              "not a .npy file (bad magic)");
  int major = uint8_t(bytes[6]);
  size_t header_len, off;
  if (major == 1) {
    header_len = uint8_t(bytes[8]) | (size_t(uint8_t(bytes[9])) << 8);
    off = 10;
  } else {
    HCC_REQUIRE(major == 2 || major == 3, name, "", "unsupported .npy version {}", major);
    HCC_REQUIRE(bytes.size() >= 12, name, "", "truncated .npy header");
    header_len = 0;
    for (int i = 0; i < 4; ++i) header_len |= size_t(uint8_t(bytes[8 + i])) << (8 * i);
    off = 12;
  }
  HCC_REQUIRE(off + header_len <= bytes.size(), name, "header", "truncated .npy header");
  std::string header = bytes.substr(off, header_len);
  NpyArray a;
  a.dtype = dict_value(header, "descr", name);
  std::string fortran = dict_value(header, "fortran_order", name);
  bool is_fortran = fortran.find("True") != std::string::npos;
  a.shape = parse_shape(dict_value(header, "shape", name), name);

  int itemsize = 0;
  char kind = 0;
  const std::string& d = a.dtype;
  bool little = !d.empty() && (d[0] == '<' || d[0] == '|' || d[0] == '=');
  if (d == "<f8" || d == "=f8") { itemsize = 8; kind = 'f'; }
  else if (d == "<f4" || d == "=f4") { itemsize = 4; kind = 'f'; }
  else if (d == "<i8" || d == "=i8") { itemsize = 8; kind = 'i'; }
  else if (d == "<i4" || d == "=i4") { itemsize = 4; kind = 'i'; }
  HCC_REQUIRE(little && itemsize > 0, name, "dtype", "unsupported dtype '{}'", d,
              "little-endian float32/float64/int32/int64");
  int64_t n = 1;
  for (auto s : a.shape) {
    HCC_REQUIRE(s >= 0 && (s == 0 || n <= (int64_t(1) << 40) / std::max<int64_t>(s, 1)), name,
                "shape", "shape {} is too large", s);
    n *= s;
  }
  size_t data_off = off + header_len;
  size_t need = size_t(n) * itemsize;
  HCC_REQUIRE(bytes.size() - data_off >= need, name, "data",
              "truncated: holds {} bytes of data, shape {} needs {}", bytes.size() - data_off,
              a.shape_str(), need);
  a.data.resize(n);
  const char* p = bytes.data() + data_off;
  for (int64_t i = 0; i < n; ++i) {
    double v;
    if (kind == 'f' && itemsize == 8) { double x; std::memcpy(&x, p + 8 * i, 8); v = x; }
    else if (kind == 'f') { float x; std::memcpy(&x, p + 4 * i, 4); v = x; }
    else if (itemsize == 8) { int64_t x; std::memcpy(&x, p + 8 * i, 8); v = double(x); }
    else { int32_t x; std::memcpy(&x, p + 4 * i, 4); v = x; }
    a.data[i] = v;
  }
  if (!allow_nonfinite)
    for (int64_t i = 0; i < n; ++i)
      HCC_REQUIRE(std::isfinite(a.data[i]), name, fmt::format("element {}", i),
                  "non-finite value {}", a.data[i], "finite numbers");
  if (is_fortran && a.shape.size() > 1) {
    // Fortran order: first index fastest. Re-lay out in C order.
    std::vector<double> c(n);
    size_t nd = a.shape.size();
    std::vector<int64_t> idx(nd, 0);
    for (int64_t f = 0; f < n; ++f) {
      int64_t ci = 0;
      for (size_t k = 0; k < nd; ++k) ci = ci * a.shape[k] + idx[k];
      c[ci] = a.data[f];
      for (size_t k = 0; k < nd; ++k) {  // increment Fortran multi-index
        if (++idx[k] < a.shape[k]) break;
        idx[k] = 0;
      }
    }
    a.data.swap(c);
  }
  return a;
}

NpyArray read_npy(const std::string& path, bool allow_nonfinite) {
  return parse_npy(read_file_bytes(path, int64_t(1) << 34), path, allow_nonfinite);
}

NpyArrayF32 read_npy_f32(const std::string& path, bool allow_nonfinite) {
  NpyArray a = read_npy(path, allow_nonfinite);
  return {std::move(a.shape), std::vector<float>(a.data.begin(), a.data.end())};
}

NpyArray read_npy_shape(const std::string& path, const std::vector<int64_t>& expected,
                        bool allow_nonfinite) {
  NpyArray a = read_npy(path, allow_nonfinite);
  bool ok = a.shape.size() == expected.size();
  for (size_t i = 0; ok && i < expected.size(); ++i)
    ok = expected[i] < 0 || expected[i] == a.shape[i];
  if (!ok) {
    NpyArray e;
    e.shape = expected;
    std::string want = e.shape_str();
    for (size_t p; (p = want.find("-1")) != std::string::npos;) want.replace(p, 2, "any");
    throw Error(path, "shape", "has shape " + a.shape_str(), "shape " + want);
  }
  return a;
}

namespace {
void write_raw(const std::string& path, const char* descr, const void* data, size_t bytes,
               const std::vector<int64_t>& shape) {
  NpyArray s;
  s.shape = shape;
  std::string header = fmt::format("{{'descr': '{}', 'fortran_order': False, 'shape': {}, }}",
                                   descr, s.shape_str());
  size_t total = 10 + header.size() + 1;
  size_t pad = (64 - total % 64) % 64;
  header += std::string(pad, ' ') + "\n";
  std::string out = std::string("\x93NUMPY\x01\x00", 8);
  out += char(header.size() & 0xff);
  out += char((header.size() >> 8) & 0xff);
  out += header;
  out.append(static_cast<const char*>(data), bytes);
  write_file_atomic(path, out);
}
int64_t count(const std::vector<int64_t>& shape) {
  int64_t n = 1;
  for (auto s : shape) n *= s;
  return n;
}
}  // namespace

void write_npy(const std::string& path, const double* data, const std::vector<int64_t>& shape) {
  write_raw(path, "<f8", data, count(shape) * 8, shape);
}
void write_npy(const std::string& path, const float* data, const std::vector<int64_t>& shape) {
  write_raw(path, "<f4", data, count(shape) * 4, shape);
}
void write_npy_i64(const std::string& path, const int64_t* data, const std::vector<int64_t>& shape) {
  write_raw(path, "<i8", data, count(shape) * 8, shape);
}

}  // namespace hashcc
