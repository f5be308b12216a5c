#pragma once
// The Sets panel: the sets on the rig, in its trash and on this computer, and
// the maps of the local library; pull, delete, restore, use, open a map.
#include <optional>

#include <QGroupBox>

#include "session.hpp"

class QProgressBar;
class QPushButton;
class QTreeWidget;
class QTreeWidgetItem;

namespace veneer::app {

class SetsPanel : public QGroupBox {
  Q_OBJECT
 public:
  explicit SetsPanel(Session& session, QWidget* parent = nullptr);
  // Rows of what the library remembers from earlier runs (no set is read).
  void showLibrary();
  // The row of a set on this computer, added or updated; the library keeps it.
  void addLocalItem(const QString& folder, const veneer::io::ImageSet& set, const cv::Mat& thumbnail = {});
  void addMapItem(const LibraryMap& map);
  // A pull began (by the panel or by the flow): its bar from 0.
  void pullStarted();

 signals:
  // Load the set in `folder` (as `role`; without one it is only listed).
  void loadRequested(QString folder, std::optional<veneer::io::Role> role);
  void openMapRequested(QString map_folder);

 private:
  QTreeWidgetItem* localItem(const QString& folder, bool create);
  QTreeWidgetItem* selectedItem() const;
  void onSetsListed(const std::vector<veneer::rig::SetSummary>& sets);
  void onTrashListed(const std::vector<veneer::rig::SetSummary>& sets);
  void askDelete(QTreeWidgetItem* item);
  void pullSelected();
  void useSelected(veneer::io::Role as);

  Session& session_;
  QTreeWidget* sets_tree_ = nullptr;
  QTreeWidgetItem *rig_root_ = nullptr, *local_root_ = nullptr, *trash_root_ = nullptr, *maps_root_ = nullptr;
  QProgressBar* pull_bar_ = nullptr;
  QPushButton* undo_btn_ = nullptr;
  QString last_deleted_;  // the rig set the Undo button brings back
};

}  // namespace veneer::app
