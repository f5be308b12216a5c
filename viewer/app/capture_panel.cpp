#include "capture_panel.hpp"

#include <algorithm>

#include <QCheckBox>
#include <QDoubleSpinBox>
#include <QFormLayout>
#include <QHBoxLayout>
#include <QLabel>
#include <QLineEdit>
#include <QProgressBar>
#include <QPushButton>
#include <QSpinBox>

#include "widgets.hpp"

namespace veneer::app {

CapturePanel::CapturePanel(Session& session, QWidget* parent) : QGroupBox(tr("Capture"), parent), session_(session) {
  auto* form = new QFormLayout(this);
  object_edit_ = named<QLineEdit>("objectName");
  object_edit_->setPlaceholderText(tr("object name (optional)"));
  shutter_ = named<QDoubleSpinBox>("shutter");
  shutter_->setRange(0, 30);
  shutter_->setDecimals(4);
  shutter_->setSpecialValueText(tr("rig default"));
  aperture_ = named<QDoubleSpinBox>("aperture");
  aperture_->setRange(0, 32);
  aperture_->setSpecialValueText(tr("rig default"));
  iso_ = named<QSpinBox>("iso");
  iso_->setRange(0, 25600);
  iso_->setSpecialValueText(tr("rig default"));
  auto_flow_ = check_box("autoFlow", tr("automatic: pull, compute the map, go live"), true,
                         tr("every capture stored on the rig is pulled and used as its role; the map is computed "
                            "as soon as both sets are there and the live repaint starts"));
  form->addRow(auto_flow_);
  form->addRow(tr("Object"), object_edit_);
  form->addRow(tr("Shutter [s]"), shutter_);
  form->addRow(tr("Aperture f/"), aperture_);
  form->addRow(tr("ISO"), iso_);
  auto* cap_dst = button(tr("Capture destination"), "captureDestination", this);
  auto* cap_src = button(tr("Capture source"), "captureSource", this);
  connect(cap_dst, &QPushButton::clicked, this, [this] { capture(veneer::io::Role::destination); });
  connect(cap_src, &QPushButton::clicked, this, [this] { capture(veneer::io::Role::source); });
  auto* press = button(tr("Press rig button"), "pressButton", this);
  connect(press, &QPushButton::clicked, this, [this] { session_.rig.pressButton(false); });
  auto* cancel = button(tr("Cancel capture"), "cancelCapture", this);
  connect(cancel, &QPushButton::clicked, this, [this] { session_.rig.cancelCapture(); });
  auto* row1 = new QHBoxLayout;
  row1->addWidget(cap_dst);
  row1->addWidget(cap_src);
  auto* row2 = new QHBoxLayout;
  row2->addWidget(press);
  row2->addWidget(cancel);
  form->addRow(row1);
  form->addRow(row2);
  shot_bar_ = named<QProgressBar>("shotProgress");
  shot_bar_->setFormat(tr("shot %v of %m"));
  shot_bar_->setValue(0);
  capture_label_ = named<QLabel>("captureStatus", tr("idle"));
  capture_label_->setWordWrap(true);
  form->addRow(shot_bar_);
  form->addRow(capture_label_);
  connect(&session_.rig, &RigLink::rigEvent, this, &CapturePanel::onRigEvent);
}

bool CapturePanel::autoFlow() const { return auto_flow_->isChecked(); }

void CapturePanel::setAutoFlow(bool on) { auto_flow_->setChecked(on); }

void CapturePanel::capture(veneer::io::Role role) {
  veneer::rig::CaptureOptions o;
  o.role = role;
  o.object = object_edit_->text().toStdString();
  o.shutter_s = shutter_->value();
  o.aperture = aperture_->value();
  o.iso = iso_->value();
  session_.rig.capture(o);
}

void CapturePanel::onRigEvent(const veneer::rig::Event& e) {
  using K = veneer::rig::Event::Kind;
  StatusLine& status = session_.status;
  StepClock& step = status.step();
  switch (e.kind) {
    case K::button_pressed:
      capture_label_->setText(e.long_press ? tr("rig button: long press (cancel)") : tr("rig button pressed"));
      break;
    case K::capture_started:
      shot_bar_->setRange(0, std::max(1, e.n));
      shot_bar_->setValue(0);
      capture_label_->setText(tr("capturing %1 (%2)…").arg(qs(veneer::io::role_name(e.role)), qs(e.object)));
      step.start("capture", tr("capturing the %1").arg(qs(veneer::io::role_name(e.role))));
      step.update(0);
      status.showStep();
      break;
    case K::shot_taken:
      shot_bar_->setRange(0, std::max(1, e.n));
      shot_bar_->setValue(e.k);
      if (e.k < e.n) {
        step.update(static_cast<double>(e.k) / std::max(1, e.n),
                    tr("capturing the %1: shot %2 of %3").arg(qs(veneer::io::role_name(e.role))).arg(e.k).arg(e.n));
      } else {  // the shots are done, the rig now writes the set: a step of its own
        step.finish();
        step.start("store", tr("storing the %1 on the rig").arg(qs(veneer::io::role_name(e.role))));
      }
      capture_label_->setText(step.line());
      status.showStep();
      break;
    case K::set_stored: {
      step.finish();
      shot_bar_->setValue(shot_bar_->maximum());
      QString text = e.role == veneer::io::Role::unknown
                         ? tr("stored %1").arg(qs(e.set_id))
                         : tr("stored %1 (%2)").arg(qs(e.set_id), qs(veneer::io::role_name(e.role)));
      for (const auto& w : e.warnings) text += "\n⚠ " + qs(w);
      capture_label_->setText(text);
      session_.rig.listSets();
      session_.rig.refreshStatus();
      status.say(tr("stored %1").arg(qs(e.set_id)));
      emit setStored(qs(e.set_id), e.role);
      break;
    }
    case K::capture_failed:
      capture_label_->setText(e.cancelled ? tr("capture cancelled") : tr("capture failed: %1").arg(qs(e.reason)));
      step.finish();
      status.showStep();
      status.say(capture_label_->text());
      session_.message(capture_label_->text(), !e.cancelled);
      session_.rig.refreshStatus();
      break;
    default:  // lamps, camera, deleted sets: the Live tab, the Rig and Sets panels
      break;
  }
}

}  // namespace veneer::app
