#include "sets_panel.hpp"

#include <algorithm>

#include <QFileDialog>
#include <QFileInfo>
#include <QHBoxLayout>
#include <QMessageBox>
#include <QProgressBar>
#include <QPushButton>
#include <QTreeWidget>
#include <QVBoxLayout>

#include <opencv2/imgproc.hpp>

#include "veneer/io/image_io.hpp"
#include "widgets.hpp"

namespace veneer::app {

SetsPanel::SetsPanel(Session& session, QWidget* parent) : QGroupBox(tr("Sets"), parent), session_(session) {
  auto* layout = new QVBoxLayout(this);
  sets_tree_ = named<QTreeWidget>("sets");
  sets_tree_->setHeaderLabels({tr("Set"), tr("Role"), tr("Object"), tr("Captured")});
  sets_tree_->setIconSize(QSize(64, 42));
  rig_root_ = new QTreeWidgetItem(sets_tree_, {tr("On the rig")});
  local_root_ = new QTreeWidgetItem(sets_tree_, {tr("On this computer")});
  trash_root_ = new QTreeWidgetItem(sets_tree_, {tr("Rig trash (restorable)")});
  maps_root_ = new QTreeWidgetItem(sets_tree_, {tr("Maps on this computer")});
  for (auto* root : {rig_root_, local_root_, trash_root_, maps_root_}) root->setExpanded(true);
  layout->addWidget(sets_tree_, 1);
  pull_bar_ = named<QProgressBar>("pullProgress");
  pull_bar_->setVisible(false);
  layout->addWidget(pull_bar_);
  auto* row = new QHBoxLayout;
  auto* open = button(tr("Open folder…"), "openLocal", this);
  auto* pull = button(tr("Pull"), "pullSet", this);
  auto* del = button(tr("Delete"), "deleteSet", this);
  auto* restore = button(tr("Restore"), "restoreSet", this);
  restore->setToolTip(tr("bring the set chosen in the rig's trash back"));
  undo_btn_ = button(tr("Undo delete"), "undoDelete", this);
  undo_btn_->setVisible(false);
  auto* use_dst = button(tr("→ Destination"), "useDestination", this);
  auto* use_src = button(tr("→ Source"), "useSource", this);
  auto* open_map = button(tr("Open map"), "openMap", this);
  open_map->setToolTip(tr("show the map chosen under \"Maps on this computer\" again: its sets are loaded and "
                          "repainted through it, without matching"));
  for (auto* b : {open, pull, del, restore}) row->addWidget(b);
  auto* row2 = new QHBoxLayout;
  row2->addWidget(use_dst);
  row2->addWidget(use_src);
  row2->addWidget(open_map);
  layout->addLayout(row);
  layout->addLayout(row2);
  layout->addWidget(undo_btn_);
  RigLink& rig = session_.rig;
  connect(undo_btn_, &QPushButton::clicked, this, [this] {
    if (!last_deleted_.isEmpty()) session_.rig.restoreSet(last_deleted_);
  });
  connect(restore, &QPushButton::clicked, this, [this] {
    QTreeWidgetItem* item = selectedItem();
    if (!item || item->parent() != trash_root_)
      return session_.message(tr("choose a set in the rig's trash to restore"), true);
    session_.rig.restoreSet(item->text(0));
  });
  connect(&rig, &RigLink::connectedChanged, this, [this](bool ok) {
    if (!ok) qDeleteAll(rig_root_->takeChildren());
  });
  connect(&rig, &RigLink::setsListed, this, &SetsPanel::onSetsListed);
  connect(&rig, &RigLink::trashListed, this, &SetsPanel::onTrashListed);
  connect(&rig, &RigLink::deleted, this, [this](QString id) {
    last_deleted_ = id;
    undo_btn_->setText(tr("Undo delete of %1").arg(id));
    undo_btn_->setVisible(true);
    session_.message(tr("%1 moved into the rig's trash").arg(id));
  });
  connect(&rig, &RigLink::restored, this, [this](QString id) {
    if (id == last_deleted_) {
      last_deleted_.clear();
      undo_btn_->setVisible(false);
    }
    session_.message(tr("%1 restored from the rig's trash").arg(id));
  });
  connect(&rig, &RigLink::rigEvent, this, [this](const veneer::rig::Event& e) {
    using K = veneer::rig::Event::Kind;
    // by this viewer or another client: both lists change
    if (e.kind == K::set_deleted || e.kind == K::set_restored) session_.rig.listSets();
  });
  connect(&rig, &RigLink::pullProgress, this, [this](QString, double f) {
    pull_bar_->setVisible(true);
    pull_bar_->setValue(static_cast<int>(f * 100));
    if (session_.status.step().running()) {
      session_.status.step().update(f);
      session_.status.showStep();
    }
  });
  connect(&rig, &RigLink::pulled, this, [this](QString id, QString folder) {
    pull_bar_->setValue(100);
    session_.message(tr("pulled %1 into %2").arg(id, folder));
  });
  connect(open, &QPushButton::clicked, this, [this] {
    QString dir = QFileDialog::getExistingDirectory(this, tr("Image set folder"));
    if (dir.isEmpty()) return;
    emit loadRequested(dir, std::nullopt);  // listed in the library; → Destination / → Source use it
  });
  connect(pull, &QPushButton::clicked, this, &SetsPanel::pullSelected);
  connect(del, &QPushButton::clicked, this, [this] {
    QTreeWidgetItem* item = selectedItem();
    if (!item) return;
    if (item->parent() == rig_root_) {
      askDelete(item);
    } else if (item->parent() == local_root_) {
      // forgets it here; the folder on disk stays
      session_.library.forgetSet(item->data(0, Qt::UserRole).toString());
      session_.library.save();
      delete item;
    }
  });
  connect(open_map, &QPushButton::clicked, this, [this] {
    QTreeWidgetItem* item = selectedItem();
    if (!item || item->parent() != maps_root_)
      return session_.message(tr("choose a map under \"Maps on this computer\""), true);
    emit openMapRequested(item->data(0, Qt::UserRole).toString());
  });
  connect(use_dst, &QPushButton::clicked, this, [this] { useSelected(veneer::io::Role::destination); });
  connect(use_src, &QPushButton::clicked, this, [this] { useSelected(veneer::io::Role::source); });
  connect(sets_tree_, &QTreeWidget::itemDoubleClicked, this, [this](QTreeWidgetItem* item) {
    if (item->parent() == local_root_) {
      useSelected(item->text(1) == "source" ? veneer::io::Role::source : veneer::io::Role::destination);
    } else if (item->parent() == rig_root_) {
      pullSelected();
    } else if (item->parent() == trash_root_) {
      session_.rig.restoreSet(item->text(0));
    } else if (item->parent() == maps_root_) {
      emit openMapRequested(item->data(0, Qt::UserRole).toString());
    }
  });
}

void SetsPanel::onSetsListed(const std::vector<veneer::rig::SetSummary>& sets) {
  qDeleteAll(rig_root_->takeChildren());
  for (const auto& s : sets) {
    auto* item = new QTreeWidgetItem(rig_root_, {qs(s.id), qs(veneer::io::role_name(s.role)), qs(s.object),
                                                 short_date(s.created)});
    QString tip = tr("%1x%2, %3 lamps, %4").arg(s.size.width).arg(s.size.height).arg(s.lights).arg(qs(s.created));
    for (const auto& w : s.warnings) tip += "\n⚠ " + qs(w);
    if (localItem(session_.workdir + "/sets/" + qs(s.id), false)) tip += tr("\npulled to this computer");
    item->setToolTip(0, tip);
  }
  rig_root_->setExpanded(true);
  session_.rig.listTrash();
}

void SetsPanel::onTrashListed(const std::vector<veneer::rig::SetSummary>& sets) {
  qDeleteAll(trash_root_->takeChildren());
  for (const auto& s : sets) {
    auto* item = new QTreeWidgetItem(trash_root_, {qs(s.id), qs(veneer::io::role_name(s.role)), qs(s.object),
                                                   short_date(s.created)});
    item->setToolTip(0, tr("deleted %1; Restore (or a double click) brings it back").arg(short_date(s.deleted)));
  }
  trash_root_->setExpanded(true);
}

// A rig capture is deleted only once the user said yes to a question naming
// it and its date; it goes into the rig's trash, whence Undo brings it back.
void SetsPanel::askDelete(QTreeWidgetItem* item) {
  const QString id = item->text(0);
  auto* box = new QMessageBox(
      QMessageBox::Question, tr("Delete a capture"),
      tr("Delete %1 from the rig?\n\n%2 · %3 · captured %4\n\nIt goes into the rig's trash: Undo (or Restore "
         "from the trash) brings it back for a week.")
          .arg(id, item->text(1), item->text(2).isEmpty() ? tr("no object name") : item->text(2), item->text(3)),
      QMessageBox::Yes | QMessageBox::Cancel, window());
  box->setObjectName("confirmDelete");
  box->setDefaultButton(QMessageBox::Cancel);
  box->setAttribute(Qt::WA_DeleteOnClose);
  connect(box, &QMessageBox::finished, this, [this, id](int answer) {
    if (answer == QMessageBox::Yes) session_.rig.deleteSet(id);
  });
  box->open();
}

QTreeWidgetItem* SetsPanel::selectedItem() const {
  auto items = sets_tree_->selectedItems();
  if (items.isEmpty() || !items.front()->parent()) return nullptr;
  return items.front();
}

void SetsPanel::pullStarted() {
  pull_bar_->setVisible(true);
  pull_bar_->setValue(0);
}

void SetsPanel::pullSelected() {
  QTreeWidgetItem* item = selectedItem();
  if (!item || item->parent() != rig_root_) {
    session_.message(tr("choose a set on the rig to pull"), true);
    return;
  }
  pullStarted();
  session_.rig.pull(item->text(0), session_.workdir + "/sets/" + item->text(0));
}

// The row of a local set (a folder already listed keeps its row and position).
QTreeWidgetItem* SetsPanel::localItem(const QString& folder, bool create) {
  for (int i = 0; i < local_root_->childCount(); ++i)
    if (local_root_->child(i)->data(0, Qt::UserRole).toString() == folder) return local_root_->child(i);
  if (!create) return nullptr;
  auto* item = new QTreeWidgetItem(local_root_);
  item->setText(0, QFileInfo(folder).fileName());
  item->setData(0, Qt::UserRole, folder);
  item->setToolTip(0, folder);
  return item;
}

void SetsPanel::addLocalItem(const QString& folder, const veneer::io::ImageSet& set, const cv::Mat& thumbnail) {
  QTreeWidgetItem* item = localItem(folder, true);
  item->setText(1, qs(veneer::io::role_name(set.role)));
  item->setText(2, qs(set.object));
  item->setText(3, short_date(set.created));
  cv::Mat small = thumbnail;
  if (small.empty() && !set.images.empty()) {
    cv::resize(set.images.front(), small, cv::Size(96, std::max(1, 96 * set.size.height / std::max(1, set.size.width))),
               0, 0, cv::INTER_AREA);
    small = io::tonemap_picture(small);
  }
  if (!small.empty()) item->setIcon(0, QIcon(QPixmap::fromImage(to_qimage(small))));
  local_root_->setExpanded(true);
  session_.library.addSet(folder, set, small.depth() == CV_8U ? small : io::tonemap_picture(small));
  session_.library.save();
}

void SetsPanel::showLibrary() {
  Library& library = session_.library;
  if (!library.problem().isEmpty()) session_.message(library.problem(), true);
  for (const auto& s : library.sets()) {
    QTreeWidgetItem* item = localItem(s.folder, true);
    item->setText(1, s.role);
    item->setText(2, s.object);
    item->setText(3, short_date(s.created.toStdString()));
    if (!QFileInfo::exists(s.folder)) item->setToolTip(0, tr("%1 (the folder is gone)").arg(s.folder));
    if (!s.thumbnail.isEmpty() && QFileInfo::exists(s.thumbnail)) item->setIcon(0, QIcon(s.thumbnail));
  }
  for (const auto& m : library.maps()) addMapItem(m);
}

void SetsPanel::addMapItem(const LibraryMap& m) {
  QTreeWidgetItem* item = nullptr;
  for (int i = 0; i < maps_root_->childCount() && !item; ++i)
    if (maps_root_->child(i)->data(0, Qt::UserRole).toString() == m.folder) item = maps_root_->child(i);
  if (!item) item = new QTreeWidgetItem(maps_root_);
  item->setText(0, QFileInfo(m.destination).fileName() + " ← " + QFileInfo(m.source).fileName());
  item->setText(1, tr("map"));
  item->setText(2, m.method);
  item->setText(3, short_date(m.computed.toStdString()));
  item->setData(0, Qt::UserRole, m.folder);
  item->setToolTip(0, tr("%1\ndestination %2\nsource %3\nOpen map (or a double click) shows it again")
                          .arg(m.folder, m.destination, m.source));
  const QString picture = m.folder + "/map.png";
  if (QFileInfo::exists(picture)) item->setIcon(0, QIcon(picture));
  maps_root_->setExpanded(true);
}

void SetsPanel::useSelected(veneer::io::Role as) {
  QTreeWidgetItem* item = selectedItem();
  if (!item || item->parent() != local_root_) {
    session_.message(tr("choose a set on this computer (pull rig sets first)"), true);
    return;
  }
  emit loadRequested(item->data(0, Qt::UserRole).toString(), as);
}

}  // namespace veneer::app
