// veneer — the command line over the engine and the rig client.
#include <algorithm>
#include <cstdio>
#include <iostream>
#include <map>

#include <unistd.h>

#include "command.hpp"
#include "veneer/util/cpu_check.hpp"
#include "veneer/util/large_buffers.hpp"
#include "veneer/util/log.hpp"

namespace veneer::cli {

ProgressBar::ProgressBar(std::string label) : label_(std::move(label)), tty_(isatty(2) != 0) {}
ProgressBar::~ProgressBar() { done(); }

void ProgressBar::update(double fraction, const std::string& stage) {
  int percent = static_cast<int>(std::clamp(fraction, 0.0, 1.0) * 100.0 + 0.5);
  if (percent == last_percent_) return;
  last_percent_ = percent;
  if (!tty_) return;
  int filled = percent * 30 / 100;
  std::fprintf(stderr, "\r%s [%-30.*s] %3d%% %-24.24s", label_.c_str(), filled,
               "##############################", percent, stage.c_str());
  std::fflush(stderr);
}

void ProgressBar::done() {
  if (finished_) return;
  finished_ = true;
  if (tty_ && last_percent_ >= 0) std::fprintf(stderr, "\r%s [%s] 100%%%-26s\n", label_.c_str(),
                                               "##############################", "");
}

}  // namespace veneer::cli

int main(int argc, char** argv) {
  CLI::App app{"veneer — appearance transfer between physical objects (simulate, normals, transfer, rig)"};
  app.set_version_flag("--version", std::string("veneer ") + VENEER_VERSION);
  app.require_subcommand(1);
  std::string log_spec;
  app.add_option("--log", log_spec, "log levels, e.g. 'debug' or 'Camera=debug,Lamps=warn'");

  std::map<std::string, veneer::cli::Runner> runners;
  for (auto& [name, setup] : veneer::cli::CommandRegistry::all()) runners[name] = setup(app);

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  if (!log_spec.empty()) veneer::log::set_levels(log_spec);
  for (auto* sub : app.get_subcommands()) {
    // A command file may register several sub-commands; the runner decides.
    for (auto& [name, runner] : runners) {
      if (sub->get_name() == name) return runner();
    }
  }
  // A group registered under another name (e.g. "rig" holds its own sub-commands).
  for (auto& [name, runner] : runners) {
    if (app.got_subcommand(name)) return runner();
  }
  std::cerr << "veneer: unknown command\n";
  return 2;
}
