#pragma once
// veneer-viewer's window: connect to a rig, capture, browse and pull sets,
// compute a transfer in the background, look at every picture, watch the live
// view repainted onto the destination, relight, export. Every computation is a
// call into viewer/core, run off the GUI thread. The window builds the menus
// and the status line and composes the panels, each a class with its own
// state; what they share is the Session (session.hpp).
#include <memory>

#include <QMainWindow>

#include "calibration.hpp"
#include "capture_panel.hpp"
#include "export.hpp"
#include "flow.hpp"
#include "library.hpp"
#include "live_first.hpp"
#include "live_tab.hpp"
#include "look_tab.hpp"
#include "map_library.hpp"
#include "relight_tab.hpp"
#include "rig_link.hpp"
#include "rig_panel.hpp"
#include "segmentation.hpp"
#include "session.hpp"
#include "sets_panel.hpp"
#include "status_line.hpp"
#include "transfer_panel.hpp"

class QTabWidget;

namespace veneer::app {

class MainWindow : public QMainWindow {
  Q_OBJECT
 public:
  struct Options {
    QString rig;         // host:port to connect to at start (empty = none)
    QString token_file;  // the rig's token file
    QString destination, source;  // local sets to load at start
    QString workdir;     // where pulled sets go (default: the app's data folder)
  };
  explicit MainWindow(const Options& options, QWidget* parent = nullptr);
  ~MainWindow() override;

  // What the tests and scripts drive (the buttons call the same), each
  // handed to the panel that does it.
  RigLink& rig() { return rig_; }
  void connectToRig(const QString& endpoint, const QString& token_file) { rig_panel_->connectToRig(endpoint, token_file); }
  bool loadLocalSet(const QString& folder, veneer::io::Role as) { return flow_->loadLocalSet(folder, as); }
  void loadSetInBackground(const QString& folder, std::optional<veneer::io::Role> as) {
    flow_->loadSetInBackground(folder, as);
  }
  int loadsRunning() const { return session_->loads_running; }
  void startTransfer() { transfer_->startTransfer(); }
  void cancelTransfer() { transfer_->cancelTransfer(); }
  bool computing() const { return transfer_->computing(); }
  int mapOnlyRuns() const { return transfer_->mapOnlyRuns(); }
  int repaintOnlyRuns() const { return transfer_->repaintOnlyRuns(); }
  const veneer::pipeline::TransferResult* result() const { return session_->result.get(); }
  const LoadedSet* destination() const { return session_->dst.get(); }
  const LoadedSet* source() const { return session_->src.get(); }
  QString workdir() const { return session_->workdir; }
  QString lastMessage() const { return status_->lastMessage(); }
  // The one line of status: the step running, its progress and time left.
  QString stepLine() const { return status_->line(); }
  // Cancels whatever the status line shows running (compute, capture, pull,
  // load, export).
  void cancelStep();
  cv::Mat lastLiveFrame() const { return live_->lastFrame(); }
  cv::Mat lastRepaintedFrame() const { return live_->lastRepaintedFrame(); }
  int liveFramesShown() const { return live_->framesShown(); }
  double liveFps() const { return live_->fps(); }
  // Grabs every view as <dir>/<tab>.png; returns the files written.
  QStringList saveScreenshots(const QString& dir);
  void showTab(const QString& name);
  // Saves the tab shown, as on screen, as a PNG; returns the file ("" and a
  // message when it cannot).
  QString snapshotTo(const QString& file);
  // The Look tab's "Show" choice by its text (e.g. "specular enhancement").
  bool showLook(const QString& what);
  QString exposureText() const { return look_->exposureText(); }
  // Segmentation by hand (segmentation.hpp).
  void setHandRect(veneer::io::Role set, const QRect& rect) { segmentation_->setHandRect(set, rect); }
  void brushHandMask(veneer::io::Role set, QPoint pixel, bool add, int radius = 0) {
    segmentation_->brushHandMask(set, pixel, add, radius);
  }
  void clearHandMask(veneer::io::Role set) { segmentation_->clearHandMask(set); }
  QStringList exportMasksTo(const QString& dir) { return segmentation_->exportMasksTo(dir); }
  // The one flow (flow.hpp).
  bool autoFlow() const { return capture_->autoFlow(); }
  void setAutoFlow(bool on) { capture_->setAutoFlow(on); }
  // Exports without a dialog (export.hpp).
  void exportMapTo(const QString& dir) { exports_->exportMapTo(dir); }
  void exportResultsTo(const QString& dir) { exports_->exportResultsTo(dir); }
  void exportRelightVideoTo(const QString& file) { exports_->exportRelightVideoTo(file); }
  bool exporting() const { return exports_->exporting(); }
  // A map kept in the library shown again (map_library.hpp).
  bool openLibraryMap(const QString& map_folder) { return map_library_->open(map_folder); }
  // Lamp calibration (calibration.hpp).
  bool calibrateLamps(const QString& sphere_folder, const QString& lights_file) {
    return calibration_->calibrateLamps(sphere_folder, lights_file);
  }
  QImage calibrationImage() const { return calibration_->image(); }
  // Live first (live_first.hpp).
  void setLiveWidth(int px) { flow_->setLiveWidth(px); }
  int liveWidth() const { return flow_->liveWidth(); }
  bool fullResolutionRunning() const { return live_first_->running(); }
  int fullResolutionSwaps() const { return live_first_->swaps(); }
  QString fullResolutionLine() const { return live_first_->line(); }

 private:
  void buildUi();
  void buildMenus();
  void wire();

  RigLink rig_;
  std::unique_ptr<Library> library_;
  StatusLine* status_ = nullptr;
  std::unique_ptr<Session> session_;
  // the panels and tabs (widgets owned by the window)
  RigPanel* rig_panel_ = nullptr;
  CapturePanel* capture_ = nullptr;
  SetsPanel* sets_ = nullptr;
  TransferPanel* transfer_ = nullptr;
  QTabWidget* tabs_ = nullptr;
  LookTab* look_ = nullptr;
  LiveTab* live_ = nullptr;
  RelightTab* relight_ = nullptr;
  // the controllers (children of the window)
  SegmentationTool* segmentation_ = nullptr;
  ExportActions* exports_ = nullptr;
  MapLibrary* map_library_ = nullptr;
  LiveFirstJob* live_first_ = nullptr;
  FlowController* flow_ = nullptr;
  CalibrationStep* calibration_ = nullptr;
};

}  // namespace veneer::app
