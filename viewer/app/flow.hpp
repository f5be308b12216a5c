#pragma once
// The one flow from capture to live repaint: with it on (the Capture panel's
// switch, on by default), every capture stored on the rig -- from its button,
// the Capture panel or the Live tab -- is pulled and loaded as its role, the
// map is computed with the current settings as soon as both sets exist, and
// the live repaint starts. Every step runs off the GUI thread; this object
// only chains them. It also loads the sets (for the flow and for the panels).
#include <map>
#include <optional>
#include <set>
#include <vector>

#include <QObject>

#include "session.hpp"

namespace veneer::app {

class CapturePanel;
class LiveFirstJob;
class LiveTab;
class MapLibrary;
class SetsPanel;
class TransferPanel;

class FlowController : public QObject {
  Q_OBJECT
 public:
  FlowController(Session& session, CapturePanel& capture, SetsPanel& sets, TransferPanel& transfer, LiveTab& live,
                 LiveFirstJob& live_first, MapLibrary& library, QObject* parent = nullptr);
  bool autoFlow() const;
  // Loads a set off the GUI thread (read, median, thumbnail), then shows it.
  // Without a role the set is only listed (a pull in manual mode); with
  // Role::unknown it is used as the role its manifest gives.
  void loadSetInBackground(const QString& folder, std::optional<veneer::io::Role> as);
  // The same on the GUI thread (the command line's sets at start).
  bool loadLocalSet(const QString& folder, veneer::io::Role as);
  // A result is shown: live repaint, then the full resolution behind a live-size map.
  void resultShown();
  // The pulls the flow waits for are cancelled.
  void forgetPulls() { auto_pulls_.clear(); }
  // Live first (live_first.hpp): the flow's sets are read at the live view's
  // width; 0 = off: full resolution first.
  void setLiveWidth(int px) { live_width_ = px; }
  int liveWidth() const { return live_width_; }
  // Live first from the rig's preview set (pulled before the full files, read
  // at the live width when it is as wide): off by default -- a run of the
  // 5600x3750 bench and a test crashed with it on, cause not found (issue 48).
  void setPreviewFirst(bool on) { preview_first_ = on; }

 signals:
  void tabWanted(QString name);

 private:
  void setStored(const QString& id, veneer::io::Role role);
  void pulled(const QString& id, const QString& folder);
  void previewPulled(const QString& id, const QString& folder);
  void computeNormals(std::shared_ptr<LoadedSet> loaded);
  void computeWaitingNormals();
  void maybeCompute();

  Session& session_;
  CapturePanel& capture_;
  SetsPanel& sets_;
  TransferPanel& transfer_;
  LiveTab& live_;
  LiveFirstJob& live_first_;
  MapLibrary& library_;
  std::vector<std::shared_ptr<LoadedSet>> normals_waiting_;  // loaded sets whose normals wait for their map
  std::map<QString, veneer::io::Role> auto_pulls_;  // rig set id -> role, pulled by the flow
  std::set<QString> previews_loaded_;  // rig set ids whose preview set the flow loaded (its full files follow)
  std::set<QString> full_folders_;     // folders whose full files are in place
  int live_width_ = 1280;
  bool preview_first_ = !qEnvironmentVariableIsEmpty("VENEER_PREVIEW_FIRST");
};

}  // namespace veneer::app
