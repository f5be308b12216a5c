#pragma once
// How every `veneer` command reports, in one place (used by all cmd_*.cpp):
//   - an error is one line on stderr, "veneer <command>: <what was wrong>",
//     exit code 1; bad usage (a wrong option value) exits 2;
//   - files go into an output folder that folder() creates, written through
//     picture() / pfm() / json() / text() (JSON and text atomically), and each
//     one is remembered;
//   - the closing summary goes to stdout: line() for figures, wrote() for
//     "wrote <folder>: <the files written>".
//
//   Output report{"normals"};
//   if (auto s = report.folder(a.out); !s) return report.fail(s.message());
//   if (auto s = report.pfm("normals.pfm", n, true); !s) return report.fail(s.message());
//   return report.wrote();
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "veneer/util/expected.hpp"

namespace veneer::cli {

class Output {
 public:
  explicit Output(std::string command) : command_(std::move(command)) {}
  const std::string& command() const { return command_; }

  // "veneer <command>: <what>" on stderr; returns the exit code (1, or 2 for usage).
  int fail(const std::string& what) const;
  int usage(const std::string& what) const;

  // The output folder, created with its parents. Names given to the writers
  // below are relative to it (without a folder: paths as given).
  Status folder(const std::filesystem::path& dir);
  const std::filesystem::path& dir() const { return dir_; }
  std::filesystem::path path(const std::filesystem::path& name) const;

  Status picture(const std::filesystem::path& name, const cv::Mat& bgr8);
  Status pfm(const std::filesystem::path& name, const cv::Mat& image, bool xyz_order);
  Status json(const std::filesystem::path& name, const nlohmann::json& doc, int indent = 2);
  Status text(const std::filesystem::path& name, const std::string& text);
  // Files written so far, as given (relative to the folder).
  const std::vector<std::string>& written() const { return written_; }

  // One summary line on stdout.
  void line(const std::string& text) const;
  // "wrote <folder>: <files written>" (or `what` instead of the list); returns 0.
  int wrote(const std::string& what = "") const;

 private:
  Status remember(const std::filesystem::path& name, Status s);
  std::string command_;
  std::filesystem::path dir_;
  std::vector<std::string> written_;
};

}  // namespace veneer::cli
