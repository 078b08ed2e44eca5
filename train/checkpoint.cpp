#include "train/checkpoint.h"

#include <cstring>

#include "core/error.h"
#include "core/fileio.h"

namespace hashcc {

uint64_t fnv1a64_update(uint64_t h, const void* data, size_t n) {
  const auto* p = static_cast<const uint8_t*>(data);
  for (size_t i = 0; i < n; ++i) { h ^= p[i]; h *= 1099511628211ULL; }
  return h;
}

uint64_t fnv1a64(const void* data, size_t n) {
  return fnv1a64_update(1469598103934665603ULL, data, n);
}

void CheckpointView::put_floats(const std::string& name, const std::vector<float>& v) {
  sections[name] = std::string_view(reinterpret_cast<const char*>(v.data()), v.size() * sizeof(float));
}

void Checkpoint::put_floats(const std::string& name, const std::vector<float>& v) {
  put_floats(name, v.data(), v.size());
}
void Checkpoint::put_floats(const std::string& name, const float* v, size_t n) {
  sections[name] = std::string(reinterpret_cast<const char*>(v), n * sizeof(float));
}

const std::string& Checkpoint::text(const std::string& name, const std::string& file) const {
  auto it = sections.find(name);
  HCC_REQUIRE(it != sections.end(), file, name, "section missing from checkpoint");
  return it->second;
}

std::vector<float> Checkpoint::floats(const std::string& name, const std::string& file, int64_t n) const {
  const std::string& b = text(name, file);
  HCC_REQUIRE(b.size() % 4 == 0, file, name, "section of {} bytes is not float32 data", b.size());
  HCC_REQUIRE(n < 0 || int64_t(b.size() / 4) == n, file, name, "holds {} values", b.size() / 4,
              fmt::format("{} (does the checkpoint belong to another model?)", n));
  std::vector<float> v(b.size() / 4);
  // An empty section must not reach memcpy: its data() may be null (UB).
  if (!b.empty()) std::memcpy(v.data(), b.data(), b.size());
  return v;
}

namespace {
template <class U> void put(std::string& s, U v) { s.append(reinterpret_cast<const char*>(&v), sizeof v); }
template <class U> U get(std::string_view s, size_t& off, const std::string& file, const char* what) {
  HCC_REQUIRE(off + sizeof(U) <= s.size(), file, what, "truncated checkpoint");
  U v;
  std::memcpy(&v, s.data() + off, sizeof v);
  off += sizeof v;
  return v;
}
}  // namespace

namespace {

// A checkpoint's file as pieces, in order: the header, each section's header and bytes (the
// caller's, not copied), the checksum. `heads` owns the small pieces.
struct FilePieces {
  std::vector<std::string> heads;
  std::vector<std::string_view> pieces;
};

FilePieces file_pieces(const CheckpointView& c) {
  FilePieces f;
  f.heads.reserve(c.sections.size() + 2);  // no reallocation: the views into heads stay valid
  std::vector<std::string_view> payload;
  uint64_t len = 0;
  for (auto& [name, bytes] : c.sections) {
    std::string h;
    put<uint32_t>(h, uint32_t(name.size()));
    h += name;
    put<uint64_t>(h, uint64_t(bytes.size()));
    f.heads.push_back(std::move(h));
    payload.push_back(f.heads.back());
    payload.push_back(bytes);
    len += f.heads.back().size() + bytes.size();
  }
  std::string head = "HASHCCKP";
  put<uint32_t>(head, kCheckpointVersion);
  put<uint64_t>(head, len);
  f.heads.push_back(std::move(head));
  f.pieces.push_back(f.heads.back());
  uint64_t sum = fnv1a64(nullptr, 0);
  for (const std::string_view p : payload) {
    sum = fnv1a64_update(sum, p.data(), p.size());
    f.pieces.push_back(p);
  }
  std::string tail;
  put<uint64_t>(tail, sum);
  f.heads.push_back(std::move(tail));
  f.pieces.push_back(f.heads.back());
  return f;
}

CheckpointView view_of(const Checkpoint& c) {
  CheckpointView v;
  for (auto& [name, bytes] : c.sections) v.sections[name] = bytes;
  return v;
}

}  // namespace

std::string Checkpoint::serialize() const {
  const FilePieces f = file_pieces(view_of(*this));
  std::string out;
  for (const std::string_view p : f.pieces) out += p;
  return out;
}

Checkpoint Checkpoint::parse(const std::string& s, const std::string& file,
                             const std::set<std::string>* only) {
  HCC_REQUIRE(s.size() >= 28 && s.compare(0, 8, "HASHCCKP") == 0, file, "",
              "not a hashcc checkpoint (bad magic or too short)");
  size_t off = 8;
  uint32_t version = get<uint32_t>(s, off, file, "version");
  HCC_REQUIRE(version == kCheckpointVersion, file, "version", "checkpoint version {}", version,
              fmt::format("version {} (written by another hashcc version)", kCheckpointVersion));
  uint64_t len = get<uint64_t>(s, off, file, "length");
  HCC_REQUIRE(len <= s.size() && off + len + 8 == s.size(), file, "length",
              "truncated or padded checkpoint: {} bytes, header says {}", s.size(), off + len + 8);
  // The payload read in place (a view of s: a checkpoint's bytes are not copied twice).
  const std::string_view payload(s.data() + off, len);
  size_t coff = off + len;
  uint64_t sum = get<uint64_t>(s, coff, file, "checksum");
  HCC_REQUIRE(sum == fnv1a64(payload.data(), payload.size()), file, "checksum",
              "checksum mismatch: the file is corrupt");
  Checkpoint c;
  size_t p = 0;
  while (p < payload.size()) {
    uint32_t nl = get<uint32_t>(payload, p, file, "section name");
    HCC_REQUIRE(p + nl <= payload.size(), file, "section name", "truncated checkpoint");
    std::string name(payload.substr(p, nl));
    p += nl;
    uint64_t bl = get<uint64_t>(payload, p, file, "section length");
    HCC_REQUIRE(bl <= payload.size() - p, file, name, "truncated checkpoint section");
    if (!only || only->count(name)) c.sections[name] = std::string(payload.substr(p, bl));
    p += bl;
  }
  return c;
}

void save_checkpoint(const std::string& path, const Checkpoint& c) {
  save_checkpoint(path, view_of(c));
}

void save_checkpoint(const std::string& path, const CheckpointView& c) {
  write_file_atomic(path, file_pieces(c).pieces);
}

Checkpoint load_checkpoint(const std::string& path, const std::set<std::string>* only) {
  return Checkpoint::parse(read_file_bytes(path, int64_t(1) << 34), path, only);
}

}  // namespace hashcc
