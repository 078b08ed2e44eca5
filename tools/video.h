// tools/video.h — `hashcc render --video FILE.mp4`: the rendered frames as one H.264 video.
//
// Encoding video is ffmpeg's job, and ffmpeg is an optional dependency: hashcc does not link
// it (libavcodec would be one more build dependency for everyone, for one flag) but runs the
// `ffmpeg` program when it is on the PATH, found at run time. Without it, --video stops with a
// clear message BEFORE any frame is rendered (exit status 2), so a long render is never
// wasted on a video that cannot be made. Debian: apt-get install ffmpeg.
#pragma once
#include <string>
#include <vector>

namespace hashcc {

// The full path of an executable `program` in $PATH's folders, "" when none.
std::string find_on_path(const std::string& program);

// The check --video makes before rendering: FILE ends in .mp4 and its folder exists, and
// ffmpeg is on the PATH. Returns ffmpeg's path; hashcc::Error naming --video otherwise.
std::string require_ffmpeg(const std::string& video);

// The arguments (after the program) that encode frames_dir/0000_rgb.png, 0001_rgb.png, … at fps
// into `out` as H.264 MP4, yuv420p (what every player reads; odd sizes padded by one pixel).
std::vector<std::string> ffmpeg_args(const std::string& frames_dir, int fps, const std::string& out);

// Runs ffmpeg (its errors on stderr) into FILE.tmp.mp4, then renames it to FILE: a crash or a
// failed encode never leaves a torn video under FILE. hashcc::Error when ffmpeg fails.
void encode_video(const std::string& ffmpeg, const std::string& frames_dir, int fps,
                  const std::string& video);

}  // namespace hashcc
