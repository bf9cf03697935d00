// Benchmarks the media layer's off-screen video (DESIGN §8: rendering happens after the run
// or beside it, so its speed sets how long `omnitwin render` takes, not how fast lockstep
// steps). Figures are frames per wall second (items/s), with a baseline in the same run:
//
//   BM_RenderBare   the generated platform model, track camera only: mjv_updateScene +
//                   mjr_render + mjr_readPixels (+ row flip). What MuJoCo alone costs.
//   BM_RenderFrame  a full video frame: track camera, overview inset, reference path and
//                   trace, overlay text, read back. Ratio to BM_RenderBare = our additions.
//   BM_RenderFrameHighQuality  the same with shadows and 4x multisampling (high_quality).
//   BM_Encode       H.264 encoding (RGB→yuv420p, libx264 veryfast, crf 23, MP4 in a temp
//                   dir) of rendered frames cycling through 8 poses.
// Each at 640x480 and 1280x720. The GL backend is OMNITWIN_GL's (media/offscreen_gl.hpp),
// OSMesa by default; one process renders with one backend, so the EGL rows are a second run:
//   bench_render                  OSMesa (llvmpipe)
//   OMNITWIN_GL=egl bench_render  EGL: a GPU if there is one, else Mesa surfaceless (llvmpipe)
// The label of each row names the GL implementation used.
#include <benchmark/benchmark.h>
#include <mujoco/mujoco.h>

#include <cmath>
#include <fstream>
#include <stdexcept>
#include <vector>

#include "media/scene_render.hpp"
#include "media/video_encoder.hpp"
#include "physics/platform_mjcf.hpp"
#include "tests/support/temp_dir.hpp"

namespace {

using namespace omnitwin;

physics::ModelPtr platform_model() {
  omnitwin::testing::TempDir dir("omnitwin-bench-render");
  const auto path = (dir / "platform.xml").string();
  std::ofstream(path) << physics::platform_mjcf(physics::PlatformParams{});
  char err[1024] = "";
  physics::ModelPtr m(mj_loadXML(path.c_str(), nullptr, err, sizeof err));
  if (!m) throw std::runtime_error(err);
  return m;
}

// A 2 m line as reference and a slightly wavy trace along it.
struct Paths {
  std::vector<media::PathPoint> reference, trace;
  Paths() {
    for (int i = 0; i <= 200; ++i) {
      reference.push_back({i * 0.01, 0});
      trace.push_back({i * 0.01, 0.01 * std::sin(i * 0.1)});
    }
  }
};

// State k of a platform driving along x and turning slowly.
media::FrameState state(int k, const Paths& p) {
  media::FrameState s;
  s.t = k / 30.0;
  s.x = 0.01 * (k % 200);
  s.y = p.trace[k % 200].y;
  s.phi = 0.01 * k;
  s.wheel_angle = {0.1 * k, -0.1 * k, 0.1 * k, -0.1 * k};
  s.speed = 0.3;
  s.bus = "tx 12000  rx 11990  drop 3  err 0  load 35%";
  s.slaves = "run run run run";
  s.trace = std::span(p.trace).first(k % 200 + 1);
  return s;
}

void render_loop(benchmark::State& st, bool full, bool high_quality = false) {
  const int w = static_cast<int>(st.range(0)), h = static_cast<int>(st.range(1));
  media::SceneOptions o{.width = w, .height = h, .overview_inset = full, .overlay = full, .high_quality = high_quality,
                        .backend = media::gl_backend_from_env()};
  media::SceneRenderer r(platform_model(), o);
  Paths paths;
  if (full) r.set_reference_path(paths.reference);
  int k = 0;
  for (auto _ : st) {
    media::FrameState s = state(k++, paths);
    if (!full) s.trace = {};
    benchmark::DoNotOptimize(r.render(s).data());
  }
  st.SetItemsProcessed(st.iterations());
  st.SetLabel(r.gl_description());
}

void BM_RenderBare(benchmark::State& st) { render_loop(st, false); }
void BM_RenderFrame(benchmark::State& st) { render_loop(st, true); }
void BM_RenderFrameHighQuality(benchmark::State& st) { render_loop(st, true, true); }

void BM_Encode(benchmark::State& st) {
  const int w = static_cast<int>(st.range(0)), h = static_cast<int>(st.range(1));
  std::vector<std::vector<unsigned char>> frames;
  {
    media::SceneRenderer r(platform_model(),
                           media::SceneOptions{.width = w, .height = h, .backend = media::gl_backend_from_env()});
    Paths paths;
    for (int k = 0; k < 8; ++k) frames.push_back(r.render(state(20 * k, paths)));
  }
  omnitwin::testing::TempDir dir("omnitwin-bench-encode");
  media::VideoEncoder enc((dir / "bench.mp4").string(), media::EncoderOptions{.width = w, .height = h, .fps = 30});
  size_t k = 0;
  for (auto _ : st) enc.add_frame(frames[k++ % frames.size()].data());
  enc.close();  // the flush of buffered frames is part of the cost
  st.SetItemsProcessed(st.iterations());
}

}  // namespace

BENCHMARK(BM_RenderBare)->Args({640, 480})->Args({1280, 720})->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_RenderFrame)->Args({640, 480})->Args({1280, 720})->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_RenderFrameHighQuality)->Args({640, 480})->Args({1280, 720})->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_Encode)->Args({640, 480})->Args({1280, 720})->Unit(benchmark::kMillisecond)->UseRealTime();

BENCHMARK_MAIN();
