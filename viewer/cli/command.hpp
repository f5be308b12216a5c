#pragma once
// Sub-commands of `veneer`. Each cmd_<name>.cpp defines one with its
// options filling an arguments struct,
//   VENEER_ARGS_COMMAND(simulate, SimulateArgs, "what it does") {
//     cmd->add_option("--out", args->out, "...");  // cmd: CLI::App*, args: shared_ptr<SimulateArgs>
//     return [args] { return run(*args); };
//   }
// or one (or a group) set up by hand with
//   VENEER_COMMAND(rig) { auto* cmd = app.add_subcommand("rig", "..."); ...; return [=] { ... }; }
// The returned function runs when the sub-command was chosen and gives the
// exit code (0 ok, 1 failure, 2 bad usage). Every command reports through
// output.hpp: errors as one line on stderr "veneer <cmd>: <what was wrong>",
// the files it writes, and its closing summary on stdout.
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

namespace veneer::cli {

using Runner = std::function<int()>;
using Setup = std::function<Runner(CLI::App& app)>;

struct CommandRegistry {
  static std::vector<std::pair<std::string, Setup>>& all() {
    static std::vector<std::pair<std::string, Setup>> v;
    return v;
  }
};

struct CommandRegistrar {
  CommandRegistrar(const char* name, Setup setup) { CommandRegistry::all().emplace_back(name, std::move(setup)); }
};

// A progress bar on stderr for slow steps (only when stderr is a terminal
// unless forced).
class ProgressBar {
 public:
  explicit ProgressBar(std::string label);
  ~ProgressBar();
  void update(double fraction, const std::string& stage);
  void done();

 private:
  std::string label_;
  int last_percent_ = -1;
  bool tty_ = false;
  bool finished_ = false;
};

}  // namespace veneer::cli

#define VENEER_COMMAND(name)                                                     \
  static ::veneer::cli::Runner veneer_setup_##name(CLI::App& app);               \
  static ::veneer::cli::CommandRegistrar veneer_registrar_##name(#name, veneer_setup_##name); \
  static ::veneer::cli::Runner veneer_setup_##name(CLI::App& app)

// The sub-command `name` described by `description`, with a fresh `Args` its
// options fill in: the body sees `cmd` (CLI::App*) and `args`.
#define VENEER_ARGS_COMMAND(name, Args, description)                                                      \
  static ::veneer::cli::Runner veneer_setup_##name(CLI::App* cmd, const std::shared_ptr<Args>& args);     \
  static ::veneer::cli::CommandRegistrar veneer_registrar_##name(#name, [](CLI::App& app) {                 \
    return veneer_setup_##name(app.add_subcommand(#name, description), std::make_shared<Args>());          \
  });                                                                                                      \
  static ::veneer::cli::Runner veneer_setup_##name(CLI::App* cmd, const std::shared_ptr<Args>& args)
