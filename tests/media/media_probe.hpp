// Test support for tests/media — what ffprobe/ffmpeg (Debian's ffmpeg package) say about an
// MP4, so that tests check the file a browser would get, not our own view of it.
#pragma once

#include <cstdio>
#include <stdexcept>
#include <string>
#include <vector>

namespace omnitwin::media::testing {

// Standard output of a shell command (stderr discarded) and its exit status.
struct CommandOutput {
  std::string out;
  int status = -1;
};

inline CommandOutput run_command(const std::string& cmd) {
  CommandOutput r;
  FILE* p = ::popen((cmd + " 2>/dev/null").c_str(), "r");
  if (!p) return r;
  char buf[4096];
  for (size_t n; (n = std::fread(buf, 1, sizeof buf, p)) > 0;) r.out.append(buf, n);
  r.status = ::pclose(p);
  return r;
}

// The value of "key" in ffprobe's JSON (first occurrence), without quotes; "" if absent.
inline std::string json_field(const std::string& json, const std::string& key) {
  const auto k = json.find("\"" + key + "\": ");
  if (k == std::string::npos) return "";
  size_t b = k + key.size() + 4;
  if (json[b] == '"') {
    const auto e = json.find('"', b + 1);
    return json.substr(b + 1, e - b - 1);
  }
  const auto e = json.find_first_of(",\n}", b);
  return json.substr(b, e - b);
}

// ffprobe's view of the first video stream.
struct StreamInfo {
  int status = -1;  // ffprobe's exit status (0: the file is readable)
  std::string codec, pix_fmt;
  int width = 0, height = 0, frames = 0;  // frames actually decoded
  double duration_s = 0;
};

inline StreamInfo probe(const std::string& file) {
  const auto r = run_command("ffprobe -v error -select_streams v:0 -show_streams -count_frames -of json '" + file + "'");
  StreamInfo s;
  s.status = r.status;
  s.codec = json_field(r.out, "codec_name");
  s.pix_fmt = json_field(r.out, "pix_fmt");
  auto num = [&](const char* key) { const auto v = json_field(r.out, key); return v.empty() ? 0.0 : std::stod(v); };
  s.width = static_cast<int>(num("width"));
  s.height = static_cast<int>(num("height"));
  s.frames = static_cast<int>(num("nb_read_frames"));
  s.duration_s = num("duration");
  return s;
}

// Frame `index` of the file decoded to RGB24, rows top to bottom ("" if ffmpeg fails).
inline std::string decode_frame_rgb(const std::string& file, int index) {
  return run_command("ffmpeg -v error -i '" + file + "' -vf 'select=eq(n\\," + std::to_string(index) +
                     ")' -frames:v 1 -f rawvideo -pix_fmt rgb24 -")
      .out;
}

}  // namespace omnitwin::media::testing
