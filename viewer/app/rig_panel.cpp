#include "rig_panel.hpp"

#include <algorithm>

#include <QComboBox>
#include <QFileDialog>
#include <QFormLayout>
#include <QHBoxLayout>
#include <QLabel>
#include <QLineEdit>
#include <QMessageBox>
#include <QPushButton>

#include "widgets.hpp"

namespace veneer::app {

RigPanel::RigPanel(Session& session, QWidget* parent)
    : QGroupBox(tr("Rig"), parent), session_(session) {
  auto* form = new QFormLayout(this);
  rig_edit_ = named<QLineEdit>("rigAddress", settings_.value("rig/last", "127.0.0.1:7878").toString());
  token_edit_ = named<QLineEdit>("tokenFile", settings_.value("rig/token_file").toString());
  token_edit_->setPlaceholderText(tr("token file (the rig's <store>/token)"));
  recent_ = named<QComboBox>("recentRigs");
  recent_->addItems(settings_.value("rig/recent").toStringList());
  connect(recent_, &QComboBox::textActivated, rig_edit_, &QLineEdit::setText);
  connect_btn_ = button(tr("Connect"), "connect", this);
  connect(connect_btn_, &QPushButton::clicked, this, [this] {
    if (session_.rig.isConnected()) {
      session_.rig.disconnectFromRig();
    } else {
      connectToRig(rig_edit_->text(), token_edit_->text());
    }
  });
  auto* browse = button(tr("…"), "browseToken", this);
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

  status_label_ = named<QLabel>("rigStatus", tr("no rig"));
  RigLink& rig = session_.rig;
  connect(&rig, &RigLink::connectedChanged, this, [this](bool ok, QString msg) {
    session_.message(msg, !ok);
    connect_btn_->setText(ok ? tr("Disconnect") : tr("Connect"));
    if (ok) rememberRig(session_.rig.endpoint());
    updateStatusLine();
  });
  connect(&rig, &RigLink::statusUpdated, this, [this](veneer::rig::RigStatus) { updateStatusLine(); });
  connect(&rig, &RigLink::failed, this, [this](QString what, QString msg) { session_.message(what + ": " + msg, true); });
  connect(&rig, &RigLink::rigEvent, this, &RigPanel::onRigEvent);
  // A rig's first use: the person compares the fingerprint with the rig's own.
  if (!RigLink::hasDefaultPinAsker()) {
    rig.setPinAsker([this](const QString& rig_name, const QString& fingerprint) {
      QMessageBox box(QMessageBox::Question, tr("New rig"),
                      tr("The rig at %1 is not known yet. Its certificate fingerprint (SHA-256) is\n\n%2\n\n"
                         "Compare it with what `veneerd --fingerprint` prints on the rig (or its log). Connect and "
                         "remember this rig only if they are the same.")
                          .arg(rig_name, fingerprint),
                      QMessageBox::Yes | QMessageBox::No, this);
      box.setDefaultButton(QMessageBox::No);
      box.setTextInteractionFlags(Qt::TextSelectableByMouse);
      return box.exec() == QMessageBox::Yes;
    });
  }
}

void RigPanel::connectToRig(const QString& endpoint, const QString& token_file, const QString& fingerprint) {
  rig_edit_->setText(endpoint);
  token_edit_->setText(token_file);
  if (token_file.isEmpty()) {
    session_.message(tr("no token file given: the rig's token is in its store folder (<store>/token)"), true);
    return;
  }
  auto token = veneer::rig::read_token_file(token_file.toStdString());
  if (!token) {
    session_.message(qs(token.message()), true);
    return;
  }
  settings_.setValue("rig/token_file", token_file);
  session_.message(tr("connecting to %1…").arg(endpoint));
  session_.rig.connectTo(endpoint, qs(*token), fingerprint);
}

void RigPanel::rememberRig(const QString& endpoint) {
  QStringList recent = settings_.value("rig/recent").toStringList();
  recent.removeAll(endpoint);
  recent.prepend(endpoint);
  while (recent.size() > 8) recent.removeLast();
  settings_.setValue("rig/recent", recent);
  settings_.setValue("rig/last", endpoint);
  recent_->clear();
  recent_->addItems(recent);
}

void RigPanel::updateStatusLine() {
  const RigLink& rig = session_.rig;
  if (!rig.isConnected()) {
    status_label_->setText(tr("no rig"));
    return;
  }
  const auto& s = rig.lastStatus();
  int on = static_cast<int>(std::count(s.lamps_on.begin(), s.lamps_on.end(), true));
  status_label_->setText(tr("%1%2 · %3%4 lamps (%5 on) · %6 GB free · %7 · %8 sets")
                             .arg(rig.endpoint(), s.simulated ? tr(" (simulated)") : QString(),
                                  s.camera_connected ? QString() : tr("NO CAMERA · "))
                             .arg(s.lamp_count)
                             .arg(on)
                             .arg(s.free_bytes / 1e9, 0, 'f', 1)
                             .arg(s.you_control ? tr("you control")
                                                : (s.controller_taken ? tr("another client controls") : tr("free")))
                             .arg(s.sets_stored));
  if (s.plain_tcp) status_label_->setText(status_label_->text() + tr(" · PLAIN TCP, not encrypted"));
  status_label_->setToolTip(tr("camera: %1\nconnection: %2")
                                .arg(s.camera_connected ? qs(s.camera_model) : tr("missing"),
                                     s.plain_tcp ? tr("plain TCP (the rig is configured so): not encrypted")
                                                 : tr("TLS 1.3, certificate fingerprint %1").arg(rig.fingerprint())));
}

// The camera came or went (the capture, the sets and the lamps have their own panels).
void RigPanel::onRigEvent(const veneer::rig::Event& e) {
  using K = veneer::rig::Event::Kind;
  if (e.kind != K::camera_connected && e.kind != K::camera_lost) return;
  session_.message(qs(veneer::rig::describe(e)), e.kind == K::camera_lost);
  session_.rig.refreshStatus();
}

}  // namespace veneer::app
