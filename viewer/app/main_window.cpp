#include "main_window.hpp"
#include "background.hpp"

#include <QApplication>
#include <QDir>
#include <QFileDialog>
#include <QLabel>
#include <QMenuBar>
#include <QSaveFile>
#include <QScrollArea>
#include <QSplitter>
#include <QStandardPaths>
#include <QStatusBar>
#include <QTabWidget>
#include <QVBoxLayout>

#include "widgets.hpp"

namespace veneer::app {

MainWindow::MainWindow(const Options& options, QWidget* parent) : QMainWindow(parent) {
  opencv_loops_in_current_arena();  // before any loop runs: the background's OpenCV calls stay on its threads
  const QString workdir = options.workdir.isEmpty()
                              ? QStandardPaths::writableLocation(QStandardPaths::AppLocalDataLocation)
                              : options.workdir;
  QDir().mkpath(workdir + "/sets");
  library_ = std::make_unique<Library>(workdir);
  status_ = new StatusLine(statusBar(), this);
  session_ = std::make_unique<Session>(rig_, *status_, *library_, workdir);
  library_->setProblemHandler(this, [this](const QString& problem) { session_->message(problem, true); });
  buildUi();
  buildMenus();
  guard_wheel(this);
  sets_->showLibrary();
  wire();

  if (!options.destination.isEmpty()) flow_->loadLocalSet(options.destination, veneer::io::Role::destination);
  if (!options.source.isEmpty()) flow_->loadLocalSet(options.source, veneer::io::Role::source);
  if (!options.rig.isEmpty()) rig_panel_->connectToRig(options.rig, options.token_file);
}

MainWindow::~MainWindow() {
  // What runs off the GUI thread stops before the session it reports to goes:
  // an export, the transfer (the side panel), the live view's frame (the tabs).
  delete exports_;
  delete centralWidget();
  library_->flush();
}

// ---------------------------------------------------------------- layout

void MainWindow::buildUi() {
  setWindowTitle(tr("Veneer"));
  Session& s = *session_;
  auto* split = new QSplitter(this);
  auto* side = new QWidget;
  auto* side_layout = new QVBoxLayout(side);
  side_layout->addWidget(rig_panel_ = new RigPanel(s));
  side_layout->addWidget(capture_ = new CapturePanel(s));
  side_layout->addWidget(sets_ = new SetsPanel(s), 1);
  side_layout->addWidget(transfer_ = new TransferPanel(s));
  auto* scroll = new QScrollArea;
  scroll->setWidget(side);
  scroll->setWidgetResizable(true);
  scroll->setMinimumWidth(330);
  split->addWidget(scroll);

  tabs_ = named<QTabWidget>("tabs");
  tabs_->addTab(look_ = new LookTab(s), tr("Look"));
  tabs_->addTab(live_ = new LiveTab(s), tr("Live"));
  tabs_->addTab(relight_ = new RelightTab(s), tr("Relight"));
  s.light_source = [relight = relight_] { return relight->direction(); };
  split->addWidget(tabs_);
  split->setStretchFactor(1, 1);
  setCentralWidget(split);
  statusBar()->addPermanentWidget(rig_panel_->statusLabel());
  resize(1400, 860);

  segmentation_ = new SegmentationTool(s, this);
  exports_ = new ExportActions(s, this);
  map_library_ = new MapLibrary(s, *sets_, *transfer_, *segmentation_, this);
  live_first_ = new LiveFirstJob(s, *transfer_, statusBar(), this);
  flow_ = new FlowController(s, *capture_, *sets_, *transfer_, *live_, *live_first_, *map_library_, this);
  calibration_ = new CalibrationStep(s, this);
}

void MainWindow::buildMenus() {
  QMenu* file = menuBar()->addMenu(tr("&File"));
  file->addAction(tr("Open set folder…"), this, [this] {
    QString dir = QFileDialog::getExistingDirectory(this, tr("Image set folder"));
    if (!dir.isEmpty()) flow_->loadSetInBackground(dir, veneer::io::Role::destination);
  });
  QMenu* exp = menuBar()->addMenu(tr("&Export"));
  exp->addAction(tr("Map (map.pfm, map.png)…"), exports_, &ExportActions::exportMap);
  exp->addAction(tr("Result pictures…"), exports_, &ExportActions::exportResults);
  exp->addAction(tr("Relight sweep video…"), exports_, &ExportActions::exportRelightVideo);
  exp->addAction(tr("Web page (relights in any browser)…"), exports_, &ExportActions::exportWebPage);
  exp->addAction(tr("Masks drawn by hand (for veneer transfer --dst-mask)…"), this, [this] {
    const QString dir = QFileDialog::getExistingDirectory(this, tr("Write the masks into"));
    if (!dir.isEmpty()) segmentation_->exportMasksTo(dir);
  });
  file->addAction(tr("Calibrate lamps from a chrome-sphere set…"), calibration_, &CalibrationStep::ask);
  file->addSeparator();
  file->addAction(tr("Quit"), qApp, &QApplication::quit);
}

// How the panels hear of each other.
void MainWindow::wire() {
  Session& s = *session_;
  connect(status_, &StatusLine::cancelRequested, this, &MainWindow::cancelStep);
  status_->setBusyCheck([this] {
    return transfer_->computing() || exports_->exporting() || session_->loads_running > 0 || rig_.pulling();
  });
  connect(&s, &Session::picturesChanged, look_, &LookTab::refresh);
  connect(&s, &Session::setsReplaced, live_, &LiveTab::updateLampBoxes);
  connect(sets_, &SetsPanel::openMapRequested, map_library_, &MapLibrary::open);
  connect(live_, &LiveTab::captureRequested, capture_, &CapturePanel::capture);
  connect(look_, &LookTab::snapshotAsked, this, [this] {
    const QString f = QFileDialog::getSaveFileName(this, tr("Snapshot"), "snapshot.png", "PNG (*.png)");
    if (!f.isEmpty()) snapshotTo(f);
  });
  connect(look_, &LookTab::handRectDrawn, segmentation_, &SegmentationTool::setHandRect);
  connect(look_, &LookTab::brushed, segmentation_,
          [this](veneer::io::Role set, QPoint p, bool add) { segmentation_->brushHandMask(set, p, add); });
  connect(segmentation_, &SegmentationTool::maskChanged, this,
          [this](veneer::io::Role set, const std::vector<QPolygonF>& outline, const QString& hand) {
            look_->setOutline(set, outline);
            transfer_->handMaskChanged(hand);
          });
  connect(relight_, &RelightTab::lightChanged, look_, &LookTab::lightChanged);
  connect(transfer_, &TransferPanel::resultShown, this,
          [this](const QImage& relit, const QImage& relit_source, const cv::Vec3d& light) {
            look_->showResult();
            relight_->showRelit(relit, relit_source, light);
            if (!session_->result->map_given) map_library_->saveShown();
            flow_->resultShown();
          });
  connect(live_first_, &LiveFirstJob::swapped, this,
          [this](const QImage& relit, const QImage& relit_source, const cv::Vec3d& light) {
            look_->refresh();
            relight_->showRelit(relit, relit_source, light);
          });
  connect(flow_, &FlowController::tabWanted, this, &MainWindow::showTab);
  // the Look tab's look is the transfer's (TransferOptions::look); a reopened map's shows there
  connect(look_, &LookTab::lookChosen, transfer_, &TransferPanel::setLook);
  connect(transfer_, &TransferPanel::lookShown, look_, &LookTab::setLook);
}

void MainWindow::cancelStep() {
  Session& s = *session_;
  if (transfer_->computing()) transfer_->cancelTransfer();
  if (exports_->exporting()) exports_->cancel();
  if (live_first_->running()) live_first_->cancel();
  if (rig_.pulling()) {
    rig_.cancelPulls();
    flow_->forgetPulls();
  }
  map_library_->cancelReopen();
  if (s.loads_running > 0) {
    s.load_cancel->store(true);
    s.load_cancel = std::make_shared<std::atomic<bool>>(false);
  }
  const StepClock& step = status_->step();
  if (step.running() && (step.kind() == "capture" || step.kind() == "store")) rig_.cancelCapture();
  s.message(tr("cancelling…"));
}

// ---------------------------------------------------------------- tabs

QStringList MainWindow::saveScreenshots(const QString& dir) {
  QDir().mkpath(dir);
  QStringList files;
  const int current = tabs_->currentIndex();
  for (int i = 0; i < tabs_->count(); ++i) {
    tabs_->setCurrentIndex(i);
    QApplication::processEvents();
    const QString f = dir + "/" + tabs_->tabText(i).toLower() + ".png";
    if (grab().save(f)) files << f;
  }
  tabs_->setCurrentIndex(current);
  return files;
}

void MainWindow::showTab(const QString& name) {
  for (int i = 0; i < tabs_->count(); ++i)
    if (tabs_->tabText(i).compare(name, Qt::CaseInsensitive) == 0) tabs_->setCurrentIndex(i);
}

bool MainWindow::showLook(const QString& what) {
  const int i = look_->lookIndex(what);
  if (i < 0) return false;
  showTab("Look");
  look_->showLook(i);
  return true;
}

QString MainWindow::snapshotTo(const QString& file) {
  QWidget* view = tabs_->currentWidget();
  if (!view) return {};
  if (!file.endsWith(".png", Qt::CaseInsensitive)) {
    session_->message(tr("a snapshot is a PNG: %1 does not end in .png").arg(file), true);
    return {};
  }
  QSaveFile out(file);  // whole or not at all
  if (!out.open(QIODevice::WriteOnly) || !view->grab().save(&out, "PNG") || !out.commit()) {
    session_->message(tr("cannot write the snapshot %1: %2").arg(file, out.errorString()), true);
    return {};
  }
  session_->message(tr("snapshot saved as %1").arg(file));
  return file;
}

}  // namespace veneer::app
