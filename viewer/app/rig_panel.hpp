#pragma once
// The Rig panel: the rig's address and token file, the recent rigs, Connect;
// and the rig's one-line status (lamps, space, who controls it) in the
// window's status bar.
#include <QGroupBox>
#include <QSettings>

#include "session.hpp"

class QComboBox;
class QLabel;
class QLineEdit;
class QPushButton;

namespace veneer::app {

class RigPanel : public QGroupBox {
  Q_OBJECT
 public:
  explicit RigPanel(Session& session, QWidget* parent = nullptr);
  // `fingerprint`: the rig's certificate's, when known (else the pinned one, else the first use asks).
  void connectToRig(const QString& endpoint, const QString& token_file, const QString& fingerprint = {});
  // The rig's status, for the window's status bar.
  QLabel* statusLabel() const { return status_label_; }

 private:
  void rememberRig(const QString& endpoint);
  void updateStatusLine();
  void onRigEvent(const veneer::rig::Event& e);

  Session& session_;
  QSettings settings_;  // the application's (veneer/veneer-viewer.conf; the tests' under their own names)
  QLineEdit *rig_edit_ = nullptr, *token_edit_ = nullptr;
  QComboBox* recent_ = nullptr;
  QPushButton* connect_btn_ = nullptr;
  QLabel* status_label_ = nullptr;
};

}  // namespace veneer::app
