// bench_rig: the simulated rig end to end (in this process, over TCP and the
// libcurl Hue path against the emulator with Hue's rate limits and latency).
//  1. a full 8-shot set at 1024x680: time per shot beyond exposure + settle
//     (and beyond the simulator's own render time), requests refused for rate;
//  2. live view of 1024x680 frames while another client downloads sets,
//     against live view alone;
//  3. the real veneerd binary's resident memory (its own process) over 100
//     fetches of a 1024x680 set with the largest chunk size, several at once,
//     and over live view at 60 fps: it must come back down, not grow in steps.
//     VENEER_BENCH_LIVE_S sets the live-view time (default 30 s; 600 for the
//     issue's 10 minutes), VENEER_BENCH_FETCHES the number of fetches (100),
//     VENEER_BENCH_ROUNDS how often both are repeated (2),
//     VENEER_BENCH_PREVIEW_SIZE the live-view size (default the still size). `bench_rig --memory`
//     runs this section alone.
//  4. the real veneerd binary's peak resident memory over a pair of captures
//     (destination, source) at the camera's full resolution (5600x3750), next
//     to the frames' own bytes.
//     `bench_rig --capture-peak` runs this section alone. Then the first
//     set's bytes by kind (the camera twin's JPEG + lossless DNG per frame)
//     and the time to pull it on loopback: live first (the preview set in
//     place, then the whole) against a plain pull.
//  5. TLS 1.3 against plain TCP (issue 43), the real veneerd binary twice on
//     copies of one store (one serving TLS, one --plain-tcp), in the same run:
//     pull throughput of a 1024x680 set on loopback (median of alternating
//     rounds) and the daemon's CPU per pulled MB; live-view frames per second
//     at 30 fps asked. `bench_rig --tls` runs this section alone.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <mutex>
#include <thread>
#include <vector>

#include "rig_test_util.hpp"
#include "veneer/rig/client.hpp"
#include "veneer/sim/simulator.hpp"
#include "veneer/util/log.hpp"
#include "veneerd/daemon.hpp"
#include "veneerd/sim/simulated_rig.hpp"

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
using Kind = veneer::rig::Event::Kind;

static double secs(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

static double env_number(const char* name, double fallback) {
  const char* v = std::getenv(name);
  if (!v || !*v) return fallback;
  char* end = nullptr;
  double x = std::strtod(v, &end);
  return end && *end == 0 && x > 0 ? x : fallback;
}

// One FetchImages over a raw connection with `chunk` bytes per chunk; the bytes
// received, or 0 on failure.
static uint64_t raw_fetch(rigtest::RawConnection& c, uint64_t id, const std::string& set_id, uint32_t chunk) {
  veneer::v1::ClientMessage m;
  m.set_id(id);
  m.mutable_fetch_images()->set_set_id(set_id);
  m.mutable_fetch_images()->set_include_truth(true);
  m.mutable_fetch_images()->set_chunk_size(chunk);
  if (!c.send(m)) return 0;
  uint64_t bytes = 0;
  for (;;) {
    auto msg = c.next(30);
    if (!msg) return 0;
    if (msg->has_response() && msg->response().id() == id && !msg->response().ok()) return 0;
    if (!msg->has_chunk() || msg->chunk().request_id() != id) continue;
    bytes += msg->chunk().data().size();
    if (msg->chunk().end_of_set()) return bytes;
  }
}

// Section 3: the daemon's resident memory, in its own process.
static int bench_daemon_memory(const fs::path& dir) {
  const double live_s = env_number("VENEER_BENCH_LIVE_S", 30);
  const int fetches = static_cast<int>(env_number("VENEER_BENCH_FETCHES", 100));
  const int rounds = static_cast<int>(env_number("VENEER_BENCH_ROUNDS", 2));
  const int parallel = 4;
  const uint32_t chunk = 4u << 20;  // the largest the rig allows
  fs::path store = dir / "mem-store";
  std::vector<std::string> args = {"--size", "1024x680", "--log", "warn"};
  if (const char* preview = std::getenv("VENEER_BENCH_PREVIEW_SIZE")) args.insert(args.end(), {"--preview-size", preview});
  auto d = rigtest::DaemonProcess::start(store, args);
  if (!d || d->port() == 0) {
    std::fprintf(stderr, "bench_rig: veneerd did not start: %s\n", d ? d->log().c_str() : "");
    return 1;
  }
  auto token = veneer::rig::read_token_file(store / "token");
  if (!token) return 1;
  auto client = veneer::rig::Client::connect({"127.0.0.1", d->port()}, *token);
  if (!client) {
    std::fprintf(stderr, "bench_rig: %s\n", client.message().c_str());
    return 1;
  }
  auto& c = **client;
  auto id = c.capture();
  if (!id) return 1;
  auto done = c.wait_event([&](const veneer::rig::Event& e) {
    return e.set_id == *id && (e.kind == Kind::set_stored || e.kind == Kind::capture_failed);
  }, 120);
  if (!done || done->kind != Kind::set_stored) {
    std::fprintf(stderr, "bench_rig: capture failed\n");
    return 1;
  }
  auto settle = [] { std::this_thread::sleep_for(std::chrono::seconds(2)); };
  settle();
  struct Row {
    std::string moment;
    double rss;
    double anon = -1;  // of which anonymous (heap, stacks): what a leak would grow
  };
  std::vector<Row> rows;
  rows.push_back({"after one capture, idle", d->rss_mib(), d->rss_mib("RssAnon")});

  // The project's own client: pulls one at a time with the default chunk size.
  for (int i = 0; i < 15; ++i) {
    fs::path out = dir / ("mem-pull-" + std::to_string(i));
    (void)c.pull(*id, out, true);
    fs::remove_all(out);
  }
  settle();
  rows.push_back({"after 15 pulls with the rig client (256 KiB chunks, one at a time)", d->rss_mib(),
                  d->rss_mib("RssAnon")});

  double set_mib = 0, fetch_mib_s = 0, live_fps = 0;
  for (int round = 1; round <= rounds; ++round) {
    const std::string tag = rounds > 1 ? "round " + std::to_string(round) + ": " : "";
    // A third-party client: the largest chunks, `parallel` fetches at once.
    std::atomic<int> next{0}, failed{0};
    std::atomic<uint64_t> bytes{0};
    std::atomic<bool> fetching{true};
    double peak = 0;
    std::thread sampler([&] {
      while (fetching) {
        peak = std::max(peak, d->rss_mib());
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
      }
    });
    auto t0 = Clock::now();
    std::vector<std::thread> workers;
    for (int w = 0; w < parallel; ++w) {
      workers.emplace_back([&] {
        rigtest::RawConnection raw(d->port());
        if (!raw.hello(*token)) {
          ++failed;
          return;
        }
        for (int n; (n = next++) < fetches;) {
          uint64_t got = raw_fetch(raw, 100 + static_cast<uint64_t>(n), *id, chunk);
          if (got == 0) ++failed;
          bytes += got;
        }
      });
    }
    for (auto& w : workers) w.join();
    fetch_mib_s = bytes.load() / 1048576.0 / secs(Clock::now() - t0);
    fetching = false;
    sampler.join();
    if (failed > 0) std::fprintf(stderr, "bench_rig: %d fetches failed\n", failed.load());
    set_mib = bytes.load() / 1048576.0 / std::max(1, fetches - failed.load());
    rows.push_back({tag + "peak during " + std::to_string(fetches) + " fetches, " + std::to_string(parallel) +
                        " at once, 4 MiB chunks",
                    peak});
    settle();
    rows.push_back({"**" + tag + "2 s after those fetches**", d->rss_mib(), d->rss_mib("RssAnon")});

    // Live view at 60 fps to two clients, then stopped.
    std::atomic<int> frames{0};
    std::vector<std::unique_ptr<veneer::rig::Client>> watchers;
    for (int i = 0; i < 2; ++i) {
      auto w = veneer::rig::Client::connect({"127.0.0.1", d->port()}, *token);
      if (!w) return 1;
      (*w)->on_live_frame = [&](const veneer::rig::LiveFrame&) { ++frames; };
      (void)(*w)->start_live_view(60);
      watchers.push_back(std::move(*w));
    }
    const double early_s = std::min(5.0, live_s / 2);
    double early = 0, highest = 0, last = 0;
    auto live_start = Clock::now();
    while (secs(Clock::now() - live_start) < live_s) {
      std::this_thread::sleep_for(std::chrono::milliseconds(500));
      double r = d->rss_mib();
      if (early == 0 && secs(Clock::now() - live_start) >= early_s) early = r;
      highest = std::max(highest, r);
      last = r;
    }
    live_fps = frames.load() / 2.0 / secs(Clock::now() - live_start);
    for (auto& w : watchers) (void)w->stop_live_view();
    watchers.clear();
    char buf[64];
    std::snprintf(buf, sizeof buf, "%.0f s", early_s);
    rows.push_back({tag + "live view, 2 clients at 60 fps: after " + std::string(buf), early});
    std::snprintf(buf, sizeof buf, "%.0f s", live_s);
    rows.push_back({tag + "live view: highest / at the end of " + std::string(buf), highest});
    rows.back().moment += " (end: " + std::to_string(static_cast<int>(last + 0.5)) + ")";
    settle();
    rows.push_back({"**" + tag + "2 s after live view stopped**", d->rss_mib(), d->rss_mib("RssAnon")});
  }

  std::printf("\n### veneerd's resident memory (the real binary in its own process; 1024x680 set of %.1f MiB, "
              "fetches at %.0f MiB/s, live view %.1f fps per client)\n\n",
              set_mib, fetch_mib_s, live_fps);
  std::printf("| moment | RSS (MiB) | of which anonymous (MiB) |\n|---|---|---|\n");
  for (const auto& r : rows) {
    if (r.anon >= 0) {
      std::printf("| %s | %.0f | %.0f |\n", r.moment.c_str(), r.rss, r.anon);
    } else {
      std::printf("| %s | %.0f | |\n", r.moment.c_str(), r.rss);
    }
  }
  client->reset();
  d->stop(SIGTERM);
  return 0;
}


// Section 4: the daemon's peak resident memory (VmHWM) over one capture at the
// camera's full resolution (issue 29: a 4 GiB board). Its peer in the same
// run: the set's frames as the camera delivers them (16-bit) and as floats,
// what a daemon holding all of them would need on top of its idle size.
// VENEER_BENCH_FULL_SIZE sets the size (default 5600x3750).
static int bench_capture_peak(const fs::path& dir) {
  const char* env = std::getenv("VENEER_BENCH_FULL_SIZE");
  const std::string size = env && *env ? env : "5600x3750";
  int w = 0, h = 0;
  if (std::sscanf(size.c_str(), "%dx%d", &w, &h) != 2 || w <= 0 || h <= 0) {
    std::fprintf(stderr, "bench_rig: VENEER_BENCH_FULL_SIZE '%s': expected WxH\n", size.c_str());
    return 1;
  }
  fs::path store = dir / "peak-store";
  auto d = rigtest::DaemonProcess::start(store, {"--size", size, "--preview-size", "320x213", "--log", "warn"});
  if (!d || d->port() == 0) {
    std::fprintf(stderr, "bench_rig: veneerd did not start: %s\n", d ? d->log().c_str() : "");
    return 1;
  }
  auto token = veneer::rig::read_token_file(store / "token");
  if (!token) return 1;
  auto client = veneer::rig::Client::connect({"127.0.0.1", d->port()}, *token);
  if (!client) {
    std::fprintf(stderr, "bench_rig: %s\n", client.message().c_str());
    return 1;
  }
  auto& c = **client;
  const double idle = d->rss_mib("VmHWM");
  // The pair, as `make demo` takes it: a destination, then a source (another scene).
  double peak[2] = {0, 0}, seconds[2] = {0, 0};
  for (int set = 0; set < 2; ++set) {
    const auto t0 = Clock::now();
    veneer::rig::CaptureOptions co;
    auto id = c.capture(co);
    if (!id) return 1;
    std::fprintf(stderr, "bench_rig: capturing set %d of 2 at %s (a minute or more on 2 cores)...\n", set + 1, size.c_str());
    auto done = c.wait_event([&](const veneer::rig::Event& e) {
      if (e.set_id == *id && e.kind == Kind::shot_taken)
        std::fprintf(stderr, "bench_rig:   shot %d of %d (peak so far %.0f MiB)\n", e.k, e.n, d->rss_mib("VmHWM"));
      return e.set_id == *id && (e.kind == Kind::set_stored || e.kind == Kind::capture_failed);
    }, 3600);
    if (!done || done->kind != Kind::set_stored) {
      std::fprintf(stderr, "bench_rig: the %s capture failed: %s\n", size.c_str(), d->log().c_str());
      return 1;
    }
    seconds[set] = secs(Clock::now() - t0);
    peak[set] = d->rss_mib("VmHWM");
  }
  const double frame16 = static_cast<double>(w) * h * 6 / 1048576.0;
  const int frames = 8;
  std::printf("\n### veneerd's peak memory over a %dx%d pair (7 lamps + ambient, truth, DNGs; %.0f s + %.0f s)\n\n", w,
              h, seconds[0], seconds[1]);
  std::printf("| measure | MiB |\n|---|---|\n");
  std::printf("| peak RSS before the capture (idle) | %.0f |\n", idle);
  std::printf("| **peak RSS over the first set (destination; VmHWM)** | **%.0f** |\n", peak[0]);
  std::printf("| **peak RSS over both sets (the source is another scene)** | **%.0f** |\n", peak[1]);
  std::printf("| peer: one set's %d frames as the camera delivers them (16-bit) | %.0f |\n", frames, frames * frame16);
  std::printf("| peer: one set's %d frames as float (what holding them all costs) | %.0f |\n", frames, frames * frame16 * 2);
  std::printf("| budget of the issue (a 4 GiB board) | 4096 |\n");

  // The first set's bytes by kind, and pulling it on loopback: live first
  // (the preview set in place, then the whole) against a plain pull, both
  // without truth/ (the simulator's ground truth, not a camera's files).
  auto sets = c.list_sets();
  if (!sets || sets->empty()) return 1;
  const std::string first = sets->front().id;
  std::map<std::string, uint64_t> bytes;
  for (const auto& e : fs::recursive_directory_iterator(store / first)) {
    if (!e.is_regular_file()) continue;
    const std::string rel = fs::relative(e.path(), store / first).generic_string();
    const std::string kind = rel.rfind("truth/", 0) == 0 ? "truth/ (simulator only)" : e.path().extension().string();
    bytes[kind] += e.file_size();
  }
  std::printf("\n### One stored %s set (%s), bytes by kind\n\n| files | MB |\n|---|---|\n", size.c_str(), first.c_str());
  uint64_t camera = 0;
  for (const auto& [kind, b] : bytes) {
    std::printf("| %s | %.1f |\n", kind.c_str(), b / 1e6);
    if (kind != "truth/ (simulator only)") camera += b;
  }
  std::printf("| **the camera's files and set.json (what a pull without truth moves)** | **%.1f** |\n", camera / 1e6);

  // Three rounds, alternating, medians (the machine is shared).
  std::vector<double> preview_s, live_whole_s, plain_s;
  uint64_t preview_bytes = 0;
  for (int round = 0; round < 3; ++round) {
    veneer::rig::PullOptions o;
    o.include_truth = false;
    o.live_first = true;
    const fs::path out = dir / ("pulled-live-" + std::to_string(round));
    const auto t0 = Clock::now();
    o.on_preview = [&](const fs::path& f) {
      preview_s.push_back(secs(Clock::now() - t0));
      preview_bytes = 0;
      for (const auto& e : fs::directory_iterator(f)) preview_bytes += e.file_size();
    };
    if (auto s = c.pull_set(first, out, o); !s) {
      std::fprintf(stderr, "bench_rig: live-first pull: %s\n", s.message().c_str());
      return 1;
    }
    live_whole_s.push_back(secs(Clock::now() - t0));
    const auto t1 = Clock::now();
    if (auto s = c.pull(first, dir / ("pulled-plain-" + std::to_string(round)), false); !s) return 1;
    plain_s.push_back(secs(Clock::now() - t1));
    fs::remove_all(out);
    fs::remove_all(dir / ("pulled-plain-" + std::to_string(round)));
  }
  auto median = [](std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
  };
  std::printf("\n### Pulling it on loopback (no truth/; median of 3, alternating)\n\n| step | s | MB |\n|---|---|---|\n");
  std::printf("| **live first: the preview set in place (on_preview)** | **%.2f** | %.2f |\n", median(preview_s), preview_bytes / 1e6);
  std::printf("| live first: the whole set in place (exchanged with the preview) | %.2f | %.1f |\n", median(live_whole_s), camera / 1e6);
  std::printf("| peer: a plain pull of the whole set | %.2f | %.1f |\n", median(plain_s), camera / 1e6);
  client->reset();
  d->stop(SIGTERM);
  return 0;
}

// 5. TLS against plain TCP, in the same run (see the header).
static int bench_tls(const fs::path& dir) {
  const char* env = std::getenv("VENEER_BENCH_TLS_SIZE");
  const std::string size = env && *env ? env : "1024x680";
  const int rounds = static_cast<int>(env_number("VENEER_BENCH_TLS_ROUNDS", 5));
  fs::path tls_store = dir / "tls-store", plain_store = dir / "plain-store";
  const std::vector<std::string> common = {"--size", size, "--log", "warn"};
  auto tls_rig = rigtest::DaemonProcess::start(tls_store, common);
  if (!tls_rig || tls_rig->port() == 0) {
    std::fprintf(stderr, "bench_rig: veneerd did not start: %s\n", tls_rig ? tls_rig->log().c_str() : "");
    return 1;
  }
  auto token = veneer::rig::read_token_file(tls_store / "token");
  if (!token) return 1;
  veneer::rig::ConnectOptions to;
  to.fingerprint = rigtest::rig_fingerprint(tls_store);
  auto tls_client = veneer::rig::Client::connect({"127.0.0.1", tls_rig->port()}, *token, to);
  if (!tls_client) {
    std::fprintf(stderr, "bench_rig: %s\n", tls_client.message().c_str());
    return 1;
  }
  auto id = (*tls_client)->capture();
  if (!id) return 1;
  auto done = (*tls_client)->wait_event([&](const veneer::rig::Event& e) {
    return e.set_id == *id && (e.kind == Kind::set_stored || e.kind == Kind::capture_failed);
  }, 600);
  if (!done || done->kind != Kind::set_stored) {
    std::fprintf(stderr, "bench_rig: capture for the TLS bench failed\n");
    return 1;
  }
  // The same set served in plain TCP by a second daemon on a copy of the store.
  fs::create_directories(plain_store);
  fs::copy(tls_store / *id, plain_store / *id, fs::copy_options::recursive);
  fs::copy_file(tls_store / "token", plain_store / "token");
  auto plain_extra = common;
  plain_extra.push_back("--plain-tcp");
  auto plain_rig = rigtest::DaemonProcess::start(plain_store, plain_extra);
  if (!plain_rig || plain_rig->port() == 0) return 1;
  veneer::rig::ConnectOptions po;
  po.plain_tcp = true;
  auto plain_client = veneer::rig::Client::connect({"127.0.0.1", plain_rig->port()}, *token, po);
  if (!plain_client) {
    std::fprintf(stderr, "bench_rig: %s\n", plain_client.message().c_str());
    return 1;
  }
  uint64_t set_bytes = 0;
  for (const auto& e : fs::recursive_directory_iterator(tls_store / *id)) {
    if (e.is_regular_file()) set_bytes += e.file_size();
  }
  struct Side {
    veneer::rig::Client* client;
    rigtest::DaemonProcess* rig;
    std::vector<double> mb_s, cpu_ms_per_mb;
    double fps = 0;
  };
  Side sides[2] = {{tls_client->get(), tls_rig.get(), {}, {}, 0}, {plain_client->get(), plain_rig.get(), {}, {}, 0}};
  for (int round = 0; round < rounds; ++round) {
    for (int k = 0; k < 2; ++k) {
      Side& side = sides[round % 2 == 0 ? k : 1 - k];  // alternating which goes first
      const fs::path out = dir / "tls-pull";
      fs::remove_all(out);
      const double cpu0 = side.rig->cpu_seconds();
      const auto t0 = Clock::now();
      if (auto s = side.client->pull(*id, out, true); !s) {
        std::fprintf(stderr, "bench_rig: pull: %s\n", s.message().c_str());
        return 1;
      }
      const double t = secs(Clock::now() - t0);
      side.mb_s.push_back(set_bytes / 1e6 / t);
      side.cpu_ms_per_mb.push_back((side.rig->cpu_seconds() - cpu0) * 1000 / (set_bytes / 1e6));
      fs::remove_all(out);
    }
  }
  // Live view: 30 fps asked, 4 s each, one rig at a time.
  for (auto& side : sides) {
    std::atomic<int> frames{0};
    side.client->on_live_frame = [&](const veneer::rig::LiveFrame&) { ++frames; };
    (void)side.client->start_live_view(30);
    std::this_thread::sleep_for(std::chrono::milliseconds(700));
    frames = 0;
    const auto t0 = Clock::now();
    std::this_thread::sleep_for(std::chrono::seconds(4));
    side.fps = frames.load() / secs(Clock::now() - t0);
    (void)side.client->stop_live_view();
    side.client->on_live_frame = nullptr;
  }
  auto median = [](std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
  };
  const double tls_mb = median(sides[0].mb_s), plain_mb = median(sides[1].mb_s);
  std::printf("\n### TLS 1.3 against plain TCP on loopback (issue 43; one %s set with truth/, %.1f MB; median of %d "
              "alternating pulls each; two veneerd processes, same set)\n\n",
              size.c_str(), set_bytes / 1e6, rounds);
  std::printf("| measure | TLS 1.3 | plain TCP (peer) | TLS / plain |\n|---|---|---|---|\n");
  std::printf("| **pull throughput (MB/s)** | %.0f | %.0f | **%.0f %%** (goal >= 80 %%) |\n", tls_mb, plain_mb,
              plain_mb > 0 ? 100 * tls_mb / plain_mb : 0.0);
  std::printf("| veneerd CPU per pulled MB (ms) | %.2f | %.2f | %.2f |\n", median(sides[0].cpu_ms_per_mb),
              median(sides[1].cpu_ms_per_mb),
              median(sides[1].cpu_ms_per_mb) > 0 ? median(sides[0].cpu_ms_per_mb) / median(sides[1].cpu_ms_per_mb) : 0.0);
  std::printf("| **live view (fps, 30 asked)** | %.1f | %.1f | **%.0f %%** |\n", sides[0].fps, sides[1].fps,
              sides[1].fps > 0 ? 100 * sides[0].fps / sides[1].fps : 0.0);
  tls_client->reset();
  plain_client->reset();
  return 0;
}

int main(int argc, char** argv) {
  veneer::log::set_levels("warn");
  fs::path dir = rigtest::temp_dir("bench");
  if (argc > 1 && std::string(argv[1]) == "--memory") {  // section 3 alone
    int rc = bench_daemon_memory(dir);
    fs::remove_all(dir);
    return rc;
  }
  if (argc > 1 && std::string(argv[1]) == "--tls") {  // section 5 alone
    int rc = bench_tls(dir);
    fs::remove_all(dir);
    return rc;
  }
  if (argc > 1 && std::string(argv[1]) == "--capture-peak") {  // section 4 alone
    int rc = bench_capture_peak(dir);
    fs::remove_all(dir);
    return rc;
  }
  veneerd::DaemonOptions o;
  o.simulate = true;
  o.size = {1024, 680};
  o.noise_sigma = 0.002;
  o.hue_latency_ms = 20;  // a real bridge answers in 10..50 ms
  o.hue_rate_limits = true;
  o.listen = "127.0.0.1:0";
  o.store = dir / "store";
  auto daemon = veneerd::Daemon::create(o);
  if (!daemon) {
    std::fprintf(stderr, "bench_rig: %s\n", daemon.message().c_str());
    return 1;
  }
  if (auto s = (*daemon)->start(); !s) {
    std::fprintf(stderr, "bench_rig: %s\n", s.message().c_str());
    return 1;
  }
  auto& d = **daemon;
  auto client = veneer::rig::Client::connect({"127.0.0.1", d.port()}, d.token());
  if (!client) {
    std::fprintf(stderr, "bench_rig: %s\n", client.message().c_str());
    return 1;
  }
  auto& c = **client;
  const double settle_s = d.config().settle_ms / 1000.0;
  const double exposure_s = d.config().exposure.shutter_s;

  // The simulator's render time for one shot at this size (what a real camera's
  // readout replaces), measured here as the peer.
  veneer::sim::RenderOptions ro;
  ro.size = o.size;
  auto scene = veneer::sim::make_scene("bull", ro);
  double render_s = 0;
  if (scene) {
    auto ring = veneer::sim::thesis_rig();
    auto t0 = Clock::now();
    for (int i = 0; i < 3; ++i) (void)veneer::sim::render(**scene, {ring[i]}, ro);
    render_s = secs(Clock::now() - t0) / 3;
  }

  // --- 1. one full set
  d.simulated()->bridge().reset_counters();
  std::mutex m;
  std::vector<Clock::time_point> shot_times;
  c.on_event = [&](const veneer::rig::Event& e) {
    std::lock_guard lock(m);
    if (e.kind == Kind::capture_started || e.kind == Kind::shot_taken) shot_times.push_back(Clock::now());
  };
  auto t_start = Clock::now();
  auto id = c.capture();
  if (!id) {
    std::fprintf(stderr, "bench_rig: %s\n", id.message().c_str());
    return 1;
  }
  auto done = c.wait_event([&](const veneer::rig::Event& e) {
    return e.set_id == *id && (e.kind == Kind::set_stored || e.kind == Kind::capture_failed);
  }, 120);
  double total_s = secs(Clock::now() - t_start);
  auto counters = d.simulated()->bridge().counters();
  if (!done || done->kind != Kind::set_stored) {
    std::fprintf(stderr, "bench_rig: capture failed: %s\n", done ? done->reason.c_str() : done.message().c_str());
    return 1;
  }
  std::vector<double> steps;
  {
    std::lock_guard lock(m);
    for (size_t i = 1; i < shot_times.size(); ++i) steps.push_back(secs(shot_times[i] - shot_times[i - 1]));
  }
  double mean_step = 0, worst_step = 0;
  for (double s : steps) {
    mean_step += s / steps.size();
    worst_step = std::max(worst_step, s);
  }
  std::printf("\n### Full set on the simulated rig (1024x680, 7 lamps + ambient = %zu shots, Hue latency %d ms, rate limits on)\n\n",
              steps.size(), o.hue_latency_ms);
  std::printf("| measure | value |\n|---|---|\n");
  std::printf("| whole capture incl. storing (s) | %.2f |\n", total_s);
  std::printf("| mean time per shot (ms) | %.0f |\n", mean_step * 1000);
  std::printf("| worst shot (ms) | %.0f |\n", worst_step * 1000);
  std::printf("| exposure + settle per shot (ms) | %.0f |\n", (exposure_s + settle_s) * 1000);
  std::printf("| simulator render per shot, peer (ms) | %.0f |\n", render_s * 1000);
  std::printf("| **per shot beyond exposure + settle (ms)** | **%.0f** |\n", (mean_step - exposure_s - settle_s) * 1000);
  std::printf("| per shot beyond exposure + settle + render (ms) | %.0f |\n",
              (mean_step - exposure_s - settle_s - render_s) * 1000);
  std::printf("| Hue light commands accepted | %llu |\n", static_cast<unsigned long long>(counters.light_commands));
  std::printf("| Hue group commands accepted | %llu |\n", static_cast<unsigned long long>(counters.group_commands));
  std::printf("| **requests refused for rate (429) / busy (503)** | **%llu / %llu** |\n",
              static_cast<unsigned long long>(counters.refused_rate), static_cast<unsigned long long>(counters.refused_busy));

  // --- 2. live view, alone and while a download runs
  auto live_client = veneer::rig::Client::connect({"127.0.0.1", d.port()}, d.token());
  if (!live_client) return 1;
  std::atomic<int> frames{0};
  std::atomic<int> frame_w{0}, frame_h{0};
  (*live_client)->on_live_frame = [&](const veneer::rig::LiveFrame& f) {
    ++frames;
    frame_w = f.width;
    frame_h = f.height;
  };
  auto measure_live = [&](double seconds) {
    frames = 0;
    auto t0 = Clock::now();
    std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
    return frames.load() / secs(Clock::now() - t0);
  };
  (void)(*live_client)->start_live_view(30);
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  double fps_alone = measure_live(3);

  std::atomic<bool> stop{false};
  std::atomic<uint64_t> downloaded{0};
  std::thread downloader([&] {
    int n = 0;
    while (!stop) {
      fs::path out = dir / ("pull-" + std::to_string(n++));
      if (c.pull(*id, out, true)) {
        std::error_code ec;
        for (auto& e : fs::recursive_directory_iterator(out, ec)) {
          if (e.is_regular_file()) downloaded += e.file_size();
        }
      }
      fs::remove_all(out);
    }
  });
  auto t_dl = Clock::now();
  double fps_download = measure_live(4);
  stop = true;
  downloader.join();
  double dl_mb_s = downloaded.load() / 1048576.0 / secs(Clock::now() - t_dl);
  auto stats = d.server().stats();
  std::printf("\n### Live view (%dx%d JPEG, 30 fps asked)\n\n", frame_w.load(), frame_h.load());
  std::printf("| measure | alone | while downloading | ratio |\n|---|---|---|---|\n");
  std::printf("| **frames per second** | %.1f | **%.1f** | %.2f |\n", fps_alone, fps_download,
              fps_alone > 0 ? fps_download / fps_alone : 0.0);
  std::printf("| download rate (MiB/s) | - | %.1f | - |\n", dl_mb_s);
  std::printf("| live frames dropped for slow clients | - | %llu | - |\n",
              static_cast<unsigned long long>(stats.live_frames_dropped));
  live_client->reset();
  client->reset();
  daemon->reset();
  int rc = bench_daemon_memory(dir);
  if (rc == 0) rc = bench_tls(dir);
  if (rc == 0) rc = bench_capture_peak(dir);
  fs::remove_all(dir);
  return rc;
}
