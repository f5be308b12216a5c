// veneer eval: quality figures of a map (against the sets' truth), or the
// quality table of the thesis pairs.
#include <filesystem>
#include <cstdio>
#include <fstream>
#include <iostream>

#include "command.hpp"
#include "inputs.hpp"
#include "output.hpp"
#include "veneer/eval/live_look.hpp"
#include "veneer/eval/metrics.hpp"
#include "veneer/eval/table.hpp"
#include "veneer/io/imageset.hpp"
#include "veneer/pipeline/transfer.hpp"

namespace veneer::cli {
namespace {

struct EvalArgs {
  std::string dst, src, map, out, live, truth;
  bool table = false, full = false, truth_normals = false, no_fast = false;
  std::string size = "512x340";
};

::veneer::cli::Output report{"eval"};

int run_table(const EvalArgs& a) {
  eval::TableOptions options;
  int w = 0, h = 0;
  if (std::sscanf(a.size.c_str(), "%dx%d", &w, &h) != 2 || w < 32 || h < 32 || w > 4096 || h > 4096)
    return report.usage("--size must be WxH (32..4096), got '" + a.size + "'");
  options.size = {w, h};
  options.full = a.full;
  options.truth_normals = a.truth_normals;
  options.include_fast = !a.no_fast;
  ProgressBar bar("quality table");
  Progress progress;
  progress.on_progress = [&bar](double f, const std::string& stage) { bar.update(f, stage); };
  auto rows = eval::quality_table(options, progress);
  bar.done();
  if (!rows) return report.fail(rows.message());
  const std::string text = eval::format_table(*rows, options);
  std::fputs(text.c_str(), stdout);
  if (!a.out.empty()) {
    if (auto s = report.text(a.out, text); !s) return report.fail(s.message());
  }
  return 0;
}

// --live: a repainted live sequence scored frame by frame against the truth frames.
int run_live(const EvalArgs& a) {
  if (a.truth.empty()) return report.usage("--live needs --truth (a `veneer simulate --light-path ... --material SOURCE` folder)");
  if (!std::filesystem::is_directory(a.live)) return report.usage("--live " + a.live + ": no such folder");
  if (!std::filesystem::is_directory(a.truth)) return report.usage("--truth " + a.truth + ": no such folder");
  if (a.map.empty() != a.src.empty())
    return report.usage("--live: --map and --src go together (the texture from the source through the map, as "
                        "look.py measures it)");
  auto look = eval::live_look_folders(a.live, a.truth, a.map, a.src);
  if (!look) return report.fail(look.message());
  std::fputs(look->table().c_str(), stdout);
  const std::filesystem::path out = a.out.empty() ? std::filesystem::path(a.live) / "live_look.json" : std::filesystem::path(a.out);
  if (auto s = report.text(out, look->json() + "\n"); !s) return report.fail(s.message());
  report.line("wrote " + out.string() + ": " + std::to_string(look->frames.size()) + " frames, shading error mean " +
              std::to_string(look->shading_mean) +
              (look->texture_corr_mean ? ", texture_corr mean " + std::to_string(*look->texture_corr_mean) +
                                              (look->texture_from_source ? " (the source through the map)"
                                                                         : " (against the truth, identity map)")
                                        : "") +
              (look->light_angle_median_deg
                   ? ", light " + std::to_string(*look->light_angle_median_deg) + " deg median off the path's lamp"
                   : ""));
  return 0;
}

int run_map(const EvalArgs& a) {
  if (a.dst.empty() || a.src.empty() || a.map.empty()) return report.usage("--dst, --src and --map are needed (or --table)");
  auto in = read_map_inputs(a.dst, a.src, a.map);
  if (!in) return report.fail(in.message());
  auto q = pipeline::evaluate_sets(in->map, in->dst, in->src);
  if (!q) return report.fail(q.message());
  std::printf("destination object pixels  %d\n", q->destination_pixels);
  std::printf("coverage                   %.2f %%\n", 100 * q->coverage);
  std::printf("mapped into background     %d\n", q->background_hits);
  if (q->normal_mean_deg) {
    std::printf("normal agreement, mean     %.2f deg\n", *q->normal_mean_deg);
    std::printf("normal agreement, p95      %.2f deg\n", *q->normal_p95_deg);
  } else {
    std::printf("normal agreement           (no truth in both sets)\n");
  }
  std::printf("coherence                  %.2f %%\n", 100 * q->coherence);
  std::printf("reuse, max per source px   %d\n", q->reuse_max);
  std::printf("source object used         %.2f %%\n", 100 * q->source_used);
  if (q->psnr_db) std::printf("relighting PSNR            %.2f dB\n", *q->psnr_db);
  if (q->psnr_lit_db) std::printf("  outside cast shadows     %.2f dB\n", *q->psnr_lit_db);
  return 0;
}

}  // namespace
}  // namespace veneer::cli

VENEER_ARGS_COMMAND(eval, veneer::cli::EvalArgs,
                    "quality of a map against ground truth, the quality table (--table), or a repainted live sequence against its truth frames (--live, --truth)") {
  veneer::cli::add_map_inputs(cmd, args->dst, args->src, args->map, false);
  cmd->add_flag("--table", args->table, "simulate the thesis pairs and print the quality table");
  cmd->add_flag("--full", args->full, "table: every method x feature x patch (slow)");
  cmd->add_option("--size", args->size, "table: render size WxH (default 512x340)");
  cmd->add_flag("--truth-normals", args->truth_normals, "table: match on true normals, not photometric stereo");
  cmd->add_flag("--no-fast", args->no_fast, "table: leave out the fast engine's rows");
  cmd->add_option("--out", args->out,
                  "table: also write it to this markdown file; --live: the per-frame JSON (default "
                  "<live>/live_look.json)");
  cmd->add_option("--live", args->live,
                  "score a repainted live sequence (a `veneer repaint --video` folder) frame by frame against "
                  "--truth with look.py's measure (shading error, texture_corr; eval/live_look.hpp); prints the "
                  "table with its mean");
  cmd->add_option("--truth", args->truth,
                  "--live: the sequence's folder from `veneer simulate --light-path ... --material SOURCE` "
                  "(light_path.json, truth/frame_NNNN.png, truth/mask.png); with --map (the transfer the frames "
                  "were repainted through) and --src (its source set) texture_corr is look.py's: the frame's "
                  "high-pass against the source's median photo's warped through the map");
  return [args] {
    if (!args->live.empty()) return veneer::cli::run_live(*args);
    return args->table ? veneer::cli::run_table(*args) : veneer::cli::run_map(*args);
  };
}
