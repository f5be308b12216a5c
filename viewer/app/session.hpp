#pragma once
// What the viewer's panels share: the rig link, the status line, the local
// library, the two sets loaded and the transfer shown. One object, made by the
// window and lent to every panel; each panel keeps the rest of its state.
#include <atomic>
#include <functional>
#include <memory>
#include <optional>

#include <QImage>
#include <QObject>
#include <QString>

#include <opencv2/core.hpp>

#include "library.hpp"
#include "rig_link.hpp"
#include "status_line.hpp"
#include "veneer/io/imageset.hpp"
#include "veneer/pipeline/transfer.hpp"
#include "veneer/ps/photometric_stereo.hpp"
#include "veneer/repaint/live_session.hpp"
#include "veneer/repaint/relight.hpp"

namespace veneer::app {

// One object the window has loaded: the set and what photometric stereo says of it.
struct LoadedSet {
  QString folder;
  veneer::io::ImageSet set;
  std::optional<veneer::ps::PsResult> normals;  // filled in the background after loading
  cv::Mat median;                               // per-pixel median photo (linear BGR)
  cv::Mat median_picture;                       // the same, tonemapped (8-bit), for the views
  QImage median_image;                          // ... as the views show it (made by the loader)
  cv::Mat histogram;                            // ... its 64-bin luminance histogram (CV_32F)
  cv::Mat hand_mask;  // segmentation by hand (CV_8UC1, 255 = object); empty = automatic
  int hand_version = 0;
  bool live_size = false;  // read at the live view's width (reduced decode), smaller than the set
  int live_width = 0;      // ... the width asked for (pipeline::LiveOptions' read.width), when live_size
  bool preview = false;    // read from the rig's preview set, whose full files are still being pulled
};

// What a transfer ran with (the options, the hand masks), kept with the
// result it made so that the library stores the map with them.
struct RunSettings {
  veneer::pipeline::TransferOptions options;
  cv::Mat dst_hand, src_hand;
  QString reopened;  // the library map it repainted through ("" = matched)
};

class Session : public QObject {
  Q_OBJECT
 public:
  Session(RigLink& rig, StatusLine& status, Library& library, const QString& workdir)
      : rig(rig), status(status), library(library), workdir(workdir) {}

  RigLink& rig;
  StatusLine& status;
  Library& library;
  const QString workdir;  // pulled sets go to <workdir>/sets

  // The sets loaded as destination and source.
  std::shared_ptr<LoadedSet> dst, src;
  std::shared_ptr<LoadedSet> setFor(veneer::io::Role role) const { return role == veneer::io::Role::source ? src : dst; }
  int sets_loaded = 0;  // counts every set loaded as destination or source
  // Loads running off the GUI thread (sets, library maps) and their cancel flag.
  int loads_running = 0;
  std::shared_ptr<std::atomic<bool>> load_cancel = std::make_shared<std::atomic<bool>>(false);

  // The transfer shown, what the views, the live repaint and the exports use.
  std::shared_ptr<veneer::pipeline::TransferResult> result;
  std::shared_ptr<veneer::repaint::Relighter> relighter;
  QString relight_error;  // why there is no relighter for the result shown
  // The live repaint: each frame registered to the source's stills, carried
  // through the map, with the outline, a quality figure and a lost state.
  std::shared_ptr<veneer::repaint::LiveSession> live_session;
  QString live_refusal;  // the live view's framing could not be related to the stills
  cv::Mat result_picture;  // the result's picture and the same as the view shows it,
  QImage result_image;     // made by the worker that made the result
  RunSettings shown;       // what the result shown was made with

  // The Relight tab's light direction (0, 0, 1 before there is one).
  std::function<cv::Vec3d()> light_source;
  cv::Vec3d light() const { return light_source ? light_source() : cv::Vec3d(0, 0, 1); }

  void message(const QString& text, bool error = false) { status.message(text, error); }
  // `loaded` is now the destination or the source: the transfer shown goes.
  void setLoaded(std::shared_ptr<LoadedSet> loaded, veneer::io::Role as) {
    (as == veneer::io::Role::source ? src : dst) = std::move(loaded);
    ++sets_loaded;
    result.reset();
    relighter.reset();
    live_session.reset();
    live_refusal.clear();
    emit picturesChanged();
    emit setsReplaced();
  }
  // A set's normals came in from the background.
  void normalsReady() { emit picturesChanged(); }

 signals:
  void picturesChanged();  // a set loaded, or its normals arrived: the Look tab follows
  void setsReplaced();     // a set loaded: what depends on its lamps follows
};

}  // namespace veneer::app
