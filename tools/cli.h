// tools/cli.h — the hashcc command line (one binary, subcommands).
#pragma once
#include <atomic>
#include <functional>
#include <string>
#include <vector>

namespace CLI { class App; }
namespace hashcc {
// Parses argv and runs a subcommand. Returns the process exit status: 0 ok, 2 bad input
// (one-line message naming the file/flag and the problem), 1 internal failure.
int run_cli(int argc, char** argv);

// Thrown by a subcommand that stopped on SIGINT/SIGTERM after saving its state (exit 130).
struct Interrupted {};

// This process's command line as run_cli received it (argv[0] as its file name, "hashcc"):
// train, eval and render record it in RUN/commands.txt for the run report (tools/run_report.h).
const std::vector<std::string>& command_args();

// `hashcc train --help-all`: the command's help with the options --help leaves out (each still
// works, and --set KEY=VALUE reaches every config.json key). run_cli reads it from argv.
bool help_all();

// While alive, SIGINT and SIGTERM set flag() instead of killing the process, so long jobs
// finish their step and write a checkpoint. Restores the default handlers when destroyed.
class StopSignals {
 public:
  StopSignals();
  ~StopSignals();
  const std::atomic<bool>& flag() const;
};

// Subcommands defined in tools/cmd_<name>.cpp. Each registers its flags on app and, when
// chosen, sets run to the job.
void add_train_command(CLI::App& app, std::function<void()>& run);
void add_bench_command(CLI::App& app, std::function<void()>& run);  // tools/cmd_bench.cpp
void add_render_command(CLI::App& app, std::function<void()>& run);
void add_export_command(CLI::App& app, std::function<void()>& run);
void add_eval_command(CLI::App& app, std::function<void()>& run);
void add_step_command(CLI::App& app, std::function<void()>& run);  // tools/cmd_step.cpp
void add_study_command(CLI::App& app, std::function<void()>& run);  // tools/cmd_study.cpp
void add_report_command(CLI::App& app, std::function<void()>& run);  // tools/cmd_report.cpp
}  // namespace hashcc
