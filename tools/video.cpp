#include "tools/video.h"

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fmt/core.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include "core/error.h"

extern char** environ;

namespace fs = std::filesystem;

namespace hashcc {

std::string find_on_path(const std::string& program) {
  const char* path = std::getenv("PATH");
  if (!path || !*path) return "";
  const std::string p = path;
  size_t at = 0;
  while (at <= p.size()) {
    size_t end = p.find(':', at);
    if (end == std::string::npos) end = p.size();
    const std::string dir = end > at ? p.substr(at, end - at) : ".";  // an empty entry is "."
    const std::string cand = (fs::path(dir) / program).string();
    std::error_code ec;
    if (fs::is_regular_file(cand, ec) && access(cand.c_str(), X_OK) == 0) return cand;
    at = end + 1;
  }
  return "";
}

std::string require_ffmpeg(const std::string& video) {
  HCC_REQUIRE(fs::path(video).extension() == ".mp4", "--video", video, "not a .mp4 file name",
              "FILE.mp4 (H.264)");
  const fs::path parent = fs::absolute(video).parent_path();
  HCC_REQUIRE(fs::is_directory(parent), "--video", video,
              fmt::format("its folder {} does not exist", parent.string()));
  const std::string ffmpeg = find_on_path("ffmpeg");
  HCC_REQUIRE(!ffmpeg.empty(), "--video", video,
              "needs the ffmpeg program, and none is on the PATH (nothing was rendered)",
              "ffmpeg installed (Debian: apt-get install ffmpeg), or no --video");
  return ffmpeg;
}

std::vector<std::string> ffmpeg_args(const std::string& frames_dir, int fps, const std::string& out) {
  return {"-y", "-hide_banner", "-loglevel", "error", "-framerate", std::to_string(fps),
          "-i", (fs::path(frames_dir) / "%04d_rgb.png").string(),
          "-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2",  // yuv420p needs even sides
          "-c:v", "libx264", "-pix_fmt", "yuv420p", "-movflags", "+faststart", "-f", "mp4", out};
}

void encode_video(const std::string& ffmpeg, const std::string& frames_dir, int fps,
                  const std::string& video) {
  const std::string tmp = video + ".tmp.mp4";
  std::vector<std::string> args = ffmpeg_args(frames_dir, fps, tmp);
  args.insert(args.begin(), "ffmpeg");
  std::vector<char*> argv;
  for (std::string& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  pid_t pid = 0;
  const int err = posix_spawn(&pid, ffmpeg.c_str(), nullptr, nullptr, argv.data(), environ);
  HCC_REQUIRE(err == 0, "--video", video, fmt::format("could not start {}: {}", ffmpeg, std::strerror(err)));
  int status = 0;
  while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
    std::error_code ec;
    fs::remove(tmp, ec);
    throw Error("--video", video, WIFEXITED(status)
                                      ? fmt::format("ffmpeg exited with status {} (its message is above)", WEXITSTATUS(status))
                                      : "ffmpeg was killed by a signal");
  }
  std::error_code ec;
  fs::rename(tmp, video, ec);
  HCC_REQUIRE(!ec, "--video", video, fmt::format("could not rename {} to it: {}", tmp, ec.message()));
}

}  // namespace hashcc
