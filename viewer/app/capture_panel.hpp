#pragma once
// The Capture panel: the automatic flow's switch, the object name and the
// exposure, the capture buttons; it follows the rig's capture events (shots,
// storing) and says when a set is stored.
#include <QGroupBox>

#include "session.hpp"

class QCheckBox;
class QDoubleSpinBox;
class QLabel;
class QLineEdit;
class QProgressBar;
class QSpinBox;

namespace veneer::app {

class CapturePanel : public QGroupBox {
  Q_OBJECT
 public:
  explicit CapturePanel(Session& session, QWidget* parent = nullptr);
  // Asks the rig for a capture of `role` with the settings shown.
  void capture(veneer::io::Role role);
  // The one flow (flow.hpp) is on: each capture stored is pulled and used.
  bool autoFlow() const;
  void setAutoFlow(bool on);

 signals:
  void setStored(QString id, veneer::io::Role role);

 private:
  void onRigEvent(const veneer::rig::Event& e);

  Session& session_;
  QCheckBox* auto_flow_ = nullptr;
  QLineEdit* object_edit_ = nullptr;
  QDoubleSpinBox *shutter_ = nullptr, *aperture_ = nullptr;
  QSpinBox* iso_ = nullptr;
  QProgressBar* shot_bar_ = nullptr;
  QLabel* capture_label_ = nullptr;
};

}  // namespace veneer::app
