// train/checkpoint.h — one versioned binary file holding a whole training state.
//
// Layout: "HASHCCKP" | u32 version | u64 payload bytes | payload | u64 FNV-1a checksum of the
// payload. The payload is a list of named sections (u32 name length, name, u64 byte length,
// bytes). Written with write_file_atomic (temporary file, fsync, rename): a crash at any moment
// leaves the previous checkpoint or the new one, never a torn one. Reading checks the magic,
// the version, every length against the file size and the checksum, so a truncated, foreign
// or bit-flipped file is a clear hashcc::Error, never a crash.
#pragma once
#include <cstdint>
#include <map>
#include <set>
#include <string>
#include <string_view>
#include <vector>

namespace hashcc {

constexpr uint32_t kCheckpointVersion = 1;

struct Checkpoint {
  std::map<std::string, std::string> sections;  // name → raw bytes

  void put_text(const std::string& name, const std::string& text) { sections[name] = text; }
  void put_floats(const std::string& name, const std::vector<float>& v);
  void put_floats(const std::string& name, const float* v, size_t n);
  const std::string& text(const std::string& name, const std::string& file) const;
  // Reads a float section, checking it holds exactly n values (n < 0: any).
  std::vector<float> floats(const std::string& name, const std::string& file, int64_t n = -1) const;

  std::string serialize() const;
  // only (non-null): keep just the sections it names (the whole file is still checked: length,
  // checksum, section headers); a reader that needs a few small sections (--cameras-from reads an
  // earlier run's cameras) then holds no copy of the networks and their moments.
  static Checkpoint parse(const std::string& bytes, const std::string& file,
                          const std::set<std::string>* only = nullptr);
};

// The sections of a checkpoint to write, as views of the caller's bytes (which must outlive
// save_checkpoint): the file is written straight from them, with the bytes serialize() gives
// for the same sections, but without copying the training state twice over (the state's
// copies, the joined payload and the file's bytes were each as large as the state).
struct CheckpointView {
  std::map<std::string, std::string_view> sections;  // name → raw bytes (not owned)

  void put_text(const std::string& name, const std::string& text) { sections[name] = text; }
  void put_floats(const std::string& name, const std::vector<float>& v);
};

void save_checkpoint(const std::string& path, const Checkpoint& c);
void save_checkpoint(const std::string& path, const CheckpointView& c);
Checkpoint load_checkpoint(const std::string& path, const std::set<std::string>* only = nullptr);
uint64_t fnv1a64(const void* data, size_t n);
// FNV-1a continued over more bytes: fnv1a64(ab) = fnv1a64_update(fnv1a64(a), b).
uint64_t fnv1a64_update(uint64_t h, const void* data, size_t n);

}  // namespace hashcc
