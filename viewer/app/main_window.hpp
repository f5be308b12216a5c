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

  // What the tests and scripts drive (the buttons call the same): the panels
  // themselves, each doing its own part (its header says what).
  RigLink& rig() { return rig_; }
  const Session& session() const { return *session_; }         // the sets, the result, the loads
  StatusLine& status() { return *status_; }                    // the one line of status, the last message
  RigPanel& rigPanel() { return *rig_panel_; }                 // connect
  CapturePanel& capture() { return *capture_; }                // capture, the one flow on or off
  TransferPanel& transfer() { return *transfer_; }             // compute, cancel
  LookTab& look() { return *look_; }                           // the pictures, exposure
  LiveTab& live() { return *live_; }                           // the live frames shown
  SegmentationTool& segmentation() { return *segmentation_; }  // masks by hand
  ExportActions& exports() { return *exports_; }               // exports without a dialog
  MapLibrary& mapLibrary() { return *map_library_; }           // a kept map shown again
  LiveFirstJob& liveFirst() { return *live_first_; }           // the full-resolution map behind live
  FlowController& flow() { return *flow_; }                    // loading sets, the live width
  CalibrationStep& calibration() { return *calibration_; }     // lamp calibration

  // What spans the panels and the tabs.
  // Cancels whatever the status line shows running (compute, capture, pull,
  // load, export).
  void cancelStep();
  // Grabs every view as <dir>/<tab>.png; returns the files written.
  QStringList saveScreenshots(const QString& dir);
  void showTab(const QString& name);
  // Saves the tab shown, as on screen, as a PNG; returns the file ("" and a
  // message when it cannot).
  QString snapshotTo(const QString& file);
  // The Look tab's "Show" choice by its text (e.g. "specular enhancement").
  bool showLook(const QString& what);

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
