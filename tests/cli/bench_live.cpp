// bench_live: live first against LibRaw, whole processes, in one run, at
// 1024x680 (the demo pair) and 5600x3750 (VENEER_BENCH_FULL=WxH to change,
// =0 to skip; VENEER_BENCH_SETS=<folder> keeps and reuses the simulated pairs). Per size: the pair simulated as `veneer simulate --optics
// --dng` writes it (bull <- orange, 7 lamps + ambient, a DNG beside each
// PNG), then
//  - LibRaw decoding the pair's 16 RAW files, linear, AHD, one thread (a
//    child process of this program with OMP_NUM_THREADS=1), the yardstick;
//  - `veneer transfer --live` (a child: files in, the live-size map and its
//    pictures written): the time to the live-ready map;
//  - `veneer transfer` with an empty result cache (a child): every
//    full-resolution result;
// with each child's peak RSS and the maps' coverage and coherence from their
// metrics.json. The simulator's truth/ folders are set aside (renamed
// truth.aside for the run, put back after) as a user's sets have none (issue
// 42); VENEER_BENCH_TRUTH=1 keeps them. Then the demo pair as `veneer simulate`
// writes it (16-bit PNGs, no RAW; truth set aside): the whole `veneer
// transfer` (cold cache) against OpenCV merely reading its photos on one
// thread, best of three each. Last, issue 48's goals beside what this run
// measured. Prints markdown tables; never fails on a number.
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <tuple>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgcodecs.hpp>

#include "veneer/io/raw.hpp"

namespace fs = std::filesystem;
extern char** environ;

namespace {

struct Child {
  double seconds = -1, rss_gib = -1;
};

// Runs `bin args...` (stdout to /dev/null) with `env` added; wall time and
// the child's peak RSS (wait4).
Child run(const std::string& bin, const std::vector<std::string>& args, const std::vector<std::string>& env = {}) {
  Child c;
  std::vector<char*> argv{const_cast<char*>(bin.c_str())};
  for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  std::vector<std::string> env_strings;
  for (char** e = environ; *e; ++e) env_strings.emplace_back(*e);
  for (const auto& e : env) env_strings.push_back(e);
  std::vector<char*> envp;
  for (auto& e : env_strings) envp.push_back(e.data());
  envp.push_back(nullptr);
  const auto t0 = std::chrono::steady_clock::now();
  const pid_t pid = ::fork();
  if (pid == 0) {
    if (std::FILE* null = std::fopen("/dev/null", "w")) ::dup2(::fileno(null), 1);
    ::execve(bin.c_str(), argv.data(), envp.data());
    std::_Exit(127);
  }
  if (pid < 0) return c;
  int status = 0;
  rusage u{};
  if (::wait4(pid, &status, 0, &u) != pid || !WIFEXITED(status) || WEXITSTATUS(status) != 0) {
    std::fprintf(stderr, "%s %s failed (status %d)\n", bin.c_str(), args.empty() ? "" : args[0].c_str(), status);
    return c;
  }
  c.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  c.rss_gib = static_cast<double>(u.ru_maxrss) / (1024.0 * 1024.0);
  return c;
}

// VENEER_BENCH_BIN=<folder>: the `veneer` to run (default: this build's)
const std::string kVeneer =
    std::string(std::getenv("VENEER_BENCH_BIN") ? std::getenv("VENEER_BENCH_BIN") : VENEER_BIN_DIR) + "/veneer";

std::vector<std::string> raw_files(const fs::path& set) {
  std::vector<std::string> out;
  for (const auto& e : fs::directory_iterator(set))
    if (veneer::io::is_raw_file_name(e.path().filename().string())) out.push_back(e.path().string());
  std::sort(out.begin(), out.end());
  return out;
}

nlohmann::json metrics(const fs::path& out) {
  std::ifstream in(out / "metrics.json");
  auto j = nlohmann::json::parse(in, nullptr, false);
  return j.is_object() ? j : nlohmann::json::object();
}

double quality(const nlohmann::json& m, const char* key) {
  return m.contains("quality") && m["quality"].contains(key) ? 100.0 * m["quality"][key].get<double>() : -1;
}

std::string load() {
  double l[3] = {0, 0, 0};
  if (::getloadavg(l, 3) < 0) return "?";
  char b[64];
  std::snprintf(b, sizeof b, "%.1f %.1f %.1f", l[0], l[1], l[2]);
  return b;
}

struct Row {
  std::string size, live_decode, load_before, load_after;
  int raw_files = 0;
  double raw_mb = 0;
  Child libraw, live, live_no_truth, full;
  double live_cov = -1, live_coh = -1, full_cov = -1, full_coh = -1;
  std::string live_size;
};

Row run_size(const std::string& exe, int w, int h, const fs::path& dir) {
  Row r;
  r.size = std::to_string(w) + "x" + std::to_string(h);
  const std::string size = r.size;
  // VENEER_BENCH_SETS=<folder>: the pairs are kept in <folder>/<WxH>/{dst,src} and reused
  // (simulating 5600x3750 takes minutes)
  const char* keep = std::getenv("VENEER_BENCH_SETS");
  const fs::path sets = keep ? fs::path(keep) / size : dir;
  const fs::path dst = sets / "dst", src = sets / "src";
  for (const auto& [scene, role, folder] : {std::tuple{"bull", "destination", dst}, std::tuple{"orange", "source", src}}) {
    if (fs::exists(folder / "set.json")) continue;
    if (run(kVeneer, {"simulate", "--scene", scene, "--role", role, "--size", size, "--scale", "2.5", "--optics",
                      "--dng", "--out", folder.string()})
            .seconds < 0)
      return r;
  }
  // truth set aside (a user's sets have none), put back when the run ends
  struct Aside {
    std::vector<fs::path> moved;
    ~Aside() {
      std::error_code ec;
      for (const auto& t : moved) fs::rename(t.parent_path() / "truth.aside", t, ec);
    }
  } aside;
  if (!std::getenv("VENEER_BENCH_TRUTH") || std::string(std::getenv("VENEER_BENCH_TRUTH")) != "1")
    for (const fs::path& set : {dst, src}) {
      std::error_code ec;
      if (!fs::exists(set / "truth")) continue;
      fs::rename(set / "truth", set / "truth.aside", ec);
      if (!ec) aside.moved.push_back(set / "truth");
    }
  std::vector<std::string> files = raw_files(dst), more = raw_files(src);
  files.insert(files.end(), more.begin(), more.end());
  r.raw_files = static_cast<int>(files.size());
  for (const auto& f : files) r.raw_mb += fs::file_size(f) / 1e6;
  r.load_before = load();

  // LibRaw, linear, AHD, one thread: this program again, as a child.
  std::vector<std::string> args{"--decode-raw"};
  args.insert(args.end(), files.begin(), files.end());
  r.libraw = run(exe, args, {"OMP_NUM_THREADS=1"});
  // live first, then everything (an empty result cache)
  r.live = run(kVeneer, {"transfer", "--live", "--dst", dst.string(), "--src", src.string(), "--out",
                         (dir / "live").string()});
  r.live_no_truth = run(kVeneer, {"transfer", "--live", "--live-no-truth", "--dst", dst.string(), "--src",
                                  src.string(), "--out", (dir / "live-no-truth").string()});
  r.full = run(kVeneer, {"transfer", "--dst", dst.string(), "--src", src.string(), "--out", (dir / "full").string(),
                         "--cache-dir", (dir / "cache").string(), "--cache-size-gb", "16"});
  r.load_after = load();
  const auto lm = metrics(dir / "live"), fm = metrics(dir / "full");
  if (lm.contains("live")) {
    r.live_decode = lm["live"].value("destination_decode", "") + " / " + lm["live"].value("source_decode", "");
  }
  {
    std::ifstream pfm(dir / "live" / "map.pfm", std::ios::binary);
    std::string magic;
    int mw = 0, mh = 0;
    pfm >> magic >> mw >> mh;
    r.live_size = std::to_string(mw) + "x" + std::to_string(mh);
  }
  r.live_cov = quality(lm, "coverage");
  r.live_coh = quality(lm, "coherence");
  r.full_cov = quality(fm, "coverage");
  r.full_coh = quality(fm, "coherence");
  return r;
}

// The child: decode each RAW file (linear, AHD) in turn.
int decode_raw(int argc, char** argv) {
  veneer::io::RawOptions o;
  o.demosaic = veneer::io::Demosaic::ahd;
  for (int i = 2; i < argc; ++i) {
    auto m = veneer::io::read_raw_linear(argv[i], o);
    if (!m) {
      std::fprintf(stderr, "%s\n", m.message().c_str());
      return 1;
    }
  }
  return 0;
}

// The demo pair as `veneer simulate` writes it (16-bit PNGs, truth set
// aside): the whole `veneer transfer` with an empty cache against OpenCV
// reading the same photos on one thread, the better of three runs each.
struct Demo {
  double opencv_s = -1, transfer_s = -1, rss_gib = -1;
  int frames = 0;
  std::string load_before, load_after;
};

Demo run_demo(const fs::path& dir) {
  Demo d;
  const fs::path dst = dir / "dst", src = dir / "src";
  for (const auto& [scene, role, folder] : {std::tuple{"bull", "destination", dst}, std::tuple{"orange", "source", src}})
    if (run(kVeneer, {"simulate", "--scene", scene, "--role", role, "--size", "1024x680", "--scale", "2.5", "--out",
                      folder.string()})
            .seconds < 0)
      return d;
  std::vector<std::string> photos;
  for (const fs::path& set : {dst, src}) {
    std::error_code ec;
    fs::rename(set / "truth", set / "truth.aside", ec);
    for (const auto& e : fs::directory_iterator(set)) {
      const std::string n = e.path().filename().string();
      if (e.path().extension() == ".png" && (n.rfind("light_", 0) == 0 || n == "ambient.png"))
        photos.push_back(e.path().string());
    }
  }
  std::sort(photos.begin(), photos.end());
  d.frames = static_cast<int>(photos.size());
  d.load_before = load();
  for (int round = 0; round < 3; ++round) {
    cv::setNumThreads(1);
    const auto t0 = std::chrono::steady_clock::now();
    for (const auto& f : photos)
      if (cv::imread(f, cv::IMREAD_UNCHANGED).empty()) std::fprintf(stderr, "imread failed: %s\n", f.c_str());
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    cv::setNumThreads(-1);
    if (d.opencv_s < 0 || s < d.opencv_s) d.opencv_s = s;
    const fs::path out = dir / "out", cache = dir / ("cache-" + std::to_string(round));
    const Child c = run(kVeneer, {"transfer", "--dst", dst.string(), "--src", src.string(), "--out", out.string(),
                                  "--cache-dir", cache.string()});
    if (c.seconds > 0 && (d.transfer_s < 0 || c.seconds < d.transfer_s)) d.transfer_s = c.seconds, d.rss_gib = c.rss_gib;
    fs::remove_all(out);
    fs::remove_all(cache);
  }
  d.load_after = load();
  return d;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc > 1 && std::strcmp(argv[1], "--decode-raw") == 0) return decode_raw(argc, argv);
  std::vector<std::pair<int, int>> sizes = {{1024, 680}, {5600, 3750}};
  if (const char* env = std::getenv("VENEER_BENCH_FULL")) {
    int w = 0, h = 0;
    if (std::sscanf(env, "%dx%d", &w, &h) == 2 && w > 0 && h > 0) sizes[1] = {w, h};
    else sizes.pop_back();
  }
  const std::string exe = fs::read_symlink("/proc/self/exe").string();
  const fs::path root = fs::temp_directory_path() / ("veneer-bench-live-" + std::to_string(::getpid()));
  std::vector<Row> rows;
  for (const auto& [w, h] : sizes) {
    const fs::path dir = root / (std::to_string(w) + "x" + std::to_string(h));
    fs::create_directories(dir);
    rows.push_back(run_size(exe, w, h, dir));
    fs::remove_all(dir);
  }
  Demo demo;
  if (!std::getenv("VENEER_BENCH_DEMO") || std::string(std::getenv("VENEER_BENCH_DEMO")) != "0") {
    const fs::path dir = root / "demo";
    fs::create_directories(dir);
    demo = run_demo(dir);
  }
  fs::remove_all(root);

  std::printf("## Live first: whole processes against LibRaw (bull <- orange, --optics --dng, 16 RAW files)\n\n");
  std::printf("| pair | RAW MB | LibRaw AHD 1 thread s | `transfer --live` s | live / LibRaw | `--live --live-no-truth` s | that / LibRaw | `transfer` (cold cache) s "
              "| all / LibRaw | live + all s | live peak GiB | all peak GiB | live map | live decode (dst / src) | "
              "load before / after |\n");
  std::printf("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---|---|\n");
  for (const Row& r : rows) {
    const double lib = r.libraw.seconds;
    std::printf("| %s | %.0f | %.2f | %.2f | %.3f | %.2f | %.3f | %.2f | %.2f | %.2f | %.2f | %.2f | %s | %s | %s / %s |\n",
                r.size.c_str(), r.raw_mb, lib, r.live.seconds, lib > 0 ? r.live.seconds / lib : 0,
                r.live_no_truth.seconds, lib > 0 ? r.live_no_truth.seconds / lib : 0, r.full.seconds,
                lib > 0 ? r.full.seconds / lib : 0, r.live.seconds + r.full.seconds, r.live.rss_gib, r.full.rss_gib,
                r.live_size.c_str(), r.live_decode.c_str(), r.load_before.c_str(), r.load_after.c_str());
  }
  std::printf("\n## The live map against the full-resolution map (metrics.json, truth masks)\n\n");
  std::printf("| pair | coverage live / full %% | coherence live / full %% | coverage diff | coherence diff |\n");
  std::printf("|---|---|---|---:|---:|\n");
  for (const Row& r : rows)
    std::printf("| %s | %.1f / %.1f | %.1f / %.1f | %+.1f | %+.1f |\n", r.size.c_str(), r.live_cov, r.full_cov,
                r.live_coh, r.full_coh, r.live_cov - r.full_cov, r.live_coh - r.full_coh);
  std::printf("\nThe sets' truth/ folders set aside (VENEER_BENCH_TRUTH=1 keeps them): metrics' coverage and "
              "coherence are then against the segmented masks. ");
  std::printf("live = `veneer transfer --live` (default --live-width 1280: a set no wider keeps its size); all = "
              "`veneer transfer` with an empty result cache (RAW unpacked by LibRaw, our MHC demosaic, full resolution; the look's figures not asked for); live + all "
              "= what the viewer's flow does one after the other. Peak = the child's own RSS high-water mark.\n");

  if (demo.frames > 0) {
    std::printf("\n## The demo pair as a user's sets (1024x680 16-bit PNGs, truth/ set aside): the whole `veneer "
                "transfer` (cold cache) against OpenCV reading its %d photos on one thread, best of three each\n\n",
                demo.frames);
    std::printf("| OpenCV imread, 1 thread s | `veneer transfer` s | / OpenCV | peak GiB | load before / after |\n");
    std::printf("|---:|---:|---:|---:|---|\n");
    std::printf("| %.3f | %.3f | %.2fx | %.2f | %s / %s |\n", demo.opencv_s, demo.transfer_s,
                demo.opencv_s > 0 ? demo.transfer_s / demo.opencv_s : 0, demo.rss_gib, demo.load_before.c_str(),
                demo.load_after.c_str());
  }
  // Issue 48's goals beside this run's measures (the peers measured in the same run).
  std::printf("\n## Issue 48's goals, against the peers measured in this run\n\n");
  std::printf("| goal | measured | peer | ratio | bound | met |\n|---|---:|---:|---:|---:|---|\n");
  auto goal = [](const std::string& what, double measured, double peer, double bound) {
    if (measured < 0 || peer <= 0) {
      std::printf("| %s | not measured | | | %.2fx | |\n", what.c_str(), bound);
      return;
    }
    const double ratio = measured / peer;
    std::printf("| %s | %.2f s | %.2f s | %.3fx | %.2fx | %s |\n", what.c_str(), measured, peer, ratio, bound,
                ratio <= bound ? "yes" : "**no**");
  };
  for (const Row& r : rows) {
    if (r.size == "1024x680") continue;
    goal("`veneer transfer` " + r.size + ", every result, cold / LibRaw AHD 1 thread", r.full.seconds,
         r.libraw.seconds, 0.5);
    goal("`veneer transfer --live` " + r.size + " / LibRaw AHD 1 thread", r.live.seconds, r.libraw.seconds, 0.05);
    std::printf("| `veneer transfer` %s peak RSS | %.2f GiB | | | 4.00 GiB | %s |\n", r.size.c_str(), r.full.rss_gib,
                r.full.rss_gib > 0 && r.full.rss_gib <= 4.0 ? "yes" : "**no**");
  }
  goal("`veneer transfer` demo pair (PNG) / OpenCV reading its photos, 1 thread", demo.transfer_s, demo.opencv_s, 1.0);
  return 0;
}
