// bench_app: the viewer's live path. Repaint of a 1024x680 frame through a
// map (LiveRepainter vs the straightforward per-pixel repaint), and the live
// view's rate and the GUI's longest stall while a transfer computes.
#include <algorithm>
#include <chrono>
#include <ctime>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <string>
#include <vector>

#include <QApplication>
#include <QComboBox>
#include <QDoubleSpinBox>
#include <QCheckBox>
#include <QFile>
#include <QProcess>
#include <QPushButton>
#include <QTcpServer>
#include <QTemporaryDir>
#include <QTest>
#include <QTimer>

#include <opencv2/imgproc.hpp>

#include "main_window.hpp"
#include "rig_link.hpp"
#include "scratch_home.hpp"
#include "wait_for.hpp"
#include <QTemporaryDir>
#include "veneer/io/image_io.hpp"
#include "veneer/pipeline/transfer.hpp"
#include "veneer/repaint/live.hpp"
#include "veneer/sim/simulator.hpp"

namespace {

double now_ms() {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

// CPU time of the calling thread: a stall with little of it was the thread
// waiting (for a core, a lock), not working.
double cpu_ms() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return ts.tv_sec * 1e3 + ts.tv_nsec / 1e6;
}

// Time the calling thread spent runnable but waiting for a core (ms), from
// /proc/thread-self/schedstat; -1 when the kernel does not say.
double runqueue_ms() {
  FILE* f = std::fopen("/proc/thread-self/schedstat", "r");
  if (!f) return -1;
  unsigned long long run = 0, wait = 0;
  const int n = std::fscanf(f, "%llu %llu", &run, &wait);
  std::fclose(f);
  return n == 2 ? wait / 1e6 : -1;
}

template <class F>
double median_ms(F f, int runs) {
  std::vector<double> t;
  for (int i = 0; i < runs; ++i) {
    const double a = now_ms();
    f();
    t.push_back(now_ms() - a);
  }
  std::sort(t.begin(), t.end());
  return t[t.size() / 2];
}


// With VENEER_BENCH_TRACE set, every GUI event handled in over 30 ms while a
// stall is measured is printed to stderr (what was measured, receiver class,
// name, event type, ms): what a stall was.
const char* g_measuring = nullptr;

class TracingApp : public QApplication {
 public:
  using QApplication::QApplication;
  bool notify(QObject* receiver, QEvent* event) override {
    if (!trace_ || !g_measuring) return QApplication::notify(receiver, event);
    const double t = now_ms(), cpu = cpu_ms(), queued = runqueue_ms();
    const int type = event->type();
    const bool r = QApplication::notify(receiver, event);
    const double ms = now_ms() - t;
    if (ms > 30)
      std::fprintf(stderr,
                   "stall trace (%s): %.1f ms (%.1f ms of GUI-thread CPU, %.1f ms waiting for a core) in %s '%s' "
                   "event %d\n",
                   g_measuring, ms, cpu_ms() - cpu, runqueue_ms() - queued, receiver->metaObject()->className(),
                   receiver->objectName().toStdString().c_str(), type);
    return r;
  }

 private:
  bool trace_ = !qEnvironmentVariableIsEmpty("VENEER_BENCH_TRACE");
};

}  // namespace

int main(int argc, char** argv) {
  if (qEnvironmentVariableIsEmpty("QT_QPA_PLATFORM")) qputenv("QT_QPA_PLATFORM", "offscreen");
  QTemporaryDir xdg;
  veneer::test::use_scratch_xdg_folders(xdg);
  TracingApp app(argc, argv);
  QTemporaryDir known;  // the simulated rigs are pinned here, their first use answered yes
  qputenv("VENEER_KNOWN_RIGS", (known.path() + "/known_rigs").toUtf8());
  veneer::app::RigLink::setDefaultPinAsker([](const QString&, const QString&) { return true; });
  const cv::Size size(1024, 680);
  // VENEER_BENCH_APP_ONLY=live-first: section 4 alone (iterating on it)
  const bool live_first_only = qEnvironmentVariable("VENEER_BENCH_APP_ONLY") == "live-first";
  QTemporaryDir dir;
  // Heartbeat: the longest gap between 10 ms timer ticks is the GUI's worst stall.
  double last = now_ms(), worst = 0;
  QTimer beat;
  QObject::connect(&beat, &QTimer::timeout, [&] {
    const double t = now_ms();
    worst = std::max(worst, t - last);
    last = t;
  });
  if (!live_first_only) {
  // 1. Repaint through a map: a real map (destination bull, source orange, truth normals).
  veneer::sim::RenderOptions ro;
  ro.size = size;
  auto dst = veneer::sim::simulate_set("bull", ro, veneer::io::Role::destination);
  auto src = veneer::sim::simulate_set("orange", ro, veneer::io::Role::source);
  if (!dst || !src) {
    std::fprintf(stderr, "bench_app: simulation failed\n");
    return 1;
  }
  veneer::pipeline::TransferOptions to;
  to.truth_normals = true;
  to.match.method = veneer::match::Method::coherent;
  auto tr = veneer::pipeline::transfer(*dst, *src, to);
  if (!tr) {
    std::fprintf(stderr, "bench_app: transfer failed: %s\n", tr.message().c_str());
    return 1;
  }
  cv::Mat frame8 = veneer::io::tonemap_picture(src->images[0]);
  cv::Mat backdrop8 = veneer::io::tonemap_picture(dst->images[0]);
  veneer::repaint::LiveRepainter live(tr->map, tr->source_size, backdrop8);
  live.apply(frame8);  // tables built once
  const double fast = median_ms([&] { cv::Mat out = live.apply(frame8); }, 200);
  // the same with the transfer's blend (2 px, guided by normals: the pictures' default)
  veneer::repaint::LiveRepainter live_blended(tr->map, tr->source_size, backdrop8, tr->blend);
  const double blended = median_ms([&] { cv::Mat out = live_blended.apply(frame8); }, 100);
  cv::Mat frame_f = src->images[0];
  const double peer = median_ms([&] { cv::Mat out = veneer::repaint::repaint(tr->map, frame_f, dst->images[0]); }, 30);
  int mapped = 0;
  for (int y = 0; y < tr->map.xy.rows; ++y)
    for (int x = 0; x < tr->map.xy.cols; ++x) mapped += tr->map.xy.at<cv::Vec2f>(y, x)[0] >= 0;
  std::printf("## Repaint of one 1024x680 frame through the map (%d mapped pixels)\n\n", mapped);
  std::printf("| path | median ms | target |\n|---|---|---|\n");
  std::printf("| LiveRepainter (gather tables, cv::remap) | %.3f | < 2 ms |\n", fast);
  std::printf("| LiveRepainter, seams blended (%s) | %.3f | |\n",
              tr->blend ? "2 px, guided, weights made once per map" : "no blend plan: nearest", blended);
  std::printf("| per-pixel repaint() loop, float (peer) | %.3f | |\n", peer);
  std::printf("| ratio | %.1fx | |\n\n", peer / fast);

  // 2. Live view while a transfer computes, against a real simulated rig.
  QTcpServer probe;
  probe.listen(QHostAddress::LocalHost, 0);
  const int port = probe.serverPort();
  probe.close();
  QProcess rig;
  rig.setProcessChannelMode(QProcess::ForwardedErrorChannel);
  const QString store = dir.path() + "/store";
  rig.start(VENEER_BIN_DIR "/veneerd", {"--simulate", "--scenes", "bull,orange", "--size", "1024x680", "--listen",
                                        QString("127.0.0.1:%1").arg(port), "--store", store});
  if (!rig.waitForStarted(5000) || !wait_for([&] { return QFile::exists(store + "/token"); }, 20000)) {
    std::fprintf(stderr, "bench_app: veneerd did not start\n");
    return 1;
  }
  QString dpath = dir.path() + "/bull", spath = dir.path() + "/orange";
  (void)veneer::io::write_set(*dst, dpath.toStdString());
  (void)veneer::io::write_set(*src, spath.toStdString());
  veneer::app::MainWindow w({QString("127.0.0.1:%1").arg(port), store + "/token", dpath, spath, dir.path()});
  w.show();
  if (!wait_for([&] { return w.rig().isConnected(); }, 10000)) {
    std::fprintf(stderr, "bench_app: cannot connect: %s\n", w.status().lastMessage().toStdString().c_str());
    return 1;
  }
  // A first transfer so the live view has a map to repaint through.
  w.transfer().startTransfer();
  wait_for([&] { return !w.transfer().computing(); }, 120000);
  w.showTab("Live");
  w.findChild<QPushButton*>("liveToggle")->setChecked(true);
  wait_for([&] { return w.live().framesShown() > 5; }, 10000);

  // The stream's own rate with nothing computing, as the peer of the rate below.
  const int idle_before = w.live().framesShown();
  const double idle_t0 = now_ms();
  QTest::qWait(3000);
  const double idle_fps = (w.live().framesShown() - idle_before) * 1000.0 / (now_ms() - idle_t0);

  // A slow computation: the faithful exhaustive search with 3x3 patches.
  w.findChild<QComboBox*>("method")->setCurrentText("linear");
  w.findChild<QComboBox*>("patch")->setCurrentText("3");
  w.findChild<QCheckBox*>("fast")->setChecked(false);
  const int frames_before = w.live().framesShown();
  const double t0 = now_ms();
  w.transfer().startTransfer();
  last = now_ms();
  beat.start(10);
  g_measuring = "live while computing";
  double window_ms = 0;
  int frames = 0;
  wait_for([&] { return !w.transfer().computing() || now_ms() - t0 > 8000; }, 60000);
  window_ms = now_ms() - t0;
  frames = w.live().framesShown() - frames_before;
  const bool still_computing = w.transfer().computing();
  beat.stop();
  g_measuring = nullptr;
  w.transfer().cancelTransfer();
  wait_for([&] { return !w.transfer().computing(); }, 60000);
  std::printf("## Live view while a transfer computes (rig asked for 15 fps, 1024x680 frames; the simulated\n"
              "## rig renders its frames on the same 2 cores as the transfer, a real rig does not)\n\n");
  std::printf("| measure | value | target |\n|---|---|---|\n");
  std::printf("| computing during the window | %s | yes |\n", still_computing ? "yes (cancelled after)" : "finished early");
  std::printf("| frames shown | %d in %.1f s | |\n", frames, window_ms / 1000.0);
  std::printf("| live view rate, nothing computing (same run) | %.1f fps | |\n", idle_fps);
  std::printf("| live view rate while computing | %.1f fps | >= 15 fps |\n", frames * 1000.0 / window_ms);
  std::printf("| while computing / nothing computing | %.2f | |\n", frames * 1000.0 / window_ms / std::max(1e-9, idle_fps));
  std::printf("| longest GUI stall (10 ms heartbeat) | %.1f ms | < 100 ms |\n", worst);

  // 3. The longest GUI-thread stall during an export and a 10 Mpx set load
  //    (issue 28: "loading a 10 Mpx set blocks the window about 5 s; export
  //    blocks 2-3 s"). Same heartbeat; the peer is the old synchronous path,
  //    measured in the same run.
  w.capture().setAutoFlow(false);  // the big set alone: no transfer starts by itself
  auto stall_during = [&](const char* what, auto start, auto done) {
    last = now_ms();
    worst = 0;
    beat.start(10);
    g_measuring = what;
    const double t = now_ms();
    start();
    wait_for(done, 300000);
    const double total = now_ms() - t;
    beat.stop();
    g_measuring = nullptr;
    return std::make_pair(worst, total);
  };
  const auto results_export =
      stall_during("export results", [&] { w.exports().exportResultsTo(dir.path() + "/export"); },
                   [&] { return !w.exports().exporting(); });
  const auto video_export =
      stall_during("export video", [&] { w.exports().exportRelightVideoTo(dir.path() + "/relight.avi"); },
                   [&] { return !w.exports().exporting(); });
  const cv::Size big(3872, 2592);  // 10.0 Mpx
  veneer::io::ImageSet large = *dst;
  for (auto& im : large.images) cv::resize(im, im, big, 0, 0, cv::INTER_LINEAR);
  if (!large.ambient.empty()) cv::resize(large.ambient, large.ambient, big, 0, 0, cv::INTER_LINEAR);
  if (!large.mask.empty()) cv::resize(large.mask, large.mask, big, 0, 0, cv::INTER_NEAREST);
  large.truth = {};
  large.size = big;
  const QString lpath = dir.path() + "/large";
  if (auto ws = veneer::io::write_set(large, lpath.toStdString()); !ws) {
    std::fprintf(stderr, "bench_app: cannot write the 10 Mpx set: %s\n", ws.message().c_str());
    return 1;
  }
  large = {};
  const auto load =
      stall_during("load 10 Mpx", [&] { w.flow().loadSetInBackground(lpath, veneer::io::Role::destination); },
                   [&] { return w.session().loads_running == 0; });
  const double sync_t = now_ms();
  w.flow().loadLocalSet(lpath, veneer::io::Role::destination);  // the old way: all on the GUI thread
  const double sync_load = now_ms() - sync_t;
  std::printf("\n## Longest GUI-thread stall (10 ms heartbeat) while the window works off the GUI thread\n\n");
  std::printf("| job | longest stall ms | job took s | target |\n|---|---|---|---|\n");
  std::printf("| export result pictures (1024x680 transfer) | %.1f | %.2f | < 100 ms |\n", results_export.first,
              results_export.second / 1000);
  std::printf("| export relight sweep video (100 frames 1024x680) | %.1f | %.2f | < 100 ms |\n", video_export.first,
              video_export.second / 1000);
  std::printf("| load a 10 Mpx set (%dx%d, %zu photos) | %.1f | %.2f | < 100 ms |\n", big.width, big.height,
              dst->images.size(), load.first, load.second / 1000);
  std::printf("| peer: the same load on the GUI thread (loadLocalSet) | %.1f | %.2f | |\n", sync_load,
              sync_load / 1000);
  rig.kill();
  rig.waitForFinished(3000);
  }  // sections 1-3

  // 4. Live first (issue 34): from the second set stored on a simulated rig at
  //    5600x3750 (VENEER_BENCH_APP_FULL=WxH to change, =0 to skip) to the first
  //    live repainted frame, the automatic flow doing everything; then the
  //    full-resolution map made behind it and swapped in, with the GUI's
  //    longest stall meanwhile and the live frames' rate. The flow pulls the
  //    rig's preview set first (no truth/ since issue 48) and reads it at the
  //    live width when it is as wide, so only the preview's pull is part of the time.
  cv::Size full(5600, 3750);
  if (const char* env = std::getenv("VENEER_BENCH_APP_FULL")) {
    int fw = 0, fh = 0;
    if (std::sscanf(env, "%dx%d", &fw, &fh) == 2 && fw > 0 && fh > 0) full = {fw, fh};
    else full = {};
  }
  if (full.area() == 0) return 0;
  QProcess big_rig;
  big_rig.setProcessChannelMode(QProcess::ForwardedErrorChannel);
  const QString big_store = dir.path() + "/store-full";
  QTcpServer probe2;
  probe2.listen(QHostAddress::LocalHost, 0);
  const int port2 = probe2.serverPort();
  probe2.close();
  big_rig.start(VENEER_BIN_DIR "/veneerd",
                {"--simulate", "--scenes", "bull,orange", "--size", QString("%1x%2").arg(full.width).arg(full.height),
                 "--listen", QString("127.0.0.1:%1").arg(port2), "--store", big_store});
  if (!big_rig.waitForStarted(5000) || !wait_for([&] { return QFile::exists(big_store + "/token"); }, 20000)) {
    std::fprintf(stderr, "bench_app: the %dx%d veneerd did not start\n", full.width, full.height);
    return 1;
  }
  QTemporaryDir work;
  veneer::app::MainWindow lw({QString("127.0.0.1:%1").arg(port2), big_store + "/token", QString(), QString(), work.path()});
  lw.show();
  if (!wait_for([&] { return lw.rig().isConnected(); }, 10000)) {
    std::fprintf(stderr, "bench_app: cannot connect to the %dx%d rig\n", full.width, full.height);
    return 1;
  }
  int stored = 0;
  double second_stored = -1;
  QObject::connect(&lw.rig(), &veneer::app::RigLink::rigEvent, [&](const veneer::rig::Event& e) {
    if (e.kind == veneer::rig::Event::Kind::set_stored && ++stored == 2) second_stored = now_ms();
  });
  lw.findChild<QPushButton*>("captureSource")->click();
  if (!wait_for([&] { return stored >= 1; }, 1800000)) {
    std::fprintf(stderr, "bench_app: the source was not stored: %s\n", lw.status().lastMessage().toStdString().c_str());
    return 1;
  }
  lw.showTab("Live");
  lw.findChild<QPushButton*>("liveCaptureDestination")->click();
  if (!wait_for([&] { return stored >= 2; }, 1800000)) {
    std::fprintf(stderr, "bench_app: the destination was not stored\n");
    return 1;
  }
  double both_loaded = -1, map_ready = -1, first_frame = -1;
  // With VENEER_BENCH_TRACE set: every change of the flow's state, with its time since the second set was stored.
  const bool trace = !qEnvironmentVariableIsEmpty("VENEER_BENCH_TRACE");
  std::string traced;
  auto trace_state = [&] {
    if (!trace) return;
    const auto& s = lw.session();
    char line[512];
    std::snprintf(line, sizeof line,
                  "dst %s src %s result %s computing %d live_session %s refusal '%s' frames %d repainted %dx%d "
                  "full running %d swaps %d | %s",
                  s.dst ? (s.dst->live_size ? "live" : "full") : "-", s.src ? (s.src->live_size ? "live" : "full") : "-",
                  s.result ? "yes" : "no", lw.transfer().computing(), s.live_session ? (s.live_session->ready() ? "ready" : "not ready") : "none",
                  s.live_refusal.toStdString().c_str(), lw.live().framesShown() > 0 ? 1 : 0,
                  lw.live().lastRepaintedFrame().cols, lw.live().lastRepaintedFrame().rows, lw.liveFirst().running(),
                  lw.liveFirst().swaps(), lw.status().lastMessage().toStdString().c_str());
    if (line != traced) {
      traced = line;
      std::fprintf(stderr, "trace %.2f s: %s\n", (now_ms() - second_stored) / 1000, line);
    }
  };
  wait_for(
      [&] {
        trace_state();
        const double t = now_ms();
        if (both_loaded < 0 && lw.session().dst && lw.session().src) both_loaded = t;
        if (map_ready < 0 && lw.session().result && !lw.transfer().computing()) map_ready = t;
        if (map_ready > 0 && lw.live().framesShown() > 0 && !lw.live().lastRepaintedFrame().empty()) first_frame = t;
        return first_frame > 0;
      },
      600000);
  const cv::Size live_map = lw.session().result ? lw.session().result->map.xy.size() : cv::Size();
  last = now_ms();
  worst = 0;
  beat.start(10);
  g_measuring = "full resolution behind live";
  const double full_t0 = now_ms();
  const int frames_t0 = lw.live().framesShown();
  wait_for(
      [&] {
        trace_state();
        return lw.liveFirst().swaps() > 0 || (!lw.liveFirst().running() && now_ms() - full_t0 > 2000);
      },
      1800000);
  const double full_s = (now_ms() - full_t0) / 1000;
  const double live_fps_meanwhile = (lw.live().framesShown() - frames_t0) / std::max(1e-3, full_s);
  beat.stop();
  g_measuring = nullptr;
  const cv::Size full_map = lw.session().result ? lw.session().result->map.xy.size() : cv::Size();
  auto since = [&](double t) { return t > 0 ? (t - second_stored) / 1000 : -1.0; };
  std::printf("\n## Live first on a %dx%d simulated rig (%s)\n\n",
              full.width, full.height,
              qEnvironmentVariableIsEmpty("VENEER_PREVIEW_FIRST") ? "whole sets pulled"
                                                                   : "VENEER_PREVIEW_FIRST: the preview set pulled first");
  std::printf("| from the second set stored to | s | target |\n|---|---|---|\n");
  std::printf("| both sets pulled and read at the live width | %.2f | |\n", since(both_loaded));
  std::printf("| live-size map ready (%dx%d) | %.2f | |\n", live_map.width, live_map.height, since(map_ready));
  std::printf("| first live repainted frame | %.2f | <= 3 s |\n", since(first_frame));
  std::printf("| full-resolution map swapped in (%dx%d), after the first frame | %.2f (%s) | |\n", full_map.width,
              full_map.height, full_s, lw.liveFirst().swaps() > 0 ? "swapped" : "not swapped");
  std::printf("| longest GUI stall meanwhile (10 ms heartbeat) | %.1f ms | < 100 ms |\n", worst);
  std::printf("| live frames shown meanwhile (the Live tab asks %.0f fps) | %.1f fps | |\n",
              lw.findChild<QDoubleSpinBox*>("liveFps")->value(), live_fps_meanwhile);
  lw.findChild<QPushButton*>("liveToggle")->setChecked(false);
  big_rig.kill();
  big_rig.waitForFinished(3000);
  return 0;
}
