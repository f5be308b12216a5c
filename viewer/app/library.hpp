#pragma once
// The local library: every set pulled or opened on this computer, and the maps
// computed from them, remembered across restarts in <workdir>/library.json
// (written whole through a temporary file, so a crash leaves the old one)
// with a thumbnail per set in <workdir>/thumbnails/. The files are written on
// the library's own thread, in the order asked: the GUI does not wait for
// the disk (a file's sync can take long on a busy machine).
#include <functional>
#include <vector>

#include <QPointer>
#include <QString>
#include <QThreadPool>

#include <opencv2/core.hpp>

#include "veneer/io/imageset.hpp"

namespace veneer::app {

struct LibrarySet {
  QString folder;     // the set's folder (the key)
  QString role;       // "destination" | "source" | "unknown"
  QString object;
  QString created;    // the capture's date (UTC, ISO 8601), from the manifest
  QString thumbnail;  // PNG path, may be empty
};

// A map kept in the library, enough to show it again after a restart
// without matching: its folder holds map.pfm, map.png (thumbnail),
// options.json (the transfer options it was computed and repainted with,
// pipeline::transfer_options_json) and, when the sets were segmented by hand,
// dst-mask.png / src-mask.png.
struct LibraryMap {
  QString folder;
  QString destination, source;  // the sets' folders, in their roles
  QString destination_id, source_id;  // the sets' ids (manifest) when computed: a set replaced is noticed
  QString method;
  QString computed;  // UTC, ISO 8601
};

class Library {
 public:
  // Reads <workdir>/library.json when there is one; a damaged file is set
  // aside as library.json.bad and named in `problem`.
  explicit Library(const QString& workdir);
  ~Library();  // waits for the writes asked
  const QString& problem() const { return problem_; }
  const std::vector<LibrarySet>& sets() const { return sets_; }
  const std::vector<LibraryMap>& maps() const { return maps_; }
  // Adds or updates the set at `folder` (thumbnail: 8-bit BGR, may be empty).
  void addSet(const QString& folder, const veneer::io::ImageSet& set, const cv::Mat& thumbnail);
  void forgetSet(const QString& folder);
  void addMap(const LibraryMap& map);
  const LibraryMap* findMap(const QString& folder) const;
  QString mapsFolder() const { return workdir_ + "/maps"; }
  // Writes library.json as it is now, on the library's thread; a write that
  // fails is told to the problem handler (on its context's thread).
  void save();
  void setProblemHandler(QObject* context, std::function<void(const QString&)> on_problem);
  void flush();  // waits for the writes asked so far

 private:
  void problemLater(const QString& problem);
  QString workdir_, problem_;
  QPointer<QObject> context_;
  std::function<void(const QString&)> on_problem_;
  QThreadPool writer_;  // one thread: the writes in the order asked
  std::vector<LibrarySet> sets_;
  std::vector<LibraryMap> maps_;
};

}  // namespace veneer::app
