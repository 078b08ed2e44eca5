// core/fileio.h — whole-file reads with size limits, and crash-safe writes.
#pragma once
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace hashcc {

// Reads a whole file; throws hashcc::Error if missing, unreadable, or larger than max_bytes.
std::string read_file_bytes(const std::string& path, int64_t max_bytes);

// Crash-safe write: writes path + ".tmp", flushes it to disk (fsync), then renames over path.
// A crash at any moment leaves either the old file or the new one, never a torn one.
// Throws hashcc::Error naming the file on any failure (e.g. disk full), leaving the old file.
void write_file_atomic(const std::string& path, const std::string& bytes);
// The same for a file made of pieces, written one after the other straight from the caller's
// memory (a checkpoint's sections: no joined copy of tens of MiB).
void write_file_atomic(const std::string& path, const std::vector<std::string_view>& pieces);

// Test hook: when set to n > 0, the n-th following write_file_atomic fails as if the disk
// were full (for the "full disk keeps the previous checkpoint" test).
void inject_write_failure_after(int n);

// Creates a directory and its parents; throws hashcc::Error on failure.
void make_dirs(const std::string& dir);

}  // namespace hashcc
