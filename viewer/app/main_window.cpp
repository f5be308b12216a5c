#include "main_window.hpp"
#include "widgets.hpp"

#include <algorithm>
#include <cmath>

#include <QApplication>
#include <QCheckBox>
#include <QComboBox>
#include <QDir>
#include <QDoubleSpinBox>
#include <QFileDialog>
#include <QFormLayout>
#include <QGroupBox>
#include <QHBoxLayout>
#include <QLabel>
#include <QLineEdit>
#include <QMenuBar>
#include <QProgressBar>
#include <QPushButton>
#include <QScrollArea>
#include <QSpinBox>
#include <QSplitter>
#include <QStandardPaths>
#include <QStatusBar>
#include <QTabWidget>
#include <QTreeWidget>
#include <QVBoxLayout>
#include <QtConcurrent/QtConcurrentRun>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "veneer/io/image_io.hpp"
#include "veneer/ps/segmentation.hpp"

namespace veneer::app {

cv::Mat picture_of(const cv::Mat& linear) { return linear.empty() ? cv::Mat() : io::tonemap_picture(linear); }

MainWindow::MainWindow(const Options& options, QWidget* parent)
    : QMainWindow(parent), settings_("veneer", "veneer-viewer") {
  workdir_ = options.workdir.isEmpty()
                 ? QStandardPaths::writableLocation(QStandardPaths::AppLocalDataLocation)
                 : options.workdir;
  QDir().mkpath(workdir_ + "/sets");
  library_ = std::make_unique<Library>(workdir_);
  library_->setProblemHandler(this, [this](const QString& problem) { message(problem, true); });
  buildUi();
  buildMenus();
  guard_wheel(this);
  showLibrary();

  connect(&rig_, &RigLink::connectedChanged, this, [this](bool ok, QString msg) {
    message(msg, !ok);
    connect_btn_->setText(ok ? tr("Disconnect") : tr("Connect"));
    if (ok) rememberRig(rig_.endpoint());
    if (!ok) qDeleteAll(rig_root_->takeChildren());
    updateStatusLine();
  });
  connect(&rig_, &RigLink::statusUpdated, this, [this](veneer::rig::RigStatus) {
    updateStatusLine();
    updateLampBoxes();
  });
  connect(&rig_, &RigLink::setsListed, this, &MainWindow::onSetsListed);
  connect(&rig_, &RigLink::rigEvent, this, &MainWindow::onRigEvent);
  connect(&rig_, &RigLink::liveFrame, this, &MainWindow::onLiveFrame);
  connect(&rig_, &RigLink::failed, this, [this](QString what, QString msg) { message(what + ": " + msg, true); });
  connect(&rig_, &RigLink::pullProgress, this, [this](QString, double f) {
    pull_bar_->setVisible(true);
    pull_bar_->setValue(static_cast<int>(f * 100));
    if (step_.running()) {
      step_.update(f);
      showStep();
    }
  });
  connect(&rig_, &RigLink::pulled, this, [this](QString id, QString folder) {
    pull_bar_->setValue(100);
    message(tr("pulled %1 into %2").arg(id, folder));
    flowPulled(id, folder);
  });
  live_pool_.setMaxThreadCount(1);
  live_pool_.setExpiryTimeout(-1);  // the live view's thread stays while the window lives
  step_timer_.setInterval(250);
  connect(&step_timer_, &QTimer::timeout, this, &MainWindow::showStep);
  connect(&transfer_watch_, &QFutureWatcher<void>::finished, this, &MainWindow::onTransferDone);

  if (!options.destination.isEmpty()) loadLocalSet(options.destination, veneer::io::Role::destination);
  if (!options.source.isEmpty()) loadLocalSet(options.source, veneer::io::Role::source);
  if (!options.rig.isEmpty()) connectToRig(options.rig, options.token_file);
}

MainWindow::~MainWindow() {
  cancel_ = true;
  job_cancel_ = true;
  job_future_.waitForFinished();
  transfer_watch_.waitForFinished();
  live_pool_.waitForDone();
  library_->flush();
}

// ---------------------------------------------------------------- layout

void MainWindow::buildUi() {
  setWindowTitle(tr("Veneer"));
  auto* split = new QSplitter(this);
  auto* side = new QWidget;
  auto* side_layout = new QVBoxLayout(side);
  side_layout->addWidget(buildConnectPanel());
  side_layout->addWidget(buildCapturePanel());
  side_layout->addWidget(buildSetsPanel(), 1);
  side_layout->addWidget(buildTransferPanel());
  auto* scroll = new QScrollArea;
  scroll->setWidget(side);
  scroll->setWidgetResizable(true);
  scroll->setMinimumWidth(330);
  split->addWidget(scroll);

  tabs_ = new QTabWidget;
  tabs_->setObjectName("tabs");
  tabs_->addTab(buildLookTab(), tr("Look"));
  tabs_->addTab(buildLiveTab(), tr("Live"));
  tabs_->addTab(buildRelightTab(), tr("Relight"));
  split->addWidget(tabs_);
  split->setStretchFactor(1, 1);
  setCentralWidget(split);

  status_label_ = new QLabel(tr("no rig"));
  status_label_->setObjectName("rigStatus");
  statusBar()->addPermanentWidget(status_label_);
  message_label_ = new QLabel;
  message_label_->setObjectName("message");
  step_bar_ = new QProgressBar;
  step_bar_->setObjectName("stepProgress");
  step_bar_->setMaximumWidth(140);
  step_bar_->setTextVisible(false);
  step_bar_->setVisible(false);
  step_label_ = new QLabel(tr("connect to a rig, then capture a source and a destination"));
  step_label_->setObjectName("stepStatus");
  // the one line: the step running and its progress first, the last message, the rig
  statusBar()->addWidget(step_label_, 3);
  statusBar()->addWidget(step_bar_);
  step_cancel_ = button(tr("Cancel"), "stepCancel", this);
  step_cancel_->setVisible(false);
  connect(step_cancel_, &QPushButton::clicked, this, &MainWindow::cancelStep);
  statusBar()->addWidget(step_cancel_);
  statusBar()->addWidget(message_label_, 2);
  resize(1400, 860);
}

QWidget* MainWindow::buildConnectPanel() {
  auto* box = new QGroupBox(tr("Rig"));
  auto* form = new QFormLayout(box);
  rig_edit_ = new QLineEdit(settings_.value("rig/last", "127.0.0.1:7878").toString());
  rig_edit_->setObjectName("rigAddress");
  token_edit_ = new QLineEdit(settings_.value("rig/token_file").toString());
  token_edit_->setObjectName("tokenFile");
  token_edit_->setPlaceholderText(tr("token file (the rig's <store>/token)"));
  recent_ = new QComboBox;
  recent_->setObjectName("recentRigs");
  recent_->addItems(settings_.value("rig/recent").toStringList());
  connect(recent_, &QComboBox::textActivated, rig_edit_, &QLineEdit::setText);
  connect_btn_ = button(tr("Connect"), "connect", box);
  connect(connect_btn_, &QPushButton::clicked, this, [this] {
    if (rig_.isConnected()) {
      rig_.disconnectFromRig();
    } else {
      connectToRig(rig_edit_->text(), token_edit_->text());
    }
  });
  auto* browse = button(tr("…"), "browseToken", box);
  connect(browse, &QPushButton::clicked, this, [this] {
    QString f = QFileDialog::getOpenFileName(this, tr("Token file"));
    if (!f.isEmpty()) token_edit_->setText(f);
  });
  auto* token_row = new QHBoxLayout;
  token_row->addWidget(token_edit_);
  token_row->addWidget(browse);
  form->addRow(tr("Address"), rig_edit_);
  form->addRow(tr("Recent"), recent_);
  form->addRow(tr("Token"), token_row);
  form->addRow(connect_btn_);
  return box;
}

QWidget* MainWindow::buildCapturePanel() {
  auto* box = new QGroupBox(tr("Capture"));
  auto* form = new QFormLayout(box);
  object_edit_ = new QLineEdit;
  object_edit_->setObjectName("objectName");
  object_edit_->setPlaceholderText(tr("object name (optional)"));
  shutter_ = new QDoubleSpinBox;
  shutter_->setObjectName("shutter");
  shutter_->setRange(0, 30);
  shutter_->setDecimals(4);
  shutter_->setSpecialValueText(tr("rig default"));
  aperture_ = new QDoubleSpinBox;
  aperture_->setObjectName("aperture");
  aperture_->setRange(0, 32);
  aperture_->setSpecialValueText(tr("rig default"));
  iso_ = new QSpinBox;
  iso_->setObjectName("iso");
  iso_->setRange(0, 25600);
  iso_->setSpecialValueText(tr("rig default"));
  auto_flow_ = new QCheckBox(tr("automatic: pull, compute the map, go live"));
  auto_flow_->setObjectName("autoFlow");
  auto_flow_->setChecked(true);
  auto_flow_->setToolTip(tr("every capture stored on the rig is pulled and used as its role; the map is computed "
                            "as soon as both sets are there and the live repaint starts"));
  form->addRow(auto_flow_);
  form->addRow(tr("Object"), object_edit_);
  form->addRow(tr("Shutter [s]"), shutter_);
  form->addRow(tr("Aperture f/"), aperture_);
  form->addRow(tr("ISO"), iso_);
  auto capture = capture_ = [this](veneer::io::Role role) {
    veneer::rig::CaptureOptions o;
    o.role = role;
    o.object = object_edit_->text().toStdString();
    o.shutter_s = shutter_->value();
    o.aperture = aperture_->value();
    o.iso = iso_->value();
    pending_role_ = veneer::io::role_name(role);
    rig_.capture(o);
  };
  auto* cap_dst = button(tr("Capture destination"), "captureDestination", box);
  auto* cap_src = button(tr("Capture source"), "captureSource", box);
  connect(cap_dst, &QPushButton::clicked, this, [capture] { capture(veneer::io::Role::destination); });
  connect(cap_src, &QPushButton::clicked, this, [capture] { capture(veneer::io::Role::source); });
  auto* press = button(tr("Press rig button"), "pressButton", box);
  connect(press, &QPushButton::clicked, this, [this] { rig_.pressButton(false); });
  auto* cancel = button(tr("Cancel capture"), "cancelCapture", box);
  connect(cancel, &QPushButton::clicked, this, [this] { rig_.cancelCapture(); });
  auto* row1 = new QHBoxLayout;
  row1->addWidget(cap_dst);
  row1->addWidget(cap_src);
  auto* row2 = new QHBoxLayout;
  row2->addWidget(press);
  row2->addWidget(cancel);
  form->addRow(row1);
  form->addRow(row2);
  shot_bar_ = new QProgressBar;
  shot_bar_->setObjectName("shotProgress");
  shot_bar_->setFormat(tr("shot %v of %m"));
  shot_bar_->setValue(0);
  capture_label_ = new QLabel(tr("idle"));
  capture_label_->setObjectName("captureStatus");
  capture_label_->setWordWrap(true);
  form->addRow(shot_bar_);
  form->addRow(capture_label_);
  return box;
}

void MainWindow::buildMenus() {
  QMenu* file = menuBar()->addMenu(tr("&File"));
  file->addAction(tr("Open set folder…"), this, [this] {
    QString dir = QFileDialog::getExistingDirectory(this, tr("Image set folder"));
    if (!dir.isEmpty()) loadSetInBackground(dir, veneer::io::Role::destination);
  });
  QMenu* exp = menuBar()->addMenu(tr("&Export"));
  exp->addAction(tr("Map (map.pfm, map.png)…"), this, &MainWindow::exportMap);
  exp->addAction(tr("Result pictures…"), this, &MainWindow::exportResults);
  exp->addAction(tr("Relight sweep video…"), this, &MainWindow::exportRelightVideo);
  exp->addAction(tr("Masks drawn by hand (for veneer transfer --dst-mask)…"), this, [this] {
    const QString dir = QFileDialog::getExistingDirectory(this, tr("Write the masks into"));
    if (!dir.isEmpty()) exportMasksTo(dir);
  });
  addCalibrationMenu(file);
  file->addSeparator();
  file->addAction(tr("Quit"), qApp, &QApplication::quit);
}

// ---------------------------------------------------------------- rig

void MainWindow::message(const QString& text, bool error) {
  last_message_ = text;
  message_label_->setText(text);
  message_label_->setStyleSheet(error ? "color: #e05050;" : "");
}

void MainWindow::connectToRig(const QString& endpoint, const QString& token_file) {
  rig_edit_->setText(endpoint);
  token_edit_->setText(token_file);
  if (token_file.isEmpty()) {
    message(tr("no token file given: the rig's token is in its store folder (<store>/token)"), true);
    return;
  }
  auto token = veneer::rig::read_token_file(token_file.toStdString());
  if (!token) {
    message(qs(token.message()), true);
    return;
  }
  settings_.setValue("rig/token_file", token_file);
  message(tr("connecting to %1…").arg(endpoint));
  rig_.connectTo(endpoint, qs(*token));
}

void MainWindow::rememberRig(const QString& endpoint) {
  QStringList recent = settings_.value("rig/recent").toStringList();
  recent.removeAll(endpoint);
  recent.prepend(endpoint);
  while (recent.size() > 8) recent.removeLast();
  settings_.setValue("rig/recent", recent);
  settings_.setValue("rig/last", endpoint);
  recent_->clear();
  recent_->addItems(recent);
}

void MainWindow::updateStatusLine() {
  if (!rig_.isConnected()) {
    status_label_->setText(tr("no rig"));
    return;
  }
  const auto& s = rig_.lastStatus();
  int on = static_cast<int>(std::count(s.lamps_on.begin(), s.lamps_on.end(), true));
  status_label_->setText(tr("%1%2 · %3%4 lamps (%5 on) · %6 GB free · %7 · %8 sets")
                             .arg(rig_.endpoint(), s.simulated ? tr(" (simulated)") : QString(),
                                  s.camera_connected ? QString() : tr("NO CAMERA · "))
                             .arg(s.lamp_count)
                             .arg(on)
                             .arg(s.free_bytes / 1e9, 0, 'f', 1)
                             .arg(s.you_control ? tr("you control")
                                                : (s.controller_taken ? tr("another client controls") : tr("free")))
                             .arg(s.sets_stored));
  status_label_->setToolTip(tr("camera: %1").arg(s.camera_connected ? qs(s.camera_model) : tr("missing")));
}

void MainWindow::onRigEvent(const veneer::rig::Event& e) {
  using K = veneer::rig::Event::Kind;
  switch (e.kind) {
    case K::button_pressed:
      capture_label_->setText(e.long_press ? tr("rig button: long press (cancel)") : tr("rig button pressed"));
      break;
    case K::capture_started:
      shot_bar_->setRange(0, std::max(1, e.n));
      shot_bar_->setValue(0);
      capture_label_->setText(tr("capturing %1 (%2)…").arg(qs(veneer::io::role_name(e.role)), qs(e.object)));
      step_.start("capture", tr("capturing the %1").arg(qs(veneer::io::role_name(e.role))));
      step_.update(0);
      showStep();
      break;
    case K::shot_taken:
      shot_bar_->setRange(0, std::max(1, e.n));
      shot_bar_->setValue(e.k);
      if (e.k < e.n) {
        step_.update(static_cast<double>(e.k) / std::max(1, e.n),
                     tr("capturing the %1: shot %2 of %3").arg(qs(veneer::io::role_name(e.role))).arg(e.k).arg(e.n));
      } else {  // the shots are done, the rig now writes the set: a step of its own
        step_.finish();
        step_.start("store", tr("storing the %1 on the rig").arg(qs(veneer::io::role_name(e.role))));
      }
      capture_label_->setText(step_.line());
      showStep();
      break;
    case K::set_stored: {
      step_.finish();
      shot_bar_->setValue(shot_bar_->maximum());
      QString text = e.role == veneer::io::Role::unknown
                         ? tr("stored %1").arg(qs(e.set_id))
                         : tr("stored %1 (%2)").arg(qs(e.set_id), qs(veneer::io::role_name(e.role)));
      for (const auto& w : e.warnings) text += "\n⚠ " + qs(w);
      capture_label_->setText(text);
      pending_role_.clear();
      rig_.listSets();
      rig_.refreshStatus();
      step_label_->setText(tr("stored %1").arg(qs(e.set_id)));
      flowSetStored(qs(e.set_id), e.role);
      break;
    }
    case K::capture_failed:
      capture_label_->setText(e.cancelled ? tr("capture cancelled") : tr("capture failed: %1").arg(qs(e.reason)));
      step_.finish();
      showStep();
      step_label_->setText(capture_label_->text());
      message(capture_label_->text(), !e.cancelled);
      pending_role_.clear();
      rig_.refreshStatus();
      break;
    case K::lamp_state:
      for (size_t i = 0; i < lamp_boxes_.size() && i < e.lamps_on.size(); ++i) {
        QSignalBlocker block(lamp_boxes_[i]);
        lamp_boxes_[i]->setChecked(e.lamps_on[i]);
      }
      break;
    case K::camera_connected:
    case K::camera_lost:
      message(qs(veneer::rig::describe(e)), e.kind == K::camera_lost);
      rig_.refreshStatus();
      break;
    case K::set_deleted:
    case K::set_restored:  // by this viewer or another client: both lists change
      rig_.listSets();
      break;
  }
}

}  // namespace veneer::app
