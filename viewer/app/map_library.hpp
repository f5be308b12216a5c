#pragma once
// The maps of the local library: kept when computed, shown again after a
// restart through the stored map (repainted, not matched again).
#include <memory>
#include <optional>

#include <QObject>

#include "session.hpp"

namespace veneer::app {

class SegmentationTool;
class SetsPanel;
class TransferPanel;

class MapLibrary : public QObject {
  Q_OBJECT
 public:
  MapLibrary(Session& session, SetsPanel& sets, TransferPanel& transfer, SegmentationTool& segmentation,
             QObject* parent = nullptr);
  // The map shown goes into the library with the options and hand masks it
  // was made with (written off the GUI thread, each file through a temporary).
  void saveShown();
  // Shows a map kept in the library again: loads its destination and source
  // in their roles, with the options and hand masks it was computed with, and
  // repaints through the stored map -- no matching. False, with a message
  // naming what is missing, when its map file or one of its sets is gone; a
  // set found replaced (another id in its folder) is said once both are loaded.
  bool open(const QString& map_folder);
  // A set finished loading as `role`: true while a map being reopened waits
  // for its sets (and when it then starts), so the flow does not compute.
  bool reopenWhenLoaded(const QString& folder, veneer::io::Role role);
  // A set failed to load: true (and the reopening dropped, said) when it was
  // one of a reopened map's.
  bool reopenFailed(const QString& folder, const QString& error);
  void cancelReopen() { reopen_.reset(); }

 signals:
  void loadRequested(QString folder, veneer::io::Role role);

 private:
  // A library map being reopened: shown once both its sets are loaded.
  struct Reopen {
    LibraryMap entry;
    std::shared_ptr<const veneer::match::Map> map;
    veneer::pipeline::TransferOptions options;
    cv::Mat dst_hand, src_hand;
    bool dst_loaded = false, src_loaded = false;
  };

  Session& session_;
  SetsPanel& sets_;
  TransferPanel& transfer_;
  SegmentationTool& segmentation_;
  std::optional<Reopen> reopen_;
};

}  // namespace veneer::app
