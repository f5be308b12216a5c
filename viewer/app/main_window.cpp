#include "main_window.hpp"

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
namespace {

const char* kMethods[] = {"combined", "coherent", "linear", "flann", "candidates", "patchmatch", "regiongrow", "baseline"};

QPushButton* button(const QString& text, const QString& name, QWidget* parent) {
  auto* b = new QPushButton(text, parent);
  b->setObjectName(name);
  return b;
}

// A number box of the transfer panel: range, decimals, step and start value.
QDoubleSpinBox* number_box(const QString& name, double lo, double hi, int decimals, double step, double value,
                           const QString& tip = {}) {
  auto* b = new QDoubleSpinBox;
  b->setObjectName(name);
  b->setRange(lo, hi);
  b->setDecimals(decimals);
  b->setSingleStep(step);
  b->setValue(value);
  if (!tip.isEmpty()) b->setToolTip(tip);
  return b;
}

cv::Mat picture_of(const cv::Mat& linear) { return linear.empty() ? cv::Mat() : tonemap_picture(linear); }

}  // namespace

MainWindow::MainWindow(const Options& options, QWidget* parent)
    : QMainWindow(parent), settings_("veneer", "veneer-viewer") {
  workdir_ = options.workdir.isEmpty()
                 ? QStandardPaths::writableLocation(QStandardPaths::AppLocalDataLocation)
                 : options.workdir;
  QDir().mkpath(workdir_ + "/sets");
  buildUi();
  buildMenus();

  connect(&rig_, &RigLink::connectedChanged, this, [this](bool ok, QString msg) {
    message(msg, !ok);
    connect_btn_->setText(ok ? tr("Disconnect") : tr("Connect"));
    if (ok) rememberRig(rig_.endpoint());
    if (!ok) qDeleteAll(rig_root_->takeChildren());
    updateStatusLine();
  });
  connect(&rig_, &RigLink::statusUpdated, this, [this](veneer::rig::RigStatus) { updateStatusLine(); });
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
  step_timer_.setInterval(250);
  connect(&step_timer_, &QTimer::timeout, this, &MainWindow::showStep);
  connect(&transfer_watch_, &QFutureWatcher<void>::finished, this, &MainWindow::onTransferDone);

  if (!options.destination.isEmpty()) loadLocalSet(options.destination, veneer::Role::destination);
  if (!options.source.isEmpty()) loadLocalSet(options.source, veneer::Role::source);
  if (!options.rig.isEmpty()) connectToRig(options.rig, options.token_file);
}

MainWindow::~MainWindow() {
  cancel_ = true;
  transfer_watch_.waitForFinished();
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
  auto capture = capture_ = [this](veneer::Role role) {
    veneer::rig::CaptureOptions o;
    o.role = role;
    o.object = object_edit_->text().toStdString();
    o.shutter_s = shutter_->value();
    o.aperture = aperture_->value();
    o.iso = iso_->value();
    pending_role_ = veneer::role_name(role);
    rig_.capture(o);
  };
  auto* cap_dst = button(tr("Capture destination"), "captureDestination", box);
  auto* cap_src = button(tr("Capture source"), "captureSource", box);
  connect(cap_dst, &QPushButton::clicked, this, [capture] { capture(veneer::Role::destination); });
  connect(cap_src, &QPushButton::clicked, this, [capture] { capture(veneer::Role::source); });
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

QWidget* MainWindow::buildSetsPanel() {
  auto* box = new QGroupBox(tr("Sets"));
  auto* layout = new QVBoxLayout(box);
  sets_tree_ = new QTreeWidget;
  sets_tree_->setObjectName("sets");
  sets_tree_->setHeaderLabels({tr("Set"), tr("Role"), tr("Object")});
  sets_tree_->setIconSize(QSize(64, 42));
  rig_root_ = new QTreeWidgetItem(sets_tree_, {tr("On the rig")});
  local_root_ = new QTreeWidgetItem(sets_tree_, {tr("On this computer")});
  rig_root_->setExpanded(true);
  local_root_->setExpanded(true);
  layout->addWidget(sets_tree_, 1);
  pull_bar_ = new QProgressBar;
  pull_bar_->setObjectName("pullProgress");
  pull_bar_->setVisible(false);
  layout->addWidget(pull_bar_);
  auto* row = new QHBoxLayout;
  auto* open = button(tr("Open folder…"), "openLocal", box);
  auto* pull = button(tr("Pull"), "pullSet", box);
  auto* del = button(tr("Delete"), "deleteSet", box);
  auto* use_dst = button(tr("→ Destination"), "useDestination", box);
  auto* use_src = button(tr("→ Source"), "useSource", box);
  for (auto* b : {open, pull, del}) row->addWidget(b);
  auto* row2 = new QHBoxLayout;
  row2->addWidget(use_dst);
  row2->addWidget(use_src);
  layout->addLayout(row);
  layout->addLayout(row2);
  connect(open, &QPushButton::clicked, this, [this] {
    QString dir = QFileDialog::getExistingDirectory(this, tr("Image set folder"));
    if (dir.isEmpty()) return;
    auto read = veneer::read_set(dir.toStdString());
    if (!read) {
      message(qs(read.message()), true);
      return;
    }
    addLocalItem(dir, *read);
  });
  connect(pull, &QPushButton::clicked, this, &MainWindow::pullSelected);
  connect(del, &QPushButton::clicked, this, [this] {
    QTreeWidgetItem* item = selectedItem();
    if (!item) return;
    if (item->parent() == rig_root_) {
      rig_.deleteSet(item->text(0));
    } else if (item->parent() == local_root_) {
      delete item;  // forgets it here; the folder on disk stays
    }
  });
  connect(use_dst, &QPushButton::clicked, this, [this] { useSelected(veneer::Role::destination); });
  connect(use_src, &QPushButton::clicked, this, [this] { useSelected(veneer::Role::source); });
  connect(sets_tree_, &QTreeWidget::itemDoubleClicked, this, [this](QTreeWidgetItem* item) {
    if (item->parent() == local_root_) {
      useSelected(item->text(1) == "source" ? veneer::Role::source : veneer::Role::destination);
    } else if (item->parent() == rig_root_) {
      pullSelected();
    }
  });
  return box;
}

QWidget* MainWindow::buildTransferPanel() {
  auto* box = new QGroupBox(tr("Transfer"));
  auto* form = new QFormLayout(box);
  method_ = new QComboBox;
  method_->setObjectName("method");
  for (const char* m : kMethods) method_->addItem(m);
  feature_ = new QComboBox;
  feature_->setObjectName("feature");
  feature_->addItems({"normals", "intensities"});
  patch_ = new QComboBox;
  patch_->setObjectName("patch");
  patch_->addItems({"1", "3", "5", "7"});
  const veneer::match::MatchOptions defaults;  // every matching box starts at the library's default
  const veneer::match::TransferOptions transfer_defaults;
  candidates_ = new QSpinBox;
  candidates_->setObjectName("candidates");
  candidates_->setRange(1, 100);
  candidates_->setValue(defaults.candidates);
  threshold_ = number_box("threshold", 0, 2, 3, 0.01, defaults.threshold);
  iterations_ = new QSpinBox;
  iterations_->setObjectName("iterations");
  iterations_->setRange(1, 50);
  iterations_->setValue(defaults.iterations);
  coherent_threshold_ = number_box("coherentThreshold", 0, 2, 3, 0.01, defaults.coherent_threshold,
                                   tr("coherent: the normal error a chunk may make (0.1 = about 6°; on intensities "
                                      "converted by the destination's own normals)"));
  coherent_smooth_ = number_box("coherentSmooth", 0, 20, 2, 0.25, defaults.coherent_smooth,
                                tr("coherent: how much a seam between two chunks costs, in coherent thresholds "
                                   "(0 = chunks only; larger = fewer seams, less exact shading)"));
  coherent_guide_ = number_box("coherentGuide", 0, 32, 1, 1, defaults.coherent_guide,
                               tr("coherent on normals: match the source's normals smoothed over this radius, so "
                                  "its small relief (dimples, grain) is copied whole (0 = off)"));
  coherent_guide_->setSuffix(tr(" px"));
  blend_ = new QSpinBox;
  blend_->setObjectName("blend");
  blend_->setRange(0, 16);
  blend_->setSuffix(tr(" px"));
  blend_->setValue(transfer_defaults.blend);
  blend_->setToolTip(tr("result pictures: blend the chunks meeting at a seam over this radius (0 = off: each "
                        "pixel its own source pixel)"));
  blend_guide_ = number_box("blendGuide", 0, 2, 2, 0.05, transfer_defaults.blend_guide,
                            tr("result pictures, maps matched on normals: blend only chunks whose normals fit "
                               "(fall-off |dn|, 0.1 = about 6°), so outlines such as a leg in front of the body "
                               "stay sharp (0 = plain blend)"));
  uniformity_ = number_box("uniformity", 0, 10, 2, 0.1, defaults.uniformity);
  fast_ = new QCheckBox(tr("fast engine"));
  fast_->setObjectName("fast");
  fast_->setChecked(true);
  truth_normals_ = new QCheckBox(tr("truth normals (simulated sets)"));
  truth_normals_->setObjectName("truthNormals");
  seg_method_ = new QComboBox;
  seg_method_->setObjectName("segMethod");
  seg_method_->addItems({"automatic", "otsu", "threshold"});
  seg_threshold_ = number_box("segThreshold", 0, 0.99, 3, 0.005, veneer::ps::SegmentOptions{}.threshold);
  rect_label_ = new QLabel(tr("no rectangle (shift+drag on the destination)"));
  rect_label_->setWordWrap(true);
  form->addRow(tr("Method"), method_);
  form->addRow(tr("Feature"), feature_);
  form->addRow(tr("Patch"), patch_);
  form->addRow(tr("Candidates K"), candidates_);
  form->addRow(tr("Region threshold"), threshold_);
  form->addRow(tr("PatchMatch iterations"), iterations_);
  form->addRow(tr("Coherent threshold"), coherent_threshold_);
  form->addRow(tr("Seam cost"), coherent_smooth_);
  form->addRow(tr("Source relief"), coherent_guide_);
  form->addRow(tr("Uniformity"), uniformity_);
  form->addRow(tr("Blend seams"), blend_);
  form->addRow(tr("Blend guide"), blend_guide_);
  form->addRow(fast_);
  form->addRow(truth_normals_);
  live_update_ = new QCheckBox(tr("recompute as options change"));
  live_update_->setObjectName("liveUpdate");
  live_update_->setChecked(true);
  live_update_->setToolTip(tr("after a first Compute, changing a matching option recomputes the map alone "
                              "(normals and masks are kept)"));
  form->addRow(live_update_);
  form->addRow(tr("Segmentation"), seg_method_);
  form->addRow(tr("Seg. threshold"), seg_threshold_);
  form->addRow(rect_label_);
  compute_btn_ = button(tr("Compute"), "compute", box);
  cancel_btn_ = button(tr("Cancel"), "cancelTransfer", box);
  cancel_btn_->setEnabled(false);
  connect(compute_btn_, &QPushButton::clicked, this, &MainWindow::startTransfer);
  connect(cancel_btn_, &QPushButton::clicked, this, &MainWindow::cancelTransfer);
  for (QComboBox* c : {method_, feature_, patch_})
    connect(c, &QComboBox::currentIndexChanged, this, &MainWindow::matchOptionChanged);
  for (QSpinBox* b : {candidates_, iterations_, blend_})
    connect(b, &QSpinBox::valueChanged, this, &MainWindow::matchOptionChanged);
  for (QDoubleSpinBox* b : {threshold_, coherent_threshold_, coherent_smooth_, coherent_guide_, uniformity_, blend_guide_})
    connect(b, &QDoubleSpinBox::valueChanged, this, &MainWindow::matchOptionChanged);
  connect(fast_, &QCheckBox::toggled, this, &MainWindow::matchOptionChanged);
  // segmentation and truth normals change the prepared objects: prepared again, then the map
  connect(truth_normals_, &QCheckBox::toggled, this, &MainWindow::matchOptionChanged);
  connect(seg_method_, &QComboBox::currentIndexChanged, this, &MainWindow::matchOptionChanged);
  connect(seg_threshold_, &QDoubleSpinBox::valueChanged, this, &MainWindow::matchOptionChanged);
  auto* row = new QHBoxLayout;
  row->addWidget(compute_btn_);
  row->addWidget(cancel_btn_);
  form->addRow(row);
  transfer_bar_ = new QProgressBar;
  transfer_bar_->setObjectName("transferProgress");
  transfer_label_ = new QLabel;
  transfer_label_->setObjectName("transferStatus");
  transfer_label_->setWordWrap(true);
  form->addRow(transfer_bar_);
  form->addRow(transfer_label_);
  return box;
}

QWidget* MainWindow::buildLookTab() {
  auto* w = new QWidget;
  auto* layout = new QVBoxLayout(w);
  auto* top = new QHBoxLayout;
  look_what_ = new QComboBox;
  look_what_->setObjectName("lookWhat");
  look_what_->addItems({tr("median of all lamps"), tr("normals"), tr("albedo"), tr("mask"),
                        tr("correspondence map"), tr("source reuse")});
  connect(look_what_, &QComboBox::currentIndexChanged, this, [this] { refreshLook(); });
  top->addWidget(new QLabel(tr("Show")));
  top->addWidget(look_what_);
  auto* reset = button(tr("Fit"), "fitViews", w);
  connect(reset, &QPushButton::clicked, this, [this] { sync_.reset(); });
  top->addWidget(reset);
  top->addStretch();
  layout->addLayout(top);
  auto* row = new QHBoxLayout;
  dst_view_ = new ImageView(tr("destination"));
  src_view_ = new ImageView(tr("source"));
  result_view_ = new ImageView(tr("result"));
  for (auto* v : {dst_view_, src_view_, result_view_}) {
    v->setSync(&sync_);
    row->addWidget(v);
  }
  layout->addLayout(row, 3);
  origin_view_ = new ImageView(tr("origin: click a destination or result pixel"));
  layout->addWidget(origin_view_, 2);
  connect(dst_view_, &ImageView::pixelClicked, this, &MainWindow::showOrigin);
  connect(result_view_, &ImageView::pixelClicked, this, &MainWindow::showOrigin);
  connect(dst_view_, &ImageView::rectDrawn, this, [this](QRect r) {
    seg_rect_ = r;
    rect_label_->setText(r.isEmpty() ? tr("no rectangle")
                                     : tr("rectangle %1,%2 %3x%4").arg(r.x()).arg(r.y()).arg(r.width()).arg(r.height()));
    matchOptionChanged();  // a new object outline: prepared again and matched
  });
  return w;
}

QWidget* MainWindow::buildLiveTab() {
  auto* w = new QWidget;
  auto* layout = new QVBoxLayout(w);
  auto* top = new QHBoxLayout;
  live_btn_ = button(tr("Start live view"), "liveToggle", w);
  live_btn_->setCheckable(true);
  fps_ = new QDoubleSpinBox;
  fps_->setObjectName("liveFps");
  fps_->setRange(1, 60);
  fps_->setValue(15);
  connect(live_btn_, &QPushButton::toggled, this, [this](bool on) {
    live_btn_->setText(on ? tr("Stop live view") : tr("Start live view"));
    if (on) {
      live_clock_.start();
      live_frames_ = 0;
      rig_.startLive(fps_->value());
    } else {
      rig_.stopLive();
    }
  });
  top->addWidget(live_btn_);
  auto* live_cap_src = button(tr("Capture source"), "liveCaptureSource", w);
  auto* live_cap_dst = button(tr("Capture destination"), "liveCaptureDestination", w);
  connect(live_cap_src, &QPushButton::clicked, this, [this] { capture_(veneer::Role::source); });
  connect(live_cap_dst, &QPushButton::clicked, this, [this] { capture_(veneer::Role::destination); });
  top->addWidget(live_cap_src);
  top->addWidget(live_cap_dst);
  top->addWidget(new QLabel(tr("fps")));
  top->addWidget(fps_);
  top->addWidget(new QLabel(tr("Lamps:")));
  for (int i = 0; i < 7; ++i) {
    auto* box = new QCheckBox(QString::number(i + 1));
    box->setObjectName(QString("lamp%1").arg(i + 1));
    lamp_boxes_.push_back(box);
    top->addWidget(box);
    connect(box, &QCheckBox::toggled, this, [this] {
      std::vector<bool> on;
      for (auto* b : lamp_boxes_) on.push_back(b->isChecked());
      on.resize(std::max<size_t>(on.size(), static_cast<size_t>(rig_.lastStatus().lamp_count)), false);
      if (rig_.lastStatus().lamp_count > 0) on.resize(static_cast<size_t>(rig_.lastStatus().lamp_count));
      rig_.setLamps(on, 254);
    });
  }
  top->addStretch();
  live_label_ = new QLabel;
  live_label_->setObjectName("liveStatus");
  top->addWidget(live_label_);
  layout->addLayout(top);
  auto* row = new QHBoxLayout;
  live_src_view_ = new ImageView(tr("source, live"));
  live_dst_view_ = new ImageView(tr("destination, repainted live"));
  row->addWidget(live_src_view_, 3);
  row->addWidget(live_dst_view_, 3);
  auto* pad_box = new QVBoxLayout;
  pad_box->addWidget(new QLabel(tr("hand-held lamp\n(simulated rig)")));
  hand_pad_ = new SpherePad;
  hand_pad_->setObjectName("handLamp");
  connect(hand_pad_, &SpherePad::directionChanged, this, [this](cv::Vec3d d) {
    // The lamp 0.6 m from the object in the chosen direction.
    rig_.moveHandLamp(d * 0.6);
  });
  pad_box->addWidget(hand_pad_);
  pad_box->addStretch();
  row->addLayout(pad_box, 1);
  layout->addLayout(row, 1);
  return w;
}

QWidget* MainWindow::buildRelightTab() {
  auto* w = new QWidget;
  auto* layout = new QHBoxLayout(w);
  auto* left = new QVBoxLayout;
  left->addWidget(new QLabel(tr("Drag the light over the sphere")));
  relight_pad_ = new SpherePad;
  relight_pad_->setObjectName("relightPad");
  relight_pad_->setDirection(cv::Vec3d(-0.4, 0.4, std::sqrt(1 - 0.32)));
  connect(relight_pad_, &SpherePad::directionChanged, this, [this] { refreshRelight(); });
  left->addWidget(relight_pad_);
  relight_label_ = new QLabel;
  relight_label_->setWordWrap(true);
  left->addWidget(relight_label_);
  left->addStretch();
  layout->addLayout(left, 1);
  relight_src_view_ = new ImageView(tr("source under the virtual light"));
  relight_view_ = new ImageView(tr("destination relit in the source's material"));
  layout->addWidget(relight_src_view_, 3);
  layout->addWidget(relight_view_, 3);
  return w;
}

void MainWindow::buildMenus() {
  QMenu* file = menuBar()->addMenu(tr("&File"));
  file->addAction(tr("Open set folder…"), this, [this] {
    QString dir = QFileDialog::getExistingDirectory(this, tr("Image set folder"));
    if (!dir.isEmpty()) loadLocalSet(dir, veneer::Role::destination);
  });
  QMenu* exp = menuBar()->addMenu(tr("&Export"));
  exp->addAction(tr("Map (map.pfm, map.png)…"), this, &MainWindow::exportMap);
  exp->addAction(tr("Result pictures…"), this, &MainWindow::exportResults);
  exp->addAction(tr("Relight sweep video…"), this, &MainWindow::exportRelightVideo);
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
      capture_label_->setText(tr("capturing %1 (%2)…").arg(qs(veneer::role_name(e.role)), qs(e.object)));
      step_.start("capture", tr("capturing the %1").arg(qs(veneer::role_name(e.role))));
      step_.update(0);
      showStep();
      break;
    case K::shot_taken:
      shot_bar_->setRange(0, std::max(1, e.n));
      shot_bar_->setValue(e.k);
      if (e.k < e.n) {
        step_.update(static_cast<double>(e.k) / std::max(1, e.n),
                     tr("capturing the %1: shot %2 of %3").arg(qs(veneer::role_name(e.role))).arg(e.k).arg(e.n));
      } else {  // the shots are done, the rig now writes the set: a step of its own
        step_.finish();
        step_.start("store", tr("storing the %1 on the rig").arg(qs(veneer::role_name(e.role))));
      }
      capture_label_->setText(step_.line());
      showStep();
      break;
    case K::set_stored: {
      step_.finish();
      shot_bar_->setValue(shot_bar_->maximum());
      QString text = e.role == veneer::Role::unknown
                         ? tr("stored %1").arg(qs(e.set_id))
                         : tr("stored %1 (%2)").arg(qs(e.set_id), qs(veneer::role_name(e.role)));
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
      rig_.listSets();
      break;
  }
}

void MainWindow::onSetsListed(const std::vector<veneer::rig::SetSummary>& sets) {
  qDeleteAll(rig_root_->takeChildren());
  for (const auto& s : sets) {
    auto* item = new QTreeWidgetItem(rig_root_, {qs(s.id), qs(veneer::role_name(s.role)), qs(s.object)});
    QString tip = tr("%1x%2, %3 lamps, %4").arg(s.size.width).arg(s.size.height).arg(s.lights).arg(qs(s.created));
    for (const auto& w : s.warnings) tip += "\n⚠ " + qs(w);
    item->setToolTip(0, tip);
  }
  rig_root_->setExpanded(true);
}

QTreeWidgetItem* MainWindow::selectedItem() const {
  auto items = sets_tree_->selectedItems();
  if (items.isEmpty() || !items.front()->parent()) return nullptr;
  return items.front();
}

void MainWindow::pullSelected() {
  QTreeWidgetItem* item = selectedItem();
  if (!item || item->parent() != rig_root_) {
    message(tr("choose a set on the rig to pull"), true);
    return;
  }
  pull_bar_->setVisible(true);
  pull_bar_->setValue(0);
  rig_.pull(item->text(0), workdir_ + "/sets/" + item->text(0));
}

void MainWindow::addLocalItem(const QString& folder, const veneer::ImageSet& set, const cv::Mat& thumbnail) {
  // A folder already listed is updated in place (its row keeps its position).
  QTreeWidgetItem* item = nullptr;
  for (int i = 0; i < local_root_->childCount() && !item; ++i)
    if (local_root_->child(i)->data(0, Qt::UserRole).toString() == folder) item = local_root_->child(i);
  if (!item) item = new QTreeWidgetItem(local_root_);
  item->setText(0, QFileInfo(folder).fileName());
  item->setText(1, qs(veneer::role_name(set.role)));
  item->setText(2, qs(set.object));
  item->setData(0, Qt::UserRole, folder);
  item->setToolTip(0, folder);
  if (!thumbnail.empty()) {
    item->setIcon(0, QIcon(QPixmap::fromImage(to_qimage(thumbnail))));
  } else if (!set.images.empty()) {
    cv::Mat small;
    cv::resize(set.images.front(), small, cv::Size(96, std::max(1, 96 * set.size.height / std::max(1, set.size.width))),
               0, 0, cv::INTER_AREA);
    item->setIcon(0, QIcon(QPixmap::fromImage(to_qimage(small))));
  }
  local_root_->setExpanded(true);
}

void MainWindow::useSelected(veneer::Role as) {
  QTreeWidgetItem* item = selectedItem();
  if (!item || item->parent() != local_root_) {
    message(tr("choose a set on this computer (pull rig sets first)"), true);
    return;
  }
  loadLocalSet(item->data(0, Qt::UserRole).toString(), as);
}

bool MainWindow::loadLocalSet(const QString& folder, veneer::Role as) {
  auto read = veneer::read_set(folder.toStdString());
  if (!read) {
    message(qs(read.message()), true);
    return false;
  }
  auto loaded = std::make_shared<LoadedSet>();
  loaded->folder = folder;
  loaded->set = std::move(*read);
  loaded->median = veneer::match::median_photo(loaded->set.images);
  loaded->median_picture = picture_of(loaded->median);
  addLocalItem(folder, loaded->set);
  setLoaded(loaded, as);
  computeNormals(loaded);
  message(tr("loaded %1 as the %2").arg(folder, qs(veneer::role_name(as))));
  return true;
}

void MainWindow::setLoaded(std::shared_ptr<LoadedSet> loaded, veneer::Role as) {
  if (as == veneer::Role::source) {
    src_ = loaded;
  } else {
    dst_ = loaded;
  }
  ++sets_loaded_;
  result_.reset();
  relighter_.reset();
  repainter_ = {};
  refreshLook();
}

void MainWindow::computeNormals(std::shared_ptr<LoadedSet> loaded) {
  QPointer<MainWindow> self(this);
  (void)QtConcurrent::run([self, loaded] {
    auto seg = veneer::ps::segment(loaded->set);
    if (!seg) return;
    auto ps = veneer::ps::photometric_stereo(loaded->set, seg->mask);
    if (!ps) return;
    auto result = std::make_shared<veneer::ps::PsResult>(std::move(*ps));
    if (!self) return;
    QMetaObject::invokeMethod(self.data(), [self, loaded, result] {
      if (!self) return;
      loaded->normals = *result;
      self->refreshLook();
    });
  });
}

// ---------------------------------------------------------------- transfer

void MainWindow::startTransfer() {
  if (computing_) return;
  if (!dst_ || !src_) {
    message(tr("load a destination and a source set first"), true);
    return;
  }
  veneer::match::TransferOptions options;
  auto method = veneer::match::parse_method(method_->currentText().toStdString());
  auto feature = veneer::match::parse_feature(feature_->currentText().toStdString());
  if (!method || !feature) {
    message(qs(!method ? method.message() : feature.message()), true);
    return;
  }
  options.match.method = *method;
  options.match.feature = *feature;
  options.match.patch = patch_->currentText().toInt();
  options.match.candidates = candidates_->value();
  options.match.threshold = threshold_->value();
  options.match.iterations = iterations_->value();
  options.match.coherent_threshold = coherent_threshold_->value();
  options.match.uniformity = uniformity_->value();
  options.match.coherent_smooth = coherent_smooth_->value();
  options.match.coherent_guide = coherent_guide_->value();
  options.match.fast = fast_->isChecked();
  options.truth_normals = truth_normals_->isChecked();
  options.blend = blend_->value();
  options.blend_guide = blend_guide_->value();
  if (auto ok = options.check(); !ok) {
    message(qs(ok.message()), true);
    return;
  }
  veneer::ps::SegmentOptions seg;
  seg.method = seg_method_->currentText() == "otsu"        ? veneer::ps::SegmentMethod::otsu
               : seg_method_->currentText() == "threshold" ? veneer::ps::SegmentMethod::threshold
                                                           : veneer::ps::SegmentMethod::automatic;
  seg.threshold = seg_threshold_->value();
  if (!seg_rect_.isEmpty()) seg.rect = cv::Rect(seg_rect_.x(), seg_rect_.y(), seg_rect_.width(), seg_rect_.height());
  const bool custom_segmentation = seg.method != veneer::ps::SegmentMethod::automatic || seg.rect.has_value();

  computing_ = true;
  cancel_ = false;
  compute_btn_->setEnabled(false);
  cancel_btn_->setEnabled(true);
  transfer_bar_->setValue(0);
  transfer_label_->setText(tr("computing…"));
  step_.start("compute", tr("computing the map (%1)").arg(method_->currentText()));
  step_.update(0);
  showStep();
  transfer_error_.clear();
  relight_error_.clear();
  pending_result_.reset();
  pending_relighter_.reset();
  auto dst = dst_, src = src_;
  // the prepared objects are kept while what made them stays the same
  const QString key = preparationKey();
  auto cached = key == prepared_key_ ? prepared_ : nullptr;
  auto relighter = cached ? relighter_ : nullptr;
  // the same matching options as the map shown (only the blend changed, or
  // Compute again): repainted from that map, not matched again
  std::shared_ptr<const veneer::match::TransferResult> previous =
      cached && result_ && result_->match_options == options.match ? result_ : nullptr;
  if (previous)
    ++repaint_only_runs_;
  else if (cached)
    ++map_only_runs_;
  pending_prepared_.reset();
  pending_key_ = key;
  pending_repainter_.reset();
  pending_result_picture_ = cv::Mat();
  pending_relit_ = pending_relit_source_ = cv::Mat();
  const cv::Vec3d light = relight_pad_->direction();
  QPointer<MainWindow> self(this);
  transfer_watch_.setFuture(QtConcurrent::run([this, self, dst, src, options, seg, custom_segmentation, cached,
                                               previous, relighter, light] {
    veneer::Progress progress;
    progress.cancel = &cancel_;
    progress.on_progress = [self](double f, const std::string& stage) {
      const QString s = qs(stage);
      if (self)
        QMetaObject::invokeMethod(self.data(), [self, f, s] {
          if (!self) return;
          self->transfer_bar_->setValue(static_cast<int>(f * 100));
          self->transfer_label_->setText(s);
          if (self->computing_) {
            self->step_.update(f, tr("computing the map: %1").arg(s));
            self->showStep();
          }
        });
    };
    std::shared_ptr<const veneer::match::PreparedPair> pair = cached;
    if (!pair) {
      veneer::ImageSet d = dst->set;
      if (custom_segmentation) {
        // The user's threshold / rectangle decide the destination's object pixels.
        auto m = veneer::ps::segment(d, seg);
        if (!m) {
          transfer_error_ = tr("segmentation: %1").arg(qs(m.message()));
          return;
        }
        d.mask = m->mask;
      }
      auto prepared = veneer::match::prepare_pair(d, src->set, options, progress);
      if (!prepared) {
        transfer_error_ = qs(prepared.message());
        return;
      }
      pair = std::make_shared<const veneer::match::PreparedPair>(std::move(*prepared));
      pending_prepared_ = pair;
    }
    auto result = previous ? veneer::match::transfer(*pair, options, previous->map, progress)
                           : veneer::match::transfer(*pair, options, progress);
    if (!result) {
      transfer_error_ = qs(result.message());
      return;
    }
    pending_result_ = std::make_shared<veneer::match::TransferResult>(std::move(*result));
    // what showing the result needs, made here rather than on the GUI thread
    pending_result_picture_ = picture_of(pending_result_->repainted_median);
    pending_repainter_.emplace(pending_result_->map, pending_result_->source_size, dst->median_picture,
                               pending_result_->blend);
    if (relighter) {  // same source as last time
      pending_relighter_ = relighter;
    } else {
      auto fitted = veneer::match::Relighter::fit(src->set);
      if (fitted) {
        pending_relighter_ = std::make_shared<veneer::match::Relighter>(std::move(*fitted));
      } else {
        relight_error_ = qs(fitted.message());
      }
    }
    if (pending_relighter_) {
      pending_relit_ = picture_of(pending_relighter_->render(pending_result_->map, light, dst->median * 0.25));
      pending_relit_source_ = picture_of(pending_relighter_->render_source(light));
      pending_relit_direction_ = light;
    }
  }));
}

void MainWindow::cancelTransfer() {
  if (!computing_) return;
  cancel_ = true;
  transfer_label_->setText(tr("cancelling…"));
}

// What the prepared objects depend on: the sets loaded, truth normals, the
// segmentation settings. Anything else is a matching option.
QString MainWindow::preparationKey() const {
  return QString("%1|%2|%3|%4|%5,%6,%7,%8")
      .arg(sets_loaded_)  // a set (re)loaded: everything is prepared again
      .arg(truth_normals_->isChecked())
      .arg(seg_method_->currentText())
      .arg(seg_threshold_->value())
      .arg(seg_rect_.x())
      .arg(seg_rect_.y())
      .arg(seg_rect_.width())
      .arg(seg_rect_.height());
}

// An option changed: once a transfer has been shown, recompute (the map alone
// when only matching options changed, the objects kept); while one runs,
// once more when it ends.
void MainWindow::matchOptionChanged() {
  if (!live_update_ || !live_update_->isChecked() || !result_) return;
  if (computing_) {
    rerun_ = true;
    return;
  }
  startTransfer();
}

void MainWindow::onTransferDone() {
  computing_ = false;
  step_.finish();
  compute_btn_->setEnabled(true);
  cancel_btn_->setEnabled(false);
  if (pending_prepared_) {
    prepared_ = pending_prepared_;
    prepared_key_ = pending_key_;
    pending_prepared_.reset();
  }
  if (rerun_) {  // the options moved on while this ran: show the latest
    rerun_ = false;
    if (pending_result_) {
      result_ = pending_result_;
      relighter_ = pending_relighter_;
      result_picture_ = pending_result_picture_;
    }
    startTransfer();
    return;
  }
  if (!pending_result_) {
    const bool cancelled = cancel_.load();
    transfer_label_->setText(cancelled ? tr("cancelled") : tr("failed: %1").arg(transfer_error_));
    message(cancelled ? tr("transfer cancelled") : tr("transfer failed: %1").arg(transfer_error_), !cancelled);
    transfer_bar_->setValue(0);
    step_label_->setText(transfer_label_->text());
    showStep();
    return;
  }
  result_ = pending_result_;
  relighter_ = pending_relighter_;
  transfer_bar_->setValue(100);
  QString text = tr("done");
  if (result_->quality) {
    const auto& q = *result_->quality;
    text += tr(" · coverage %1% · coherence %2%").arg(q.coverage * 100, 0, 'f', 1).arg(q.coherence * 100, 0, 'f', 1);
    if (q.normal_mean_deg) text += tr(" · normals %1°").arg(*q.normal_mean_deg, 0, 'f', 2);
  }
  if (result_->map_given)
    text += tr(" · map kept");
  else
    text += tr(" · map %1 ms").arg(result_->match_seconds * 1000, 0, 'f', 1);
  transfer_label_->setText(text);
  message(tr("transfer done (%1)").arg(method_->currentText()));
  showStep();
  step_label_->setText(tr("map computed: ") + text);
  result_picture_ = pending_result_picture_;
  if (pending_repainter_) repainter_ = std::move(*pending_repainter_);
  pending_repainter_.reset();
  if (look_what_->currentIndex() != 0)
    look_what_->setCurrentIndex(0);  // refreshes the views
  else
    refreshLook();
  if (relighter_ && !pending_relit_.empty() && pending_relit_direction_ == relight_pad_->direction()) {
    // the worker rendered it for this direction
    relight_view_->setImage(to_qimage(pending_relit_));
    relight_src_view_->setImage(to_qimage(pending_relit_source_));
    updateRelightLabel(pending_relit_direction_);
  } else {
    refreshRelight();
  }
  flowMaybeGoLive();
}

// ---------------------------------------------------------------- views

void MainWindow::refreshLook() {
  const int what = look_what_->currentIndex();
  auto pick = [what](const std::shared_ptr<LoadedSet>& s) -> cv::Mat {
    if (!s) return {};
    switch (what) {
      case 1: return s->normals ? normals_picture(s->normals->normals) : cv::Mat();
      case 2: return s->normals ? picture_of(s->normals->albedo) : cv::Mat();
      case 3: return s->normals ? s->normals->mask : cv::Mat();
      default: return s->median_picture.empty() ? picture_of(s->median) : s->median_picture;
    }
  };
  dst_view_->setImage(to_qimage(pick(dst_)));
  src_view_->setImage(to_qimage(pick(src_)));
  if (result_) {
    cv::Mat r;
    if (what == 4) {
      r = veneer::match::map_picture(result_->map, result_->source_size);
    } else if (what == 5) {
      r = veneer::match::reuse_picture(result_->reuse, result_->source_median);
      src_view_->setImage(to_qimage(r));
      r = result_picture_.empty() ? picture_of(result_->repainted_median) : result_picture_;
    } else {
      r = result_picture_.empty() ? picture_of(result_->repainted_median) : result_picture_;
    }
    result_view_->setImage(to_qimage(r));
  } else {
    result_view_->setImage({});
  }
}

void MainWindow::showOrigin(QPoint p) {
  if (!result_ || !dst_ || !src_) {
    message(tr("compute a transfer first; then a click shows where a pixel's look comes from"), true);
    return;
  }
  const auto& map = result_->map;
  if (p.x() >= map.xy.cols || p.y() >= map.xy.rows) return;
  const cv::Vec2f m = map.xy.at<cv::Vec2f>(p.y(), p.x());
  std::vector<ImageView::Marker> dst_markers{{QPointF(p), QColor(0, 220, 255), m[0] < 0}};
  dst_view_->setMarkers(dst_markers);
  result_view_->setMarkers(dst_markers);
  if (m[0] >= 0) {
    src_view_->setMarkers({{QPointF(m[0], m[1]), QColor(0, 220, 255), false}});
    message(tr("destination (%1, %2) ← source (%3, %4), distance %5")
                .arg(p.x()).arg(p.y()).arg(m[0], 0, 'f', 0).arg(m[1], 0, 'f', 0)
                .arg(map.distance.at<float>(p.y(), p.x()), 0, 'g', 3));
  } else {
    src_view_->setMarkers({});
    message(tr("destination (%1, %2) is not mapped").arg(p.x()).arg(p.y()));
  }
  origin_view_->setImage(to_qimage(
      veneer::match::origin_picture(map, dst_->median, src_->median, {cv::Point(p.x(), p.y())})));
}

void MainWindow::refreshRelight() {
  if (result_ && !relight_error_.isEmpty()) {
    relight_label_->setText(relight_error_);
    return;
  }
  if (!result_ || !relighter_ || !dst_) {
    relight_label_->setText(tr("compute a transfer first"));
    return;
  }
  const cv::Vec3d d = relight_pad_->direction();
  cv::Mat backdrop = dst_->median * 0.25;  // the destination dimmed where nothing is mapped
  relight_view_->setImage(to_qimage(relighter_->render(result_->map, d, backdrop)));
  relight_src_view_->setImage(to_qimage(relighter_->render_source(d)));
  updateRelightLabel(d);
}

void MainWindow::updateRelightLabel(const cv::Vec3d& d) {
  relight_label_->setText(tr("light (%1, %2, %3)\n%4 fit, RMS %5")
                              .arg(d[0], 0, 'f', 2).arg(d[1], 0, 'f', 2).arg(d[2], 0, 'f', 2)
                              .arg(relighter_->basis_name())
                              .arg(relighter_->fit_rms(), 0, 'f', 4));
}

void MainWindow::onLiveFrame(const veneer::rig::LiveFrame& frame) {
  cv::Mat decoded = cv::imdecode(frame.jpeg, cv::IMREAD_COLOR);
  if (decoded.empty()) {
    message(tr("live view: a frame that is not a JPEG was dropped"), true);
    return;
  }
  live_frame_ = decoded;
  ++live_frames_;
  if (live_clock_.isValid() && live_clock_.elapsed() > 0) live_fps_ = live_frames_ * 1000.0 / live_clock_.elapsed();
  live_src_view_->setImage(to_qimage(decoded));
  if (repainter_.ready()) {
    live_repainted_ = repainter_.apply(decoded);
    live_dst_view_->setImage(to_qimage(live_repainted_));
  }
  live_label_->setText(tr("frame %1 · %2 fps").arg(frame.seq).arg(live_fps_, 0, 'f', 1));
  if (!step_.running())
    step_label_->setText((repainter_.ready() ? tr("live repaint · ") : tr("live view (no map yet) · ")) +
                         live_label_->text());
}

// ---------------------------------------------------------------- export

void MainWindow::exportMap() {
  if (!result_) return message(tr("nothing to export: compute a transfer first"), true);
  QString dir = QFileDialog::getExistingDirectory(this, tr("Export the map into"));
  if (dir.isEmpty()) return;
  auto s = veneer::match::write_map((dir + "/map.pfm").toStdString(), result_->map);
  if (!s) return message(qs(s.message()), true);
  cv::imwrite((dir + "/map.png").toStdString(), veneer::match::map_picture(result_->map, result_->source_size));
  message(tr("map written to %1").arg(dir));
}

void MainWindow::exportResults() {
  if (!result_) return message(tr("nothing to export: compute a transfer first"), true);
  QString dir = QFileDialog::getExistingDirectory(this, tr("Export the results into"));
  if (dir.isEmpty()) return;
  auto s = veneer::match::write_transfer(*result_, dir.toStdString());
  message(s ? tr("results written to %1").arg(dir) : qs(s.message()), !s);
}

void MainWindow::exportRelightVideo() {
  if (!result_ || !relighter_ || !dst_) return message(tr("nothing to export: compute a transfer first"), true);
  QString file = QFileDialog::getSaveFileName(this, tr("Relight sweep video"), "relight.avi", "AVI (*.avi)");
  if (file.isEmpty()) return;
  const cv::Size size = result_->map.xy.size();
  cv::VideoWriter writer(file.toStdString(), cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 25, size);
  if (!writer.isOpened()) return message(tr("cannot write a video to %1").arg(file), true);
  cv::Mat backdrop = dst_->median * 0.25;
  for (int i = 0; i < 100; ++i) {
    const double a = 2 * M_PI * i / 100.0;
    const cv::Vec3d d = veneer::match::direction_on_sphere(0.7 * std::cos(a), 0.7 * std::sin(a));
    writer << tonemap_picture(relighter_->render(result_->map, d, backdrop));
  }
  message(tr("relight sweep written to %1").arg(file));
}

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

}  // namespace veneer::app
