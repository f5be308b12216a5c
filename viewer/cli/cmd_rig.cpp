// veneer rig find|status|capture|press|list|pull|delete|lamps|live|events — the
// rig client for scripts and tests, against --rig host:port --token-file F
// (`find` lists the rigs on the LAN through DNS-SD and needs neither).
// The connection is TLS 1.3 with the rig's certificate pinned by fingerprint:
// --fingerprint, else the known-rigs file, else a first use asks (stdin).
#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <mutex>
#include <optional>

#include <unistd.h>

#include "veneer/io/codecs.hpp"
#include <opencv2/imgproc.hpp>
#include <sstream>

#include "command.hpp"
#include "output.hpp"
#include "veneer/io/image_io.hpp"
#include "veneer/pipeline/transfer.hpp"
#include "veneer/repaint/live.hpp"
#include "veneer/repaint/live_session.hpp"
#include "veneer/repaint/track.hpp"
#include "veneer/proto/tls.hpp"
#include "veneer/rig/client.hpp"

namespace veneer::cli {
namespace {

struct RigArgs {
  std::string rig = "127.0.0.1:7878";
  std::string token_file = "veneer-sets/token";
  double timeout_s = 120;
  std::string fingerprint;  // --fingerprint: the rig's certificate must have it
  std::string known_rigs;   // --known-rigs: empty = tls::default_known_rigs_file()
  bool plain_tcp = false;   // --plain-tcp
};

// First use of a rig (no --fingerprint, none known): the fingerprint is shown
// and the answer read from stdin, a terminal or not ("yes"/"y", or the
// fingerprint itself, pins it; anything else, or nothing, refuses).
bool ask_to_pin(const std::string& rig, const std::string& seen) {
  const bool terminal = ::isatty(0) == 1;
  std::cerr << "The rig at " << rig << " presents a certificate not seen before, fingerprint (SHA-256)\n  " << seen
            << "\nCompare it with what `veneerd --fingerprint` prints on the rig (or its log).\n"
            << "Pin it and connect? [yes/no" << (terminal ? "" : ", read from standard input") << "] " << std::flush;
  std::string answer;
  if (!std::getline(std::cin, answer)) {
    std::cerr << "(no answer)\n";
    return false;
  }
  if (!terminal) std::cerr << answer << "\n";
  const char* space = " \t\r\n";
  const auto first = answer.find_first_not_of(space);
  answer = first == std::string::npos ? "" : answer.substr(first, answer.find_last_not_of(space) - first + 1);
  std::string lower;
  for (char c : answer) lower += static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (lower == "y" || lower == "yes") return true;
  auto fp = tls::parse_fingerprint(answer);
  return fp && *fp == seen;
}

// Errors as every command reports them (output.hpp): "veneer rig <cmd>: <what>".
int fail(const std::string& cmd, const std::string& what, int code = 1) {
  const Output out(cmd.empty() ? "rig" : "rig " + cmd);
  return code == 2 ? out.usage(what) : out.fail(what);
}

Expected<std::unique_ptr<rig::Client>> open_rig(const RigArgs& a) {
  auto endpoint = rig::Endpoint::parse(a.rig);
  if (!endpoint) return endpoint.error();
  auto token = rig::read_token_file(a.token_file);
  if (!token) return token.error();
  rig::ConnectOptions o;
  o.client_name = "veneer-cli";
  o.request_timeout_s = 30;
  o.plain_tcp = a.plain_tcp;
  if (!a.fingerprint.empty()) {
    auto fp = tls::parse_fingerprint(a.fingerprint);
    if (!fp) return make_error("--fingerprint: " + fp.message());
    o.fingerprint = *fp;
  }
  o.known_rigs = a.known_rigs.empty() ? tls::default_known_rigs_file() : std::filesystem::path(a.known_rigs);
  o.trust_loopback = false;  // a person runs this: the rig is pinned wherever it is
  o.confirm_first_use = ask_to_pin;
  return rig::Client::connect(*endpoint, *token, o);
}

std::string human_bytes(uint64_t b) {
  char buf[32];
  if (b >= (1ull << 30)) std::snprintf(buf, sizeof buf, "%.1f GiB", b / 1073741824.0);
  else if (b >= (1ull << 20)) std::snprintf(buf, sizeof buf, "%.1f MiB", b / 1048576.0);
  else std::snprintf(buf, sizeof buf, "%.0f KiB", b / 1024.0);
  return buf;
}

// Waits for the outcome of capture `id`, printing progress events on stderr.
int await_capture(const std::string& cmd, rig::Client& client, const std::string& id, double timeout_s) {
  auto outcome = client.wait_event(
      [&](const rig::Event& e) {
        if (e.set_id != id) return false;
        if (e.kind == rig::Event::Kind::shot_taken || e.kind == rig::Event::Kind::capture_started) {
          std::cerr << rig::describe(e) << "\n";
          return false;
        }
        return e.kind == rig::Event::Kind::set_stored || e.kind == rig::Event::Kind::capture_failed;
      },
      timeout_s);
  if (!outcome) return fail(cmd, outcome.message());
  if (outcome->kind == rig::Event::Kind::capture_failed) {
    return fail(cmd, outcome->cancelled ? "capture " + id + " cancelled" : "capture " + id + " failed: " + outcome->reason);
  }
  for (const auto& w : outcome->warnings) std::cerr << "warning: " << w << "\n";
  std::cout << id << "\n";
  return 0;
}

Expected<std::vector<bool>> parse_lamps(const std::string& text, int count) {
  std::vector<bool> on(std::max(count, 0), false);
  if (text.empty() || text == "none") return on;
  if (text == "all") return std::vector<bool>(std::max(count, 0), true);
  std::istringstream in(text);
  std::string item;
  while (std::getline(in, item, ',')) {
    int i = 0;
    try {
      size_t used = 0;
      i = std::stoi(item, &used);
      if (used != item.size()) throw std::invalid_argument(item);
    } catch (const std::exception&) {
      return make_error("--on: '" + item + "' is not a lamp number");
    }
    if (i < 1 || i > count) return make_error("--on: lamp " + item + " does not exist (lamps 1.." + std::to_string(count) + ")");
    on[i - 1] = true;
  }
  return on;
}

}  // namespace
}  // namespace veneer::cli

VENEER_COMMAND(rig) {
  using namespace veneer;
  using namespace veneer::cli;
  auto* rig_cmd = app.add_subcommand("rig", "talk to a capture rig (veneerd): status, capture, pull sets, lamps, live view");
  rig_cmd->require_subcommand(1);
  rig_cmd->fallthrough();
  auto args = std::make_shared<RigArgs>();
  rig_cmd->add_option("--rig", args->rig, "rig address host:port")->capture_default_str();
  rig_cmd->add_option("--token-file", args->token_file, "the rig's access token file (<store>/token on the rig)")
      ->capture_default_str();
  rig_cmd->add_option("--timeout", args->timeout_s, "seconds to wait for a capture or download")->capture_default_str();
  rig_cmd->add_option("--fingerprint", args->fingerprint,
                      "the rig's certificate fingerprint (SHA-256, 64 hex digits, ':' optional; `veneerd "
                      "--fingerprint` prints it): anything else is refused; pinned in the known-rigs file");
  rig_cmd->add_option("--known-rigs", args->known_rigs,
                      "file of pinned rig fingerprints (default $VENEER_KNOWN_RIGS, else "
                      "$XDG_CONFIG_HOME/veneer/known_rigs, else ~/.config/veneer/known_rigs)");
  rig_cmd->add_flag("--plain-tcp", args->plain_tcp,
                    "connect without TLS (only to a rig configured --plain-tcp; the token and photos cross the "
                    "network in clear)");

  auto* find = rig_cmd->add_subcommand("find", "list the rigs on the LAN (DNS-SD _veneer._tcp, through avahi-daemon)");
  auto find_wait = std::make_shared<double>(2.0);
  find->add_option("--wait", *find_wait, "seconds to listen for rigs")->capture_default_str()->check(CLI::Range(0.1, 60.0));

  auto* status = rig_cmd->add_subcommand("status", "the rig's state");
  auto* list = rig_cmd->add_subcommand("list", "stored sets, one a line, id first");

  auto* capture = rig_cmd->add_subcommand("capture", "capture a set and wait until it is stored (prints its id)");
  auto copts = std::make_shared<rig::CaptureOptions>();
  auto role = std::make_shared<std::string>();
  auto no_wait = std::make_shared<bool>(false);
  capture->add_option("--role", *role, "destination or source (default: the rig's next)");
  capture->add_option("--object", copts->object, "object name");
  capture->add_option("--shutter", copts->shutter_s, "shutter time [s]");
  capture->add_option("--aperture", copts->aperture, "f-number");
  capture->add_option("--iso", copts->iso, "ISO");
  capture->add_flag("--no-wait", *no_wait, "return once the capture started");

  auto* press = rig_cmd->add_subcommand("press", "press the capture button (simulated rig)");
  auto long_press = std::make_shared<bool>(false);
  auto press_wait = std::make_shared<bool>(false);
  press->add_flag("--long", *long_press, "a long press (cancels a running capture)");
  press->add_flag("--wait", *press_wait, "wait until the capture it starts is stored (prints the set id)");

  auto* cancel = rig_cmd->add_subcommand("cancel", "cancel the running capture");

  auto* pull = rig_cmd->add_subcommand("pull", "download a set as a veneer-set/1 folder");
  auto set_id = std::make_shared<std::string>();
  auto out = std::make_shared<std::string>();
  auto truth = std::make_shared<bool>(false);
  auto no_truth = std::make_shared<bool>(false);
  auto force = std::make_shared<bool>(false);
  pull->add_option("SET", *set_id, "set id (see `veneer rig list`)")->required();
  pull->add_option("--out", *out, "folder to create")->required();
  pull->add_flag("--truth", *truth, "also pull truth/ of simulated sets (for tests and quality measures)");
  pull->add_flag("--no-truth", *no_truth, "leave out truth/ of simulated sets (the default)");
  pull->add_flag("--force", *force, "replace --out if it exists");
  auto live_first = std::make_shared<bool>(false);
  auto preview_only = std::make_shared<bool>(false);
  pull->add_flag("--live-first", *live_first,
                 "first the preview set (a reduced JPEG per lamp, set.json marked preview_of; its folder is printed "
                 "as \"preview: <folder>\" once in place), then the full files, which replace it in place "
                 "atomically");
  pull->add_flag("--preview", *preview_only, "only the preview set (see --live-first)");

  auto* del = rig_cmd->add_subcommand("delete", "delete a stored set");
  auto del_id = std::make_shared<std::string>();
  del->add_option("SET", *del_id, "set id")->required();

  auto* lamps = rig_cmd->add_subcommand("lamps", "switch lamps: --on 1,3 | all | none");
  auto lamps_on = std::make_shared<std::string>();
  auto brightness = std::make_shared<int>(254);
  lamps->add_option("--on", *lamps_on, "lamps to switch on (1-based ring positions), 'all' or 'none'")->required();
  lamps->add_option("--brightness", *brightness, "1..254")->capture_default_str()->check(CLI::Range(1, 254));

  auto* live = rig_cmd->add_subcommand("live", "save live-view frames as JPEG files");
  auto frames = std::make_shared<int>(10);
  auto fps = std::make_shared<double>(10);
  auto live_out = std::make_shared<std::string>();
  live->add_option("--frames", *frames, "how many frames")->capture_default_str()->check(CLI::Range(1, 100000));
  live->add_option("--fps", *fps, "frames per second asked for")->capture_default_str()->check(CLI::Range(0.1, 60.0));
  live->add_option("--out", *live_out, "folder for frame_NNNN.jpg")->required();
  auto live_map = std::make_shared<std::string>();
  auto live_src = std::make_shared<std::string>();
  auto live_dst = std::make_shared<std::string>();
  auto live_sweep = std::make_shared<bool>(false);
  live->add_option("--map", *live_map, "also write repainted_NNNN.png: each frame carried through this map (a transfer folder or map.pfm)");
  auto live_blend = std::make_shared<int>(0);
  auto live_guide = std::make_shared<double>(0);
  live->add_option("--src", *live_src, "with --map: the source set the map was computed against (its size and mask)");
  live->add_option("--dst", *live_dst,
                   "with --map: the destination set (its picture shows where nothing is mapped; its normals guide the "
                   "blend)");
  auto* blend_opt = live->add_option("--blend", *live_blend,
                                     "with --map: blend the chunks' seams over this radius, 0..16 px (default: as the "
                                     "transfer folder's metrics.json says, else 2)")
                        ->check(CLI::Range(0, 16));
  auto* guide_opt = live->add_option("--blend-guide", *live_guide,
                                     "with --map: the blend's normal fall-off |dn|, 0..2 (0 = plain; default: as "
                                     "metrics.json says, else 0.1; needs --dst)")
                        ->check(CLI::Range(0.0, 2.0));
  live->add_flag("--sweep", *live_sweep, "simulated rig: move the hand-held lamp round the source while recording");
  auto live_look = std::make_shared<std::string>("shaded");
  auto* live_look_opt = live->add_option("--look", *live_look,
                   "with --map: shaded (each frame painted as the still look at the light estimated in it; needs "
                   "--dst, the default when it is given) | copy (the frame's pixels copied through the map)");
  auto live_no_track = std::make_shared<bool>(false);
  live->add_flag("--no-track", *live_no_track,
                 "with --map: look frames up at the stills' pose (the old live view) instead of registering each "
                 "frame to the source's stills (as `veneer repaint --video` does; then also align_NNNN.png with the "
                 "outline, and each frame's state printed)");

  auto* events = rig_cmd->add_subcommand("events", "print the rig's events, one a line");
  auto count = std::make_shared<int>(0);
  events->add_option("--count", *count, "stop after this many (0 = until --timeout)");

  return [=]() -> int {
    if (find->parsed()) {
      auto rigs = rig::find_rigs(static_cast<int>(*find_wait * 1000));
      if (!rigs) return fail("find", rigs.message() + "; connect with --rig host:port instead");
      if (rigs->empty()) {
        char wait[32];
        std::snprintf(wait, sizeof wait, "%.1f", *find_wait);
        return fail("find", std::string("no rig answered on the LAN within ") + wait +
                                " s (is veneerd running with --listen beyond 127.0.0.1?)");
      }
      for (const auto& r : *rigs) std::cout << r.describe() << "\n";
      return 0;
    }
    auto client_or = open_rig(*args);
    std::string which = rig_cmd->get_subcommands().empty() ? "" : rig_cmd->get_subcommands().front()->get_name();
    if (!client_or) return fail(which, client_or.message());
    rig::Client& client = **client_or;

    if (status->parsed()) {
      auto s = client.status();
      if (!s) return fail("status", s.message());
      std::cout << "rig:        " << s->name << (s->simulated ? " (simulated)" : "")
                << (s->ready ? ", ready" : ", NOT READY") << "\n"
                << "camera:     " << (s->camera_connected ? s->camera_model : "not connected") << "\n"
                << "lamps:      " << s->lamp_count << " (on: ";
      bool any = false;
      for (size_t i = 0; i < s->lamps_on.size(); ++i) {
        if (s->lamps_on[i]) std::cout << (any ? "," : "") << i + 1, any = true;
      }
      std::cout << (any ? "" : "none");
      if (s->lamps_age_s >= 0) {
        char age[32];
        std::snprintf(age, sizeof age, "%.1f", s->lamps_age_s);
        std::cout << ", as the bridge reported " << age << " s ago";
      }
      std::cout << ")" << (s->holds_lamps ? ", held by the rig until it exits" : "") << "\n";
      if (!s->lamps_problem.empty()) std::cout << "  problem:  " << s->lamps_problem << "\n";
      for (size_t i = 0; i < s->lamps.size(); ++i) {
        const auto& l = s->lamps[i];
        std::cout << "  " << i + 1 << " (Hue " << l.id << "): ";
        if (!l.reachable) std::cout << "unreachable, ";
        if (!l.on) {
          std::cout << "off\n";
          continue;
        }
        std::cout << "on, bri " << l.brightness << ", ";
        char colour[64];
        if (l.colour_mode == "ct") std::snprintf(colour, sizeof colour, "ct %d mired", l.ct);
        else if (l.colour_mode == "hs") std::snprintf(colour, sizeof colour, "hue %d sat %d", l.hue, l.sat);
        else std::snprintf(colour, sizeof colour, "xy %.4f %.4f", l.x, l.y);
        std::cout << colour << "\n";
      }
      std::cout
                << "capturing:  " << (s->capturing ? "yes" : "no") << "\n"
                << "next press: " << io::role_name(s->next_role) << "\n"
                << "sets:       " << s->sets_stored << " stored, " << human_bytes(s->free_bytes) << " free\n"
                << "clients:    " << s->clients << (s->controller_taken ? ", one controls the rig" : "") << "\n"
                << "connection: "
                << (s->plain_tcp ? "PLAIN TCP (the rig is configured so): not encrypted"
                                 : "TLS 1.3, certificate fingerprint " + client.fingerprint())
                << "\n";
      return 0;
    }
    if (list->parsed()) {
      auto sets = client.list_sets();
      if (!sets) return fail("list", sets.message());
      for (const auto& s : *sets) {
        std::cout << s.id << "  " << io::role_name(s.role) << "  " << s.object << "  " << s.created << "  " << s.size.width
                  << "x" << s.size.height << "  " << s.lights << " lights  " << human_bytes(s.bytes)
                  << (s.has_truth ? "  truth" : "") << (s.warnings.empty() ? "" : "  WARNING: " + s.warnings.front())
                  << "\n";
      }
      return 0;
    }
    if (capture->parsed()) {
      rig::CaptureOptions o = *copts;
      if (!role->empty()) {
        auto r = io::parse_role(*role);
        if (!r || *r == io::Role::unknown) return fail("capture", "--role '" + *role + "': expected destination or source", 2);
        o.role = *r;
      }
      auto id = client.capture(o);
      if (!id) return fail("capture", id.message());
      if (*no_wait) {
        std::cout << *id << "\n";
        return 0;
      }
      return await_capture("capture", client, *id, args->timeout_s);
    }
    if (press->parsed()) {
      if (auto s = client.press_button(*long_press); !s) return fail("press", s.message());
      if (!*press_wait || *long_press) return 0;
      auto started = client.wait_event(
          [](const rig::Event& e) {
            return e.kind == rig::Event::Kind::capture_started || e.kind == rig::Event::Kind::capture_failed;
          },
          30);
      if (!started) return fail("press", started.message());
      if (started->kind == rig::Event::Kind::capture_failed) return fail("press", "capture failed: " + started->reason);
      std::cerr << rig::describe(*started) << "\n";
      return await_capture("press", client, started->set_id, args->timeout_s);
    }
    if (cancel->parsed()) {
      if (auto s = client.cancel_capture(); !s) return fail("cancel", s.message());
      return 0;
    }
    if (pull->parsed()) {
      ProgressBar bar("pull " + *set_id);
      Progress progress;
      progress.on_progress = [&bar](double f, const std::string& stage) { bar.update(f, stage); };
      if (*preview_only) {
        if (auto s = client.pull_preview(*set_id, *out, *force, progress); !s) return fail("pull", s.message());
        bar.done();
        std::cout << *out << "\n";
        return 0;
      }
      rig::PullOptions o;
      o.include_truth = *truth && !*no_truth;
      o.overwrite = *force;
      o.live_first = *live_first;
      o.on_preview = [](const std::filesystem::path& f) { std::cout << "preview: " << f.string() << std::endl; };
      if (auto s = client.pull_set(*set_id, *out, o, progress); !s) return fail("pull", s.message());
      bar.done();
      std::cout << *out << "\n";
      return 0;
    }
    if (del->parsed()) {
      if (auto s = client.delete_set(*del_id); !s) return fail("delete", s.message());
      return 0;
    }
    if (lamps->parsed()) {
      auto on = parse_lamps(*lamps_on, client.hello_status().lamp_count);
      if (!on) return fail("lamps", on.message(), 2);
      if (auto s = client.set_lamps(*on, *brightness); !s) return fail("lamps", s.message());
      return 0;
    }
    if (live->parsed()) {
      // With --map, frames are repainted onto the destination as they would be in the viewer.
      std::optional<repaint::LiveRepainter> repainter;
      std::optional<repaint::LiveSession> session;  // with tracking (the default)
      cv::Mat still_mask;
      int tracked = 0, lost = 0;
      std::vector<double> frame_ms;
      if (!live_map->empty()) {
        if (live_src->empty()) return fail("live", "--map needs --src (the source set the map was computed against)", 2);
        std::filesystem::path mp(*live_map);
        if (std::filesystem::is_directory(mp)) mp /= "map.pfm";
        auto map = match::read_map(mp);
        if (!map) return fail("live", map.message());
        // The frames are repainted as the transfer's pictures were: its
        // options (scale, feature, blend) from the folder's metrics.json.
        pipeline::TransferOptions options;
        const std::filesystem::path metrics = mp.parent_path() / "metrics.json";
        if (std::filesystem::exists(metrics)) {
          auto read = pipeline::read_transfer_options(metrics);
          if (!read) return fail("live", read.message());
          options = *read;
        }
        if (blend_opt->count()) options.blend = *live_blend;
        if (guide_opt->count()) options.blend_guide = *live_guide;
        if (live_dst->empty() && options.blend > 0 && options.blend_guide > 0) {
          if (guide_opt->count()) return fail("live", "--blend-guide needs --dst (the destination's normals)", 2);
          options.blend_guide = 0;  // no destination normals: the plain blend
        }
        auto src = io::read_set(*live_src);
        if (!src) return fail("live", src.message());
        std::optional<io::ImageSet> dst;
        cv::Mat backdrop;
        if (!live_dst->empty()) {
          auto d = io::read_set(*live_dst);
          if (!d) return fail("live", d.message());
          backdrop = io::tonemap_picture(repaint::lit_photo(d->images));
          // a bare map.pfm: its scale from its width against the destination's
          if (!std::filesystem::exists(metrics)) options.scale = pipeline::map_scale(*map, *d);
          dst = std::move(*d);
        }
        std::shared_ptr<const match::fast::BlendPlan> plan;
        if (options.blend > 0) {
          std::cout << "preparing the blend (" << options.blend << " px, "
                    << (options.blend_guide > 0 ? "guided by the normals" : "plain") << ") ..." << std::endl;
          Expected<std::shared_ptr<const match::fast::BlendPlan>> made = std::shared_ptr<const match::fast::BlendPlan>();
          if (dst) {
            auto pair = pipeline::prepare_pair(*dst, *src, options);
            if (!pair) return fail("live", pair.message());
            made = pipeline::blend_plan_for(*pair, options, *map);
          } else {  // no destination normals: the plain blend, over the source's mask as the map saw it
            io::ImageSet source = *src;
            match::scale_set(source, options.scale);
            auto mask = match::object_mask(source, options.truth_normals);
            if (!mask) return fail("live", "source: " + mask.message());
            auto plain = match::fast::blend_plan(*map, {}, *mask, options.blend);
            if (plain) made = std::make_shared<const match::fast::BlendPlan>(std::move(*plain));
            else made = plain.error();
          }
          if (!made) return fail("live", made.message());
          plan = *made;
        }
        // the source's size as the map saw it (scaled like the transfer's)
        repainter.emplace(*map, match::scaled_size(src->size, options.scale), backdrop, plan);
        auto look = repaint::parse_look(*live_look);
        if (!look) return fail("live", "--look: " + look.message(), 2);
        std::shared_ptr<const repaint::LiveLook> shaded;
        if (*look == repaint::Look::shaded && dst && !*live_no_track) {
          // the still look of this map, and what each frame is painted with at its light
          std::cout << "preparing the shaded look ..." << std::endl;
          auto pair = pipeline::prepare_pair(*dst, *src, options);
          if (!pair) return fail("live", pair.message());
          auto made = pipeline::live_look(*pair, options, *map);
          if (!made) return fail("live", "the shaded look: " + made.message());
          shaded = *made;
        } else if (*look == repaint::Look::shaded && live_look_opt->count()) {
          return fail("live", "--look shaded needs --dst (the destination's photos and normals) and tracking", 2);
        }
        if (!*live_no_track) {
          auto mask = match::object_mask(*src, false);
          if (!mask) return fail("live", "source: " + mask.message());
          still_mask = *mask;
          if (still_mask.size() != src->size) cv::resize(still_mask, still_mask, src->size, 0, 0, cv::INTER_NEAREST);
          session.emplace(src->images, still_mask, *map, match::scaled_size(src->size, options.scale), shaded, backdrop,
                          plan);
          session->set_look(shaded ? repaint::Look::shaded : repaint::Look::copy);
        }
      }
      std::error_code ec;
      std::filesystem::create_directories(*live_out, ec);
      if (ec) return fail("live", *live_out + ": cannot create: " + ec.message());
      std::mutex m;
      std::condition_variable cv;
      int saved = 0;
      std::string error;
      client.on_live_frame = [&](const rig::LiveFrame& f) {
        std::lock_guard lock(m);
        if (saved >= *frames || !error.empty()) return;
        char name[32];
        std::snprintf(name, sizeof name, "frame_%04d.jpg", saved);
        std::ofstream file(std::filesystem::path(*live_out) / name, std::ios::binary);
        file.write(reinterpret_cast<const char*>(f.jpeg.data()), static_cast<std::streamsize>(f.jpeg.size()));
        if (!file) error = std::string(name) + ": write failed";
        if (repainter && error.empty()) {
          const cv::Mat frame = veneer::io::codecs::imdecode(f.jpeg, cv::IMREAD_COLOR);
          std::snprintf(name, sizeof name, "repainted_%04d.png", saved);
          if (frame.empty()) {
            error = "frame " + std::to_string(f.seq) + " is not a JPEG";
          } else if (session) {
            // registered to the stills first, as `veneer repaint --video` does
            auto lf = session->process(frame);
            if (!lf) {
              error = "frame " + std::to_string(saved) + ": " + lf.message();
            } else {
              if (saved == 0 && !session->geometry()->same)
                std::cout << "live view: " << session->geometry()->describe() << "\n";
              repaint::TrackResult r;
              r.lost = lf->lost;
              r.correlation = lf->quality;
              r.still_to_frame = lf->still_to_frame;
              (lf->lost ? lost : tracked) += 1;
              frame_ms.push_back(lf->track_ms + lf->repaint_ms);
              cv::Point2f centre(0, 0);
              for (const auto& p : lf->outline) centre += p / static_cast<float>(lf->outline.size());
              std::printf("frame %d: %s, ECC %.3f, outline of %zu points about (%.1f, %.1f) px, %.1f ms track + "
                          "%.1f ms repaint (%s)\n",
                          saved, lf->lost ? "LOST - hold still / recapture" : "tracked", lf->quality,
                          lf->outline.size(), centre.x, centre.y, lf->track_ms, lf->repaint_ms,
                          repaint::look_name(lf->look));
              if (lf->light) {
                const auto& l = *lf->light;
                std::printf("  light (%.3f, %.3f, %.3f), intensity %.3f, ambient %.4f, residual %.3f%s%s\n",
                            l.direction[0], l.direction[1], l.direction[2], l.intensity, l.ambient, l.residual,
                            l.explained ? "" : ", one lamp does not explain it: ", l.fallback.c_str());
              }
              std::fflush(stdout);
              char align[32];
              std::snprintf(align, sizeof align, "align_%04d.png", saved);
              if (!veneer::io::codecs::imwrite((std::filesystem::path(*live_out) / name).string(), lf->repainted) ||
                  !veneer::io::codecs::imwrite((std::filesystem::path(*live_out) / align).string(),
                               repaint::alignment_picture(frame, still_mask, r)))
                error = std::string(name) + ": write failed";
            }
          } else if (!veneer::io::codecs::imwrite((std::filesystem::path(*live_out) / name).string(), repainter->apply(frame))) {
            error = std::string(name) + ": write failed";
          }
        }
        ++saved;
        cv.notify_all();
      };
      if (auto s = client.start_live_view(*fps); !s) return fail("live", s.message());
      bool done = false;
      const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(args->timeout_s);
      for (int step = 0; !done && std::chrono::steady_clock::now() < deadline; ++step) {
        if (*live_sweep) {
          // The hand-held lamp goes round the source once over the recording.
          const double a = 2 * M_PI * step / std::max(1, *frames);
          (void)client.move_hand_lamp(cv::Vec3d(0.45 * std::cos(a), 0.45 * std::sin(a), 0.55));
        }
        std::unique_lock lock(m);
        done = cv.wait_for(lock, std::chrono::duration<double>(1.0 / *fps),
                           [&] { return saved >= *frames || !error.empty() || !client.connected(); });
      }
      (void)client.stop_live_view();
      client.on_live_frame = nullptr;
      if (!error.empty()) return fail("live", error);
      if (!done || saved < *frames) return fail("live", "got " + std::to_string(saved) + " of " + std::to_string(*frames) + " frames");
      std::cout << saved << " frames in " << *live_out;
      if (session) {
        std::sort(frame_ms.begin(), frame_ms.end());
        std::cout << " (" << tracked << " tracked, " << lost << " lost; "
                  << (frame_ms.empty() ? 0.0 : frame_ms[frame_ms.size() / 2]) << " ms per frame median)";
      }
      std::cout << "\n";
      return 0;
    }
    if (events->parsed()) {
      int seen = 0;
      auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(args->timeout_s);
      while (*count == 0 || seen < *count) {
        double left = std::chrono::duration<double>(deadline - std::chrono::steady_clock::now()).count();
        if (left <= 0) break;
        auto e = client.wait_event([](const rig::Event&) { return true; }, left);
        if (!e) break;
        std::cout << rig::describe(*e) << std::endl;
        ++seen;
      }
      return *count == 0 || seen >= *count ? 0 : fail("events", "got " + std::to_string(seen) + " of " + std::to_string(*count) + " events");
    }
    return fail("", "no rig command given", 2);
  };
}
