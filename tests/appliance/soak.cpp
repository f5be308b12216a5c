// veneer_soak — the rig's long run with faults (issue 43, `make soak`).
//
//   veneer_soak [--captures N] [--out DIR] [--faults SPEC] [--size WxH]
//
// Starts the real `veneerd --simulate --faults SPEC` as its own process and,
// N times: asks for a capture through the rig client and waits for its end
// (stored, or refused with a reason), checks the store (the set whole, or no
// folder of it; no temporary left), samples the daemon from /proc (RSS, open
// files, threads) and the store's bytes, then pulls a set -- whole, or as a
// client that hangs up mid-pull and pulls again (resuming), or beside a
// client that asks for a set and stops reading (the SPEC's client.vanish and
// client.stall). Writes DIR/report.json and DIR/soak.png (the four series).
// Exits 0 when every invariant held, 1 when one did not, 2 on bad arguments.
#include <dirent.h>
#include <signal.h>
#include <sys/wait.h>

#include <algorithm>
#include <csignal>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <map>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "rig_test_util.hpp"
#include "veneer/io/image_io.hpp"
#include "veneer/io/imageset.hpp"
#include "veneer/rig/client.hpp"
#include "veneerd/sim/fault_plan.hpp"

namespace fs = std::filesystem;
using json = nlohmann::json;
using Kind = veneer::rig::Event::Kind;
using Clock = std::chrono::steady_clock;

namespace {

// Every fault on, at rates that refuse about a fifth of the captures.
constexpr const char* kDefaultFaults =
    "bridge.429=0.01,bridge.503=0.01,bridge.timeout=0.0005,bridge.drop=0.005,lamp.unreachable=0.001,"
    "camera.gone=0.004,clock.step=0.002,store.enospc=0.002,store.eio=0.002,store.slow=0.01,store.slow_ms=100,"
    "client.vanish=0.15,client.stall=0.05,client.stall_ms=1500,seed=7";

// ---- the connection: the one place the soak connects to the rig -----------
// (when the API's transport changes -- TLS, a pinned fingerprint -- adapt here
// and in stall_client below)

struct RigAddress {
  uint16_t port = 0;
  std::string token;
};

veneer::Expected<std::unique_ptr<veneer::rig::Client>> connect_rig(const RigAddress& rig) {
  veneer::rig::ConnectOptions o;
  o.client_name = "veneer-soak";
  o.request_timeout_s = 30;
  return veneer::rig::Client::connect({"127.0.0.1", rig.port}, rig.token, o);
}

// A client that asks for set `id` in 1 KiB chunks and then stops reading
// (until `stall` is over, then it hangs up).
std::thread stall_client(const RigAddress& rig, const std::string& id, std::chrono::milliseconds stall) {
  return std::thread([port = rig.port, token = rig.token, id, stall] {
    rigtest::RawConnection c(port);
    if (!c.hello(token)) return;
    veneer::v1::ClientMessage m;
    m.set_id(2);
    m.mutable_fetch_images()->set_set_id(id);
    m.mutable_fetch_images()->set_chunk_size(1024);
    m.mutable_fetch_images()->set_include_truth(true);
    c.send(m);
    std::this_thread::sleep_for(stall);
  });
}

// ---- the daemon from /proc ------------------------------------------------

struct ProcSample {
  long rss_kb = -1;
  int fds = -1;
  int threads = -1;
};

ProcSample sample_proc(pid_t pid) {
  ProcSample s;
  const std::string base = "/proc/" + std::to_string(pid);
  std::ifstream status(base + "/status");
  std::string line;
  while (std::getline(status, line)) {
    if (line.rfind("VmRSS:", 0) == 0) s.rss_kb = std::stol(line.substr(6));
    if (line.rfind("Threads:", 0) == 0) s.threads = std::stoi(line.substr(8));
  }
  if (DIR* d = ::opendir((base + "/fd").c_str())) {
    s.fds = 0;
    while (dirent* e = ::readdir(d))
      if (e->d_name[0] != '.') ++s.fds;
    ::closedir(d);
  }
  return s;
}

uint64_t folder_bytes(const fs::path& folder) {
  uint64_t total = 0;
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(folder, ec); !ec && it != fs::recursive_directory_iterator();
       it.increment(ec)) {
    if (it->is_regular_file(ec)) total += it->file_size(ec);
  }
  return total;
}

// ---- the store's invariants -------------------------------------------------

// Entries in the store's root that only an unfinished write leaves: hidden
// names other than the store's lock and its trash.
std::vector<std::string> leftover_temporaries(const fs::path& store) {
  std::vector<std::string> out;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(store, ec)) {
    const std::string name = e.path().filename().string();
    if (name.empty() || name[0] != '.' || name == ".lock" || name == ".trash") continue;
    out.push_back(name);
  }
  return out;
}

// Whether the folder holds a whole set: it reads, has every lamp's photo and
// every file its manifest names.
bool whole_set(const fs::path& folder, std::string* why) {
  auto set = veneer::io::read_set(folder);
  if (!set) {
    *why = set.message();
    return false;
  }
  if (set->images.size() != set->lights.size() || set->lights.empty()) {
    *why = std::to_string(set->images.size()) + " photos for " + std::to_string(set->lights.size()) + " lights";
    return false;
  }
  return true;
}

// Files of `folder` under their final names (no ".part"), relative paths.
std::vector<std::string> final_files(const fs::path& folder) {
  std::vector<std::string> out;
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(folder, ec); !ec && it != fs::recursive_directory_iterator();
       it.increment(ec)) {
    if (!it->is_regular_file(ec)) continue;
    const std::string rel = fs::relative(it->path(), folder).generic_string();
    if (rel.size() > 5 && rel.compare(rel.size() - 5, 5, ".part") == 0) continue;
    out.push_back(rel);
  }
  std::sort(out.begin(), out.end());
  return out;
}

// Final-named files in `folder` that differ from the rig's (size or bytes).
int differing_files(const fs::path& folder, const fs::path& rig_set, std::string* first) {
  int bad = 0;
  for (const auto& rel : final_files(folder)) {
    auto mine = veneer::io::read_file_bytes(folder / rel);
    auto theirs = veneer::io::read_file_bytes(rig_set / rel);
    if (!mine || !theirs || *mine != *theirs) {
      if (bad++ == 0 && first)
        *first = rel + ": " + (mine ? std::to_string(mine->size()) : "?") + " bytes here, " +
                 (theirs ? std::to_string(theirs->size()) : "no file") + " on the rig";
    }
  }
  return bad;
}

// The named error of a refused capture (the rig's reason, first match wins).
std::string named_error(const std::string& reason) {
  struct Rule {
    const char* needle;
    const char* name;
  };
  static const Rule rules[] = {
      {"cancelled", "cancelled"},
      {"not connected (unplugged)", "camera_unplugged"},
      {"cannot read the lamps from the bridge", "camera_cannot_read_lamps"},
      {"No space left on device", "store_full"},
      {" is full", "store_full"},
      {"Input/output error", "store_io_error"},
      {"is unreachable", "lamp_unreachable"},
      {"unreachable", "lamp_unreachable"},
      {"lamps: the bridge does not answer", "lamps_not_restored"},
      {"restoring their state after the capture failed", "lamps_not_restored"},
      {"did not answer", "lamps_timeout"},
      {" within ", "lamps_timeout"},
      {"another client changed the lamps", "lamps_taken_over"},
      {"a capture is already running", "busy"},
  };
  for (const auto& r : rules)
    if (reason.find(r.needle) != std::string::npos) return r.name;
  if (reason.rfind("lamps", 0) == 0) return "lamps_error";
  if (reason.rfind("camera", 0) == 0) return "camera_error";
  if (reason.rfind("storing set", 0) == 0) return "store_error";
  return "";
}

// ---- the plot ---------------------------------------------------------------

void plot(const json& report, const fs::path& file) {
  struct Series {
    const char* key;
    const char* title;
    double scale;
  };
  const Series series[] = {{"rss_kb", "RSS [MiB]", 1.0 / 1024},
                           {"fds", "open file descriptors", 1},
                           {"threads", "threads", 1},
                           {"store_bytes", "store [MiB]", 1.0 / (1024 * 1024)}};
  const int W = 1000, H = 200, left = 90, right = 20, top = 28, bottom = 26;
  cv::Mat img(H * 4, W, CV_8UC3, cv::Scalar(255, 255, 255));
  for (int p = 0; p < 4; ++p) {
    const json& a = report[series[p].key];
    std::vector<double> v;
    for (const auto& x : a) v.push_back(x.get<double>() * series[p].scale);
    const int y0 = p * H;
    cv::Rect box(left, y0 + top, W - left - right, H - top - bottom);
    cv::rectangle(img, box, cv::Scalar(160, 160, 160));
    double lo = v.empty() ? 0 : *std::min_element(v.begin(), v.end());
    double hi = v.empty() ? 1 : *std::max_element(v.begin(), v.end());
    if (p == 1 || p == 2) lo = 0;  // descriptors and threads from 0: flat reads flat; RSS zoomed to its range
    if (hi - lo < 1e-9) hi = lo + 1;
    hi += (hi - lo) * 0.05;
    char text[160];
    std::snprintf(text, sizeof text, "%s  (captures 1..%zu; first %.1f, last %.1f)", series[p].title, v.size(),
                  v.empty() ? 0.0 : v.front(), v.empty() ? 0.0 : v.back());
    cv::putText(img, text, {left, y0 + 19}, cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
    for (int t = 0; t <= 2; ++t) {
      const double value = lo + (hi - lo) * t / 2;
      const int y = box.y + box.height - static_cast<int>(std::lround(box.height * t / 2.0));
      std::snprintf(text, sizeof text, "%.1f", value);
      cv::putText(img, text, {6, y + 4}, cv::FONT_HERSHEY_SIMPLEX, 0.4, cv::Scalar(60, 60, 60), 1, cv::LINE_AA);
      cv::line(img, {box.x - 4, y}, {box.x, y}, cv::Scalar(120, 120, 120));
    }
    std::vector<cv::Point> pts;
    for (size_t i = 0; i < v.size(); ++i) {
      const double fx = v.size() > 1 ? static_cast<double>(i) / (v.size() - 1) : 0.5;
      const double fy = (v[i] - lo) / (hi - lo);
      pts.emplace_back(box.x + static_cast<int>(std::lround(fx * (box.width - 1))),
                       box.y + box.height - 1 - static_cast<int>(std::lround(fy * (box.height - 1))));
    }
    if (!pts.empty()) cv::polylines(img, pts, false, cv::Scalar(170, 70, 20), 1, cv::LINE_AA);
    std::snprintf(text, sizeof text, "capture");
    cv::putText(img, text, {box.x + box.width - 60, y0 + H - 8}, cv::FONT_HERSHEY_SIMPLEX, 0.4,
                cv::Scalar(60, 60, 60), 1, cv::LINE_AA);
  }
  cv::imwrite(file.string(), img);
}

int usage(const std::string& why) {
  std::cerr << "veneer_soak: " << why
            << "\nusage: veneer_soak [--captures N] [--out DIR] [--faults SPEC] [--size WxH]\n";
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  std::signal(SIGPIPE, SIG_IGN);
  int captures = 1000;
  fs::path out = "soak-out";
  std::string faults = kDefaultFaults, size = "64x48";
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&]() -> std::string { return i + 1 < argc ? argv[++i] : ""; };
    if (a == "--captures") {
      const std::string v = value();
      if (v.empty() || v.find_first_not_of("0123456789") != std::string::npos || v.size() > 7)
        return usage("--captures: a whole number, got '" + v + "'");
      captures = std::stoi(v);
    } else if (a == "--out") {
      out = value();
    } else if (a == "--faults") {
      faults = value();
    } else if (a == "--size") {
      size = value();
    } else {
      return usage("unknown argument '" + a + "'");
    }
  }
  if (captures < 1) return usage("--captures: at least 1");
  auto plan = veneerd::FaultPlan::parse(faults);
  if (!plan) return usage(plan.message());

  std::error_code ec;
  fs::remove_all(out / "store", ec);
  fs::remove_all(out / "pulls", ec);
  fs::remove(out / "store.log", ec);
  fs::create_directories(out / "pulls", ec);
  if (ec) return usage(out.string() + ": cannot create: " + ec.message());
  const fs::path store = fs::absolute(out / "store");
  const fs::path pulls = fs::absolute(out / "pulls");

  // The rig: quick lamps (the rate limits' refusals come from bridge.429), small frames.
  const std::vector<std::string> daemon_args = {"--size", size, "--noise", "0", "--no-advertise", "--no-rate-limits",
                                                "--hue-light-rate", "50", "--hue-apply-delay-ms", "10",
                                                "--hue-latency-ms", "1", "--faults", faults};
  auto daemon = rigtest::DaemonProcess::start(store, daemon_args);
  if (!daemon || daemon->port() == 0) {
    std::cerr << "veneer_soak: veneerd did not start\n" << (daemon ? daemon->log() : "") << "\n";
    return 1;
  }
  const pid_t pid = daemon->pid();
  auto token = veneer::rig::read_token_file(store / "token");
  if (!token) {
    std::cerr << "veneer_soak: " << token.message() << "\n";
    return 1;
  }
  const RigAddress rig{daemon->port(), *token};
  auto control = connect_rig(rig);
  if (!control) {
    std::cerr << "veneer_soak: " << control.message() << "\n";
    return 1;
  }
  std::unique_ptr<veneer::rig::Client> client = std::move(*control);

  std::mt19937_64 rng(plan->seed());
  int stored = 0, half_sets = 0, leftovers = 0, restarts = 0, reconnects = 0;
  int pulls_asked = 0, pulls_whole = 0, pulls_vanished = 0, pulls_resumed = 0, pulls_stalled = 0, pulls_failed = 0;
  int wrong_final_files = 0;
  std::map<std::string, int> refused;
  std::vector<std::string> unnamed, problems, stored_ids;
  json rss = json::array(), fds = json::array(), threads = json::array(), store_bytes = json::array();
  bool store_equal_always = true;
  double waited_s = 0;  // waiting for the rig to be ready after a refusal
  uint64_t last_sets_bytes = 0, last_disk_bytes = 0;
  std::vector<std::thread> stalls;
  auto note = [&](const std::string& what) {
    if (problems.size() < 50) problems.push_back(what);
    std::cerr << "veneer_soak: " << what << "\n";
  };
  const auto t0 = Clock::now();

  for (int i = 1; i <= captures; ++i) {
    if (!client->connected()) {
      auto c = connect_rig(rig);
      if (!c) {
        note("capture " + std::to_string(i) + ": cannot reconnect: " + c.message());
        break;
      }
      client = std::move(*c);
      ++reconnects;
    }
    // ---- capture
    std::string id, reason;
    bool ok = false;
    if (auto asked = client->capture(); !asked) {
      reason = asked.message();
    } else {
      id = *asked;
      auto end = client->wait_event(
          [&](const veneer::rig::Event& e) {
            return e.set_id == id && (e.kind == Kind::set_stored || e.kind == Kind::capture_failed);
          },
          120);
      if (!end) {
        reason = "no outcome: " + end.message();
      } else if (end->kind == Kind::set_stored) {
        ok = true;
      } else {
        reason = end->reason;
      }
    }
    if (ok) {
      ++stored;
      std::string why;
      if (!whole_set(store / id, &why)) {
        ++half_sets;
        note("set " + id + " stored but not whole: " + why);
      }
      stored_ids.push_back(id);
    } else {
      std::string name = named_error(reason);
      if (name.empty()) {
        name = "unnamed";
        if (unnamed.size() < 20) unnamed.push_back(reason);
      }
      ++refused[name];
      if (!id.empty() && fs::exists(store / id, ec)) {
        ++half_sets;
        note("capture " + id + " refused (" + reason + ") but its folder is in the store");
      }
      // As a user would: wait until the rig is ready again (the camera back
      // on USB, the lamps given back) rather than be refused for the same cause.
      const auto wait_from = Clock::now();
      while (Clock::now() - wait_from < std::chrono::seconds(15)) {
        auto st = client->status();
        if (st && st->ready && !st->holds_lamps && !st->capturing) break;
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
      }
      waited_s += std::chrono::duration<double>(Clock::now() - wait_from).count();
    }
    for (const auto& t : leftover_temporaries(store)) {
      ++leftovers;
      note("capture " + std::to_string(i) + ": leftover temporary " + t);
    }
    if (!daemon->alive() || ::kill(pid, 0) != 0) {
      ++restarts;
      note("capture " + std::to_string(i) + ": veneerd (pid " + std::to_string(pid) + ") is gone");
      break;
    }

    // ---- the daemon and the store, sampled
    const ProcSample s = sample_proc(pid);
    rss.push_back(s.rss_kb);
    fds.push_back(s.fds);
    threads.push_back(s.threads);
    uint64_t disk = folder_bytes(store);
    store_bytes.push_back(disk);
    uint64_t sets_bytes = 0, set_folders = 0;
    if (auto listed = client->list_sets(); listed) {
      for (const auto& set : *listed) sets_bytes += set.bytes;
    } else {
      note("list_sets: " + listed.message());
    }
    for (const auto& e : fs::directory_iterator(store, ec)) {
      const std::string name = e.path().filename().string();
      if (e.is_directory() && !name.empty() && name[0] != '.') set_folders += folder_bytes(e.path());
    }
    if (sets_bytes != set_folders) {
      if (store_equal_always)
        note("capture " + std::to_string(i) + ": the rig lists " + std::to_string(sets_bytes) +
             " bytes of sets, their folders hold " + std::to_string(set_folders));
      store_equal_always = false;
    }
    last_sets_bytes = sets_bytes;
    last_disk_bytes = set_folders;

    // ---- a pull (of this set, or of one stored before)
    if (stored_ids.empty()) continue;
    const std::string pull_id = ok ? id : stored_ids[rng() % stored_ids.size()];
    const fs::path dest = pulls / pull_id;
    const fs::path rig_set = store / pull_id;
    ++pulls_asked;
    if (plan->draw(veneerd::Fault::client_stall)) {
      // Another client asks for the set and stops reading; this pull goes on beside it.
      ++pulls_stalled;
      stalls.push_back(stall_client(rig, pull_id, std::chrono::milliseconds(plan->sizes().client_stall_ms)));
    }
    if (plan->draw(veneerd::Fault::client_vanish)) {
      // A client that hangs up mid-pull: a connection of its own, closed from another thread.
      auto c = connect_rig(rig);
      if (!c) {
        note("pull " + pull_id + ": cannot connect: " + c.message());
      } else {
        veneer::rig::Client* raw = c->get();
        const double at = std::uniform_real_distribution<double>(0.05, 0.9)(rng);
        std::atomic<bool> closed{false};
        std::thread closer;
        veneer::Progress progress;
        progress.on_progress = [&](double f, const std::string&) {
          if (f > at && !closed.exchange(true)) {
            closer = std::thread([raw] { raw->close(); });
            const auto until = Clock::now() + std::chrono::seconds(10);
            while (raw->connected() && Clock::now() < until) std::this_thread::sleep_for(std::chrono::milliseconds(1));
          }
        };
        const bool whole = static_cast<bool>(raw->pull(pull_id, dest, true, false, progress));
        if (closer.joinable()) closer.join();
        if (!whole) ++pulls_vanished;
        // What the vanished client left: under a final name, only the rig's bytes.
        std::string first;
        const std::string staging_name = "." + dest.filename().string() + ".pull-" + pull_id;
        for (const fs::path& dir : {dest, pulls / staging_name}) {
          if (!fs::exists(dir, ec)) continue;
          if (int bad = differing_files(dir, rig_set, &first); bad > 0) {
            wrong_final_files += bad;
            note("pull " + pull_id + " interrupted: " + std::to_string(bad) + " final-named file(s) differ from the rig's, " + first);
          }
        }
        if (!whole && fs::exists(dest, ec)) {
          ++half_sets;
          note("pull " + pull_id + " interrupted but " + dest.string() + " exists");
        }
        if (!whole) ++pulls_resumed;  // the pull below resumes it
      }
    }
    if (auto s = client->pull(pull_id, dest, true, false); !s) {
      ++pulls_failed;
      note("pull " + pull_id + ": " + s.message());
    } else {
      std::string first;
      const auto mine = final_files(dest), theirs = final_files(rig_set);
      if (mine != theirs) {
        ++pulls_failed;
        note("pull " + pull_id + ": " + std::to_string(mine.size()) + " files, the rig has " + std::to_string(theirs.size()));
      } else if (int bad = differing_files(dest, rig_set, &first); bad > 0) {
        ++pulls_failed;
        wrong_final_files += bad;
        note("pull " + pull_id + ": " + first);
      } else {
        ++pulls_whole;
      }
    }
    fs::remove_all(dest, ec);
    for (auto& t : stalls) t.join();
    stalls.clear();
    if (i % 50 == 0 || i == captures) {
      std::fprintf(stderr, "veneer_soak: %d/%d captures, %d stored, RSS %ld kB, %d fds, %d threads, %.0f s\n", i,
                   captures, stored, s.rss_kb, s.fds, s.threads,
                   std::chrono::duration<double>(Clock::now() - t0).count());
    }
  }
  for (auto& t : stalls) t.join();
  const double seconds = std::chrono::duration<double>(Clock::now() - t0).count();

  // The whole store once more: every folder a whole set the rig lists, nothing else.
  int final_half = 0;
  std::vector<std::string> listed_ids;
  if (auto listed = client->list_sets(); listed)
    for (const auto& set : *listed) listed_ids.push_back(set.id);
  std::sort(listed_ids.begin(), listed_ids.end());
  for (const auto& e : fs::directory_iterator(store, ec)) {
    const std::string name = e.path().filename().string();
    if (!e.is_directory() || name.empty() || name[0] == '.') continue;
    std::string why;
    if (!std::binary_search(listed_ids.begin(), listed_ids.end(), name) || !whole_set(e.path(), &why)) {
      ++final_half;
      note("store: " + name + " is not a whole listed set " + why);
    }
  }
  half_sets += final_half;
  client.reset();
  // The daemon's own count of the faults it took (its last log line of them).
  daemon->stop(SIGTERM);
  json injected = json::object();
  {
    std::ifstream log(out / "store.log");
    std::string line;
    while (std::getline(log, line)) {
      const auto at = line.find("injected faults: ");
      if (at != std::string::npos) injected = json::parse(line.substr(at + 17), nullptr, false);
    }
  }
  if (!injected.is_object()) injected = json::object();
  for (veneerd::Fault f : {veneerd::Fault::client_vanish, veneerd::Fault::client_stall}) {  // drawn here, not by the daemon
    if (!plan->has(f)) continue;
    const auto c = plan->count(f);
    injected[veneerd::fault_name(f)] = {{"opportunities", c.opportunities}, {"taken", c.taken}};
  }

  json report;
  report["captures_asked"] = captures;
  report["stored"] = stored;
  report["refused"] = refused;
  report["unnamed_reasons"] = unnamed;
  report["half_sets"] = half_sets;
  report["leftover_temporaries"] = leftovers;
  report["daemon_restarts"] = restarts;
  report["daemon_pid"] = pid;
  report["client_reconnects"] = reconnects;
  report["pulls"] = {{"asked", pulls_asked},          {"whole", pulls_whole},   {"vanished", pulls_vanished},
                     {"resumed", pulls_resumed},      {"stalled_beside", pulls_stalled}, {"failed", pulls_failed},
                     {"final_files_differing", wrong_final_files}};
  report["store_bytes_equal"] = store_equal_always;
  report["sets_bytes_listed"] = last_sets_bytes;
  report["sets_bytes_on_disk"] = last_disk_bytes;
  report["rss_kb"] = rss;
  report["fds"] = fds;
  report["threads"] = threads;
  report["store_bytes"] = store_bytes;
  if (rss.size() >= 100) {
    const double at100 = rss[99].get<double>(), last = rss.back().get<double>();
    report["rss_kb_after_100"] = at100;
    report["rss_kb_after_last"] = last;
    report["rss_growth_after_100_pct"] = 100.0 * (last - at100) / at100;
  }
  auto range = [](const json& a) {
    std::vector<double> v;
    for (const auto& x : a) v.push_back(x.get<double>());
    if (v.empty()) return json::array();
    return json::array({*std::min_element(v.begin(), v.end()), *std::max_element(v.begin(), v.end())});
  };
  report["fds_min_max"] = range(fds);
  report["threads_min_max"] = range(threads);
  report["faults"] = plan->spec();
  report["faults_injected"] = injected;
  report["frame_size"] = size;
  report["seconds"] = seconds;
  report["seconds_waiting_for_ready"] = waited_s;
  report["problems"] = problems;
  std::ofstream(out / "report.json") << report.dump(1) << "\n";
  plot(report, out / "soak.png");
  fs::remove_all(pulls, ec);

  int named_total = 0;
  for (const auto& [name, n] : refused) named_total += n;
  const bool held = half_sets == 0 && leftovers == 0 && restarts == 0 && refused.count("unnamed") == 0 &&
                    stored + named_total == captures && store_equal_always && wrong_final_files == 0 &&
                    pulls_failed == 0;
  std::fprintf(stderr, "veneer_soak: %d captures: %d stored, %d refused; %d half sets, %d leftover temporaries, %d "
               "restarts; %d pulls (%d whole); %.0f s; %s\n",
               captures, stored, named_total, half_sets, leftovers, restarts, pulls_asked, pulls_whole, seconds,
               held ? "every invariant held" : "AN INVARIANT FAILED");
  return held ? 0 : 1;
}
