#include "output.hpp"

#include <cstdio>
#include <iostream>

#include "veneer/io/image_io.hpp"

namespace veneer::cli {

int Output::fail(const std::string& what) const {
  std::cout.flush();
  std::cerr << "veneer " << command_ << ": " << what << "\n";
  return 1;
}

int Output::usage(const std::string& what) const {
  fail(what);
  return 2;
}

Status Output::folder(const std::filesystem::path& dir) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) return make_error(dir.string() + ": cannot create: " + ec.message());
  dir_ = dir;
  return {};
}

std::filesystem::path Output::path(const std::filesystem::path& name) const {
  return dir_.empty() || name.is_absolute() ? name : dir_ / name;
}

Status Output::remember(const std::filesystem::path& name, Status s) {
  if (s) written_.push_back(name.string());
  return s;
}

Status Output::picture(const std::filesystem::path& name, const cv::Mat& bgr8) {
  return remember(name, io::write_picture(path(name), bgr8));
}

Status Output::pfm(const std::filesystem::path& name, const cv::Mat& image, bool xyz_order) {
  return remember(name, io::write_pfm(path(name), image, xyz_order));
}

Status Output::json(const std::filesystem::path& name, const nlohmann::json& doc, int indent) {
  return remember(name, io::write_file_atomic(path(name), doc.dump(indent) + "\n"));
}

Status Output::text(const std::filesystem::path& name, const std::string& text) {
  return remember(name, io::write_file_atomic(path(name), text));
}

void Output::line(const std::string& text) const { std::cout << text << "\n" << std::flush; }

int Output::wrote(const std::string& what) const {
  std::string files = what;
  if (files.empty()) {
    for (const auto& f : written_) files += (files.empty() ? "" : " ") + f;
    if (files.empty()) files = "nothing";
  }
  line("wrote " + (dir_.empty() ? std::string(".") : dir_.string()) + ": " + files);
  return 0;
}

}  // namespace veneer::cli
