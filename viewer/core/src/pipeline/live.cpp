// Live first (live.hpp): the pair read at the live size and prepared there.
#include "veneer/pipeline/live.hpp"

#include <chrono>

#include <opencv2/imgproc.hpp>

namespace veneer::pipeline {
namespace fs = std::filesystem;

namespace {
using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }
}  // namespace

Status LiveOptions::check() const {
  if (Status s = read.check(); !s) return s;
  for (const cv::Mat* m : {&destination_mask, &source_mask})
    if (!m->empty() && m->type() != CV_8UC1) return make_error("a hand-drawn mask must be 8-bit, one channel");
  return Status::success();
}

namespace {

// The sets read (masks and scale applied in `read`), prepared: normals 60-100 %.
Expected<pipeline::PreparedPair> prepare_read(io::ImageSet destination, io::ImageSet source,
                                              const pipeline::TransferOptions& transfer, const LiveOptions& options,
                                              std::vector<SetReport>& made, std::vector<SetReport>* reports,
                                              const Progress& progress) {
  pipeline::PreparedPair pair;
  pair.scale = transfer.scale;
  pair.truth_normals = transfer.truth_normals;
  const cv::Mat* masks[2] = {&options.destination_mask, &options.source_mask};
  pair.destination = std::move(destination);
  pair.source = std::move(source);
  io::ImageSet* sets[2] = {&pair.destination, &pair.source};
  match::PreparedObject* objects[2] = {&pair.dst, &pair.src};
  for (int i = 0; i < 2; ++i) {
    io::ImageSet& set = *sets[i];
    if (!masks[i]->empty()) {
      cv::Mat mask;  // a new picture: a set handed in may share its mask with its owner
      cv::resize(*masks[i] > 127, mask, set.size, 0, 0, cv::INTER_NEAREST);
      set.mask = mask;
    }
    match::scale_set(set, transfer.scale);
    made[static_cast<size_t>(i)].id = set.id;
    made[static_cast<size_t>(i)].photos_from = set.photos_from;
  }
  for (int i = 0; i < 2; ++i) {
    const auto t0 = Clock::now();
    auto object = match::prepare_object(*sets[i], transfer.truth_normals, progress.part(0.6 + 0.2 * i, 0.8 + 0.2 * i));
    if (!object) return make_error(std::string(i == 0 ? "destination" : "source") + ": " + object.message());
    *objects[i] = std::move(*object);
    made[static_cast<size_t>(i)].normals_s = since(t0);
    made[static_cast<size_t>(i)].total_s = made[static_cast<size_t>(i)].read_s + made[static_cast<size_t>(i)].normals_s;
  }
  pair.destination_median = repaint::median_photo(pair.dst.view.images);
  pair.source_median = repaint::median_photo(pair.src.view.images);
  if (reports) *reports = std::move(made);
  return pair;
}

}  // namespace

Expected<pipeline::PreparedPair> prepare_live_pair(const fs::path& destination, const fs::path& source,
                                                const pipeline::TransferOptions& transfer, const LiveOptions& options,
                                                std::vector<SetReport>* reports, const Progress& progress) {
  if (Status s = transfer.check(); !s) return s.error();
  if (Status s = options.check(); !s) return s.error();
  std::vector<SetReport> made(2);
  const fs::path folders[2] = {destination, source};
  io::ImageSet sets[2];
  for (int i = 0; i < 2; ++i) {
    const char* role = i == 0 ? "destination" : "source";
    made[static_cast<size_t>(i)].folder = folders[i].string();
    const auto t0 = Clock::now();
    auto set = io::read_set_reduced(folders[i], options.read, progress.part(0.3 * i, 0.3 * (i + 1)));
    if (!set) return make_error(std::string(role) + ": " + set.message());
    made[static_cast<size_t>(i)].read_s = since(t0);
    sets[i] = std::move(*set);
  }
  return prepare_read(std::move(sets[0]), std::move(sets[1]), transfer, options, made, reports, progress);
}

Expected<pipeline::PreparedPair> prepare_live_pair(io::ImageSet destination, io::ImageSet source,
                                                const pipeline::TransferOptions& transfer, const LiveOptions& options,
                                                std::vector<SetReport>* reports, const Progress& progress) {
  if (Status s = transfer.check(); !s) return s.error();
  if (Status s = options.check(); !s) return s.error();
  std::vector<SetReport> made(2);
  made[0].folder = destination.origin.string();
  made[1].folder = source.origin.string();
  return prepare_read(std::move(destination), std::move(source), transfer, options, made, reports, progress);
}

}  // namespace veneer::pipeline
