// media layer — render_run: run directory files → frame states → SceneRenderer →
// VideoEncoder (see run_video.hpp). The file readers here check what they read and name the
// file and line of anything wrong, since run directories may come from another machine.
#include "media/run_video.hpp"

#include "media/json_problem.hpp"

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <vector>

#include "media/scene_render.hpp"
#include "physics/mujoco_message.hpp"
#include "media/video_encoder.hpp"

namespace omnitwin::media {
namespace {

namespace fs = std::filesystem;

std::string read_text(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  if (!in) throw std::runtime_error(fmt::format("cannot read {}", p.string()));
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

std::vector<std::string> split(const std::string& line, char sep) {
  std::vector<std::string> out;
  std::string field;
  std::istringstream in(line);
  while (std::getline(in, field, sep)) out.push_back(field);
  if (!line.empty() && line.back() == sep) out.emplace_back();
  return out;
}

// A CSV file of numbers under a header line, stored by column.
struct CsvTable {
  std::string file;
  std::vector<std::string> names;
  std::vector<std::vector<double>> cols;

  size_t rows() const { return cols.empty() ? 0 : cols[0].size(); }
  const std::vector<double>* find(const std::string& name) const {
    const auto it = std::find(names.begin(), names.end(), name);
    return it == names.end() ? nullptr : &cols[it - names.begin()];
  }
  const std::vector<double>& need(const std::string& name) const {
    if (const auto* c = find(name)) return *c;
    throw std::runtime_error(fmt::format("{}: no column \"{}\"", file, name));
  }
};

double parse_number(const std::string& text, const CsvTable& t, size_t line, size_t col) {
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (text.empty() || end != text.c_str() + text.size())
    throw std::runtime_error(fmt::format("{}:{}: column \"{}\": not a number: \"{}\"", t.file, line,
                                         t.names[col], text));
  return v;
}

CsvTable read_csv(const fs::path& p) {
  CsvTable t{p.string(), {}, {}};
  std::istringstream in(read_text(p));
  std::string line;
  if (!std::getline(in, line)) throw std::runtime_error(t.file + ": empty file (no header line)");
  t.names = split(line, ',');
  t.cols.resize(t.names.size());
  for (size_t n = 2; std::getline(in, line); ++n) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty()) continue;
    const auto fields = split(line, ',');
    if (fields.size() != t.names.size())
      throw std::runtime_error(fmt::format("{}:{}: {} fields, the header has {}", t.file, n, fields.size(), t.names.size()));
    for (size_t c = 0; c < fields.size(); ++c) t.cols[c].push_back(parse_number(fields[c], t, n, c));
  }
  if (t.rows() == 0) throw std::runtime_error(t.file + ": no data rows");
  return t;
}

// A scenario fault from run.json, as far as the overlay needs it.
struct Fault {
  double at_s = 0, duration_s = 0;  // duration 0: to the end of the run
  std::string text;
  bool active(double t) const { return t >= at_s && (duration_s <= 0 || t < at_s + duration_s); }
};

std::vector<Fault> read_faults(const fs::path& p) {
  const std::string text = read_text(p);
  std::vector<Fault> out;
  try {
    const auto j = nlohmann::json::parse(text);
    if (j.contains("format") && j.at("format").get<int>() != 1)
      throw std::runtime_error(fmt::format("unsupported format {}", j.at("format").dump()));
    for (const auto& f : j.value("faults", nlohmann::json::array())) {
      Fault fault{f.at("at_s").get<double>(), f.value("duration_s", 0.0), f.value("text", "")};
      if (fault.text.empty()) fault.text = f.value("kind", "fault") + " " + f.value("target", "");
      out.push_back(std::move(fault));
    }
  } catch (const std::exception& e) {
    throw std::runtime_error(fmt::format("{}: {}", p.string(), json_problem(e)));
  }
  return out;
}

physics::ModelPtr load_model(const fs::path& p) {
  if (!fs::exists(p)) throw BadRunRecord(fmt::format("cannot read {}", p.string()));
  char err[1024] = "";
  physics::ModelPtr m(mj_loadXML(p.string().c_str(), nullptr, err, sizeof err));
  if (!m) throw BadRunRecord(fmt::format("{}: MuJoCo cannot load the model: {}", p.string(), physics::one_line(err)));
  return m;
}

// Index i and weight a with t between samples i and i+1 (a = 0 at or outside the ends).
struct Bracket {
  size_t i = 0;
  double a = 0;
};

Bracket bracket(const std::vector<double>& ts, double t) {
  if (t <= ts.front()) return {0, 0};
  if (t >= ts.back()) return {ts.size() - 1, 0};
  const size_t i = std::upper_bound(ts.begin(), ts.end(), t) - ts.begin() - 1;
  const double span = ts[i + 1] - ts[i];
  return {i, span > 0 ? (t - ts[i]) / span : 0};
}

double lerp(const std::vector<double>& v, Bracket b) {
  return b.a > 0 ? v[b.i] + b.a * (v[b.i + 1] - v[b.i]) : v[b.i];
}

// Drive state code of bus.csv (twin/run_state.hpp) as a word.
const char* state_word(double code) {
  static constexpr const char* kWords[] = {"off", "wait", "run", "sync", "FAULT"};
  const int c = std::isfinite(code) ? static_cast<int>(code) : -1;
  return c >= 0 && c <= 4 ? kWords[c] : "?";
}

}  // namespace

namespace {

// The recorded run, ready to be sampled at any sim time.
class Recording {
 public:
  explicit Recording(const fs::path& dir) {
    try {
      traj_ = read_csv(dir / "trajectory.csv");
      columns();
    } catch (const std::runtime_error& e) {
      throw BadRunRecord(e.what());
    }
    read_optional(dir);
  }

  double end_time() const { return t_->back(); }

  const std::vector<PathPoint>& reference() const { return reference_; }

  // The frame state at sim time t [s]. The returned trace points into this object.
  FrameState at(double t) {
    const Bracket b = bracket(*t_, t);
    FrameState s;
    s.t = t;
    s.x = lerp(*x_, b);
    s.y = lerp(*y_, b);
    s.phi = lerp(*phi_, b);
    for (int i = 0; i < 4; ++i) s.wheel_angle[i] = finite_or_zero(lerp(*wheel_[i], b));
    s.speed = finite_or_zero(std::hypot(lerp(*vx_, b), lerp(*vy_, b)));
    bus_lines(t, s);
    for (const auto& f : faults_)
      if (f.active(t)) s.faults.push_back(f.text);
    s.trace = trace_until(t, {s.x, s.y});
    return s;
  }

 private:
  // trajectory.csv's columns, checked; then the paths drawn from them.
  void columns() {
    t_ = &traj_.need("t");
    x_ = &traj_.need("x");
    y_ = &traj_.need("y");
    phi_ = &traj_.need("phi");
    vx_ = &traj_.need("vx");
    vy_ = &traj_.need("vy");
    for (int i = 0; i < 4; ++i) wheel_[i] = &traj_.need(fmt::format("w{}_angle_rad", i + 1));
    check_rows();
    build_paths();
  }

  static double finite_or_zero(double v) { return std::isfinite(v) ? v : 0.0; }

  // run.json (faults) and bus.csv (bus health) only feed the overlay, and an older run has
  // neither: one that is absent or unreadable drops its overlay line with a warning, as the
  // report does, rather than failing the whole video (found in review).
  void read_optional(const fs::path& dir) {
    try {
      if (fs::exists(dir / "run.json")) faults_ = read_faults(dir / "run.json");
      else spdlog::warn("{} is absent: the video shows no faults", (dir / "run.json").string());
    } catch (const std::exception& e) {
      spdlog::warn("{}; the video shows no faults", e.what());
    }
    try {
      if (fs::exists(dir / "bus.csv")) {
        bus_ = read_csv(dir / "bus.csv");
        bus_->need("t");
      }
    } catch (const std::exception& e) {
      bus_.reset();
      spdlog::warn("{}; the video shows no bus health", e.what());
    }
  }

  // Times must increase; the pose must be known in every row.
  void check_rows() const {
    for (size_t r = 0; r < traj_.rows(); ++r) {
      const bool ok = std::isfinite((*t_)[r]) && std::isfinite((*x_)[r]) &&
                      std::isfinite((*y_)[r]) && std::isfinite((*phi_)[r]);
      if (!ok) throw std::runtime_error(fmt::format("{}:{}: t, x, y, phi must be numbers", traj_.file, r + 2));
      if (r > 0 && (*t_)[r] < (*t_)[r - 1])
        throw std::runtime_error(fmt::format("{}:{}: t goes backwards", traj_.file, r + 2));
    }
  }

  // The reference (finite points only) and the driven trace, thinned to what a frame draws.
  void build_paths() {
    const auto& rx = traj_.need("ref_x");
    const auto& ry = traj_.need("ref_y");
    std::vector<PathPoint> ref;
    for (size_t r = 0; r < traj_.rows(); ++r)
      if (std::isfinite(rx[r]) && std::isfinite(ry[r])) ref.push_back({rx[r], ry[r]});
    reference_ = std::move(ref);
    std::vector<PathPoint> trace;
    for (size_t r = 0; r < traj_.rows(); ++r) trace.push_back({(*x_)[r], (*y_)[r]});
    std::vector<size_t> kept = simplify_path(trace, SceneRenderer::kPathTolerance);
    // Still too many (a long wiggly run): every n-th of the simplified points.
    const size_t stride = (kept.size() + SceneRenderer::kMaxPathPoints - 3) / (SceneRenderer::kMaxPathPoints - 2);
    for (size_t k = 0; k < kept.size(); k += std::max<size_t>(1, stride)) {
      trace_.push_back(trace[kept[k]]);
      trace_t_.push_back((*t_)[kept[k]]);
    }
  }

  // The trace samples up to t, then the current position.
  std::span<const PathPoint> trace_until(double t, PathPoint now) {
    const size_t n = std::upper_bound(trace_t_.begin(), trace_t_.end(), t) - trace_t_.begin();
    scratch_.assign(trace_.begin(), trace_.begin() + n);
    scratch_.push_back(now);
    return scratch_;
  }

  // Bus health at t from the last bus.csv row at or before t (counters are cumulative).
  void bus_lines(double t, FrameState& s) const {
    if (!bus_) return;
    const auto& ts = bus_->need("t");
    const size_t r = std::max<ptrdiff_t>(0, std::upper_bound(ts.begin(), ts.end(), t) - ts.begin() - 1);
    auto val = [&](const std::string& name) { const auto* c = bus_->find(name); return c ? (*c)[r] : NAN; };
    // Load with a decimal below 10 % (an EtherCAT segment's is 0.4 … 1.3 %: "0%" said nothing).
    const double load = 100 * val("load");
    s.bus = fmt::format("tx {:.0f}  rx {:.0f}  drop {:.0f}  err {:.0f}  load {:.{}f}%", val("frames_tx"),
                        val("frames_rx"), val("dropouts"), val("errors"), load, load < 9.95 ? 1 : 0);
    for (int i = 1; i <= 4; ++i) {
      const std::string name = fmt::format("s{}_state", i);
      if (bus_->find(name)) s.slaves += fmt::format("{}{}", s.slaves.empty() ? "" : " ", state_word(val(name)));
    }
  }

  CsvTable traj_;
  std::optional<CsvTable> bus_;
  std::vector<Fault> faults_;
  const std::vector<double>*t_, *x_, *y_, *phi_, *vx_, *vy_;
  std::array<const std::vector<double>*, 4> wheel_{};
  std::vector<PathPoint> reference_, trace_, scratch_;
  std::vector<double> trace_t_;
};

void validate(const VideoOptions& o) {
  if (o.width < 2 || o.height < 2 || o.width % 2 || o.height % 2)
    throw std::invalid_argument(fmt::format("video size must be even and at least 2x2, got {}x{}", o.width, o.height));
  if (!(o.fps > 0) || o.fps > 1000)
    throw std::invalid_argument(fmt::format("video fps must be in (0, 1000], got {}", o.fps));
}

// The backend the options name, else OMNITWIN_GL's; std::invalid_argument if unknown.
GlBackend backend_of(const VideoOptions& o) {
  return o.backend.empty() ? gl_backend_from_env() : gl_backend_from_name(o.backend);
}

// Frames 0 … total-1 into the encoder until `stop` is seen; the flag is read before each
// frame only, so once set (and however often set again) finalising is never cut short.
VideoResult render_frames(Recording& rec, SceneRenderer& renderer, VideoEncoder& encoder, const VideoOptions& o,
                          const std::atomic<bool>* stop) {
  // Frames at k/fps, and the run's last instant as the last frame where T·fps is not whole:
  // the video ended up to a frame short of the final state (found in review).
  const double end = rec.end_time();
  const int steps = static_cast<int>(std::floor(end * o.fps + 1e-6));
  const bool end_frame = steps / o.fps < end - 1e-9;
  const int total = steps + 1 + (end_frame ? 1 : 0);
  VideoResult res{encoder.path()};
  res.renderer = renderer.gl_description();
  for (int k = 0; k < total; ++k) {
    res.stopped_early = stop && stop->load();
    if (res.stopped_early) break;
    encoder.add_frame(renderer.render(rec.at(k <= steps ? k / o.fps : end)).data());
    if (o.progress) o.progress(k + 1, total);
  }
  if (res.stopped_early && encoder.frames() == 0) {
    // Stopped before the first frame: an MP4 of no frames is no video (players and ffmpeg
    // reject it); the encoder, never closed, removes its .part file.
    res.path.clear();
    return res;
  }
  encoder.close();  // trailer, then the rename: the file under out_file is whole or absent
  res.frames = encoder.frames();
  res.duration_s = encoder.duration_s();
  return res;
}

// The whole render; throws on any failure (the encoder has then removed its .part file).
VideoResult render_or_throw(const std::string& run_dir, const std::string& out_file, const VideoOptions& o,
                            GlBackend backend, const std::atomic<bool>* stop) {
  Recording rec(run_dir);
  SceneRenderer renderer(load_model(fs::path(run_dir) / "platform.xml"),
                         SceneOptions{.width = o.width, .height = o.height, .overview_inset = o.overview_inset,
                                      .overlay = o.overlay, .high_quality = o.high_quality, .camera = o.camera,
                                      .backend = backend});
  renderer.set_reference_path(rec.reference());
  VideoEncoder encoder(out_file, EncoderOptions{.width = o.width, .height = o.height, .fps = o.fps});
  return render_frames(rec, renderer, encoder, o, stop);
}

}  // namespace

std::string video_file_problem(const std::string& out_file) {
  std::error_code ec;
  if (!fs::exists(out_file, ec)) return "";
  if (!fs::is_regular_file(out_file, ec)) return out_file + " exists and is not a regular file";
  // An ISO base-media file (MP4) has a box type at bytes 4…7 ("ftyp" first for ours).
  char head[8] = {};
  std::ifstream f(out_file, std::ios::binary);
  f.read(head, sizeof head);
  if (f.gcount() == sizeof head && std::memcmp(head + 4, "ftyp", 4) == 0) return "";
  return out_file + " exists and is not an MP4 video: not replacing it (give another file)";
}

VideoResult render_run(const std::string& run_dir, const std::string& out_file, const VideoOptions& o,
                       const std::atomic<bool>* stop) {
  validate(o);
  const GlBackend backend = backend_of(o);
  const auto start = std::chrono::steady_clock::now();
  if (const std::string why = video_file_problem(out_file); !why.empty()) throw std::invalid_argument(why);
  // An older video must not pass for this run's, whatever fails below.
  std::error_code ec;
  const bool removed_old = !fs::is_directory(out_file, ec) && fs::remove(out_file, ec);
  VideoResult res;
  try {
    res = render_or_throw(run_dir, out_file, o, backend, stop);
  } catch (const BadRunRecord& e) {
    if (!removed_old) throw;
    throw BadRunRecord(fmt::format("{}; the older {} was removed", e.what(), out_file));
  } catch (const std::runtime_error& e) {
    if (!removed_old) throw;
    throw std::runtime_error(fmt::format("{}; the older {} was removed", e.what(), out_file));
  }
  res.render_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  spdlog::debug("video {}: {} frames, {:.2f} s, rendered in {:.2f} s", out_file, res.frames, res.duration_s, res.render_s);
  return res;
}

}  // namespace omnitwin::media
