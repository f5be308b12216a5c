// `veneerd ptpip-twin`: a PTP/IP camera on the network, rendering the
// simulated scene under the lamps the Hue bridge reports on.
#include <csignal>
#include <ostream>
#include <sstream>
#include <thread>

#include <pthread.h>
#include <signal.h>

#include "veneer/util/log.hpp"
#include "veneerd/sim/ptpip_twin.hpp"
#include "veneerd/sim/simulated_camera.hpp"

namespace veneerd {


int ptpip_twin_command(const std::vector<std::string>& args, std::ostream& out, std::ostream& err) {
  const char* usage =
      "usage: veneerd ptpip-twin --bridge HOST:PORT --key KEY --lamps ID,ID,... [--scene NAME]\n"
      "                          [--size WxH] [--listen HOST:PORT]\n"
      "A PTP/IP camera on the network for libgphoto2 (and veneerd's gphoto2 camera with\n"
      "\"port\": \"ptpip:HOST:PORT\"): each shot renders the simulated scene lit by the lamps\n"
      "the Hue bridge reports on (lamps in ring order). Live view through PTP streams.\n"
      "  --bridge   the Hue bridge (or emulator), host:port\n"
      "  --key      its user key\n"
      "  --lamps    Hue light ids in ring order, comma-separated\n"
      "  --scene    simulator scene (default bull)\n"
      "  --size     still and live-view size (default 1024x680)\n"
      "  --listen   IPv4 address and port to serve on (default 127.0.0.1:15740)\n"
      "Runs until SIGINT or SIGTERM.\n";
  nlohmann::json section = {{"scene", "bull"}};
  std::string listen = "127.0.0.1:15740";
  for (size_t i = 1; i < args.size(); ++i) {
    const std::string& a = args[i];
    if (a == "--help" || a == "-h") {
      out << usage;
      return 0;
    }
    if (i + 1 >= args.size() || a.rfind("--", 0) != 0) {
      err << "veneerd ptpip-twin: '" << a << "' " << (a.rfind("--", 0) == 0 ? "needs a value" : "is not an option")
          << "\n" << usage;
      return 2;
    }
    const std::string& v = args[++i];
    if (a == "--bridge") section["bridge"] = v;
    else if (a == "--key") section["key"] = v;
    else if (a == "--scene") section["scene"] = v;
    else if (a == "--listen") listen = v;
    else if (a == "--lamps") {
      nlohmann::json ids = nlohmann::json::array();
      std::stringstream in(v);
      for (std::string id; std::getline(in, id, ',');)
        if (!id.empty()) ids.push_back(id);
      section["lamps"] = ids;
    } else if (a == "--size") {
      int w = 0, h = 0;
      char x = 0;
      std::stringstream in(v);
      if (!(in >> w >> x >> h) || (x != 'x' && x != 'X')) {
        err << "veneerd ptpip-twin: --size '" << v << "': expected WxH, e.g. 1024x680\n";
        return 2;
      }
      section["size"] = {w, h};
      section["preview_size"] = {w, h};
    } else {
      err << "veneerd ptpip-twin: unknown option '" << a << "'\n" << usage;
      return 2;
    }
  }
  auto sim = SimulatedCameraOptions::from_json(section);
  if (!sim) {
    err << "veneerd ptpip-twin: " << sim.message() << "\n";
    return 2;
  }
  PtpipTwinOptions o;
  size_t colon = listen.rfind(':');
  int port = colon == std::string::npos ? -1 : std::atoi(listen.c_str() + colon + 1);
  if (colon == std::string::npos || port <= 0 || port > 65535) {
    err << "veneerd ptpip-twin: --listen '" << listen << "': expected HOST:PORT, e.g. 127.0.0.1:15740\n";
    return 2;
  }
  o.host = listen.substr(0, colon);
  o.port = uint16_t(port);
  auto camera = SimulatedCamera::create(*sim);
  if (!camera) {
    err << "veneerd ptpip-twin: " << camera.message() << "\n";
    return 1;
  }
  std::shared_ptr<SimulatedCamera> renderer(std::move(*camera));
  o.shot = simulated_shot_source(renderer);
  o.preview = simulated_preview_source(renderer);
  // The twin's threads inherit this mask; the signals are taken by sigwait below.
  sigset_t stop;
  sigemptyset(&stop);
  sigaddset(&stop, SIGINT);
  sigaddset(&stop, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &stop, nullptr);
  auto twin = PtpipTwin::start(o);
  if (!twin) {
    err << "veneerd ptpip-twin: " << twin.message() << "\n";
    return 1;
  }
  out << "PTP/IP camera twin on " << o.host << ":" << (*twin)->port() << " (libgphoto2 port "
      << (*twin)->gphoto2_port() << "), scene " << sim->scene << "; Ctrl-C stops it" << std::endl;
  int sig = 0;
  sigwait(&stop, &sig);
  auto st = (*twin)->stats();
  out << "stopped: " << st.connections << " connection(s), " << st.captures << " capture(s), " << st.downloads
      << " download(s), " << st.stream_frames << " live-view frame(s)" << std::endl;
  return 0;
}

}  // namespace veneerd
