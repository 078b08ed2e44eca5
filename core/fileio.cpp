#include "core/fileio.h"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fcntl.h>
#include <unistd.h>

#include "core/error.h"

namespace hashcc {

namespace {
int g_fail_countdown = 0;
}

void inject_write_failure_after(int n) { g_fail_countdown = n; }

std::string read_file_bytes(const std::string& path, int64_t max_bytes) {
  std::error_code ec;
  HCC_REQUIRE(std::filesystem::exists(path, ec), path, "", "no such file");
  HCC_REQUIRE(!std::filesystem::is_directory(path, ec), path, "", "is a directory, not a file");
  FILE* f = std::fopen(path.c_str(), "rb");
  HCC_REQUIRE(f, path, "", "cannot open: {}", std::strerror(errno));
  std::string out;
  // The whole file in one allocation when its size is known (a checkpoint is tens of MiB: a
  // string grown by appending would hold up to twice that while it doubles).
  const auto size = std::filesystem::file_size(path, ec);
  if (!ec && int64_t(size) <= max_bytes) out.reserve(size_t(size));
  char buf[1 << 16];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, f)) > 0) {
    out.append(buf, n);
    if (int64_t(out.size()) > max_bytes) {
      std::fclose(f);
      throw Error(path, "", fmt::format("file larger than {} bytes", max_bytes));
    }
  }
  bool err = std::ferror(f);
  std::fclose(f);
  HCC_REQUIRE(!err, path, "", "read error");
  return out;
}

void write_file_atomic(const std::string& path, const std::string& bytes) {
  write_file_atomic(path, std::vector<std::string_view>{bytes});
}

void write_file_atomic(const std::string& path, const std::vector<std::string_view>& pieces) {
  std::string tmp = path + ".tmp";
  bool inject = g_fail_countdown > 0 && --g_fail_countdown == 0;
  int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  HCC_REQUIRE(fd >= 0, path, "", "cannot write: {}", std::strerror(errno));
  bool ok = true;
  int saved = 0;
  if (inject) { ok = false; saved = ENOSPC; }
  for (size_t k = 0; ok && k < pieces.size(); ++k) {
    const std::string_view bytes = pieces[k];
    size_t done = 0;
    while (ok && done < bytes.size()) {
      ssize_t w = ::write(fd, bytes.data() + done, bytes.size() - done);
      if (w < 0) { if (errno == EINTR) continue; ok = false; saved = errno; break; }
      done += size_t(w);
    }
  }
  if (ok && ::fsync(fd) != 0) { ok = false; saved = errno; }
  if (::close(fd) != 0 && ok) { ok = false; saved = errno; }
  if (!ok) {
    ::unlink(tmp.c_str());
    throw Error(path, "", fmt::format("write failed ({}); the previous file is kept",
                                      std::strerror(saved)));
  }
  if (::rename(tmp.c_str(), path.c_str()) != 0) {
    int e = errno;
    ::unlink(tmp.c_str());
    throw Error(path, "", fmt::format("rename failed: {}", std::strerror(e)));
  }
}

void make_dirs(const std::string& dir) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  HCC_REQUIRE(!ec, dir, "", "cannot create directory: {}", ec.message());
}

}  // namespace hashcc
