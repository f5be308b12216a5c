// The Sets panel: sets on the rig, in its trash and on this computer; pull, delete, use.
#include "main_window.hpp"
#include "widgets.hpp"

#include <algorithm>
#include <cmath>

#include <QApplication>
#include <QCheckBox>
#include <QComboBox>
#include <QDateTime>
#include <QDir>
#include <QMessageBox>
#include <QPointer>
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

QWidget* MainWindow::buildSetsPanel() {
  auto* box = new QGroupBox(tr("Sets"));
  auto* layout = new QVBoxLayout(box);
  sets_tree_ = new QTreeWidget;
  sets_tree_->setObjectName("sets");
  sets_tree_->setHeaderLabels({tr("Set"), tr("Role"), tr("Object"), tr("Captured")});
  sets_tree_->setIconSize(QSize(64, 42));
  rig_root_ = new QTreeWidgetItem(sets_tree_, {tr("On the rig")});
  local_root_ = new QTreeWidgetItem(sets_tree_, {tr("On this computer")});
  trash_root_ = new QTreeWidgetItem(sets_tree_, {tr("Rig trash (restorable)")});
  maps_root_ = new QTreeWidgetItem(sets_tree_, {tr("Maps on this computer")});
  for (auto* root : {rig_root_, local_root_, trash_root_, maps_root_}) root->setExpanded(true);
  layout->addWidget(sets_tree_, 1);
  pull_bar_ = new QProgressBar;
  pull_bar_->setObjectName("pullProgress");
  pull_bar_->setVisible(false);
  layout->addWidget(pull_bar_);
  auto* row = new QHBoxLayout;
  auto* open = button(tr("Open folder…"), "openLocal", box);
  auto* pull = button(tr("Pull"), "pullSet", box);
  auto* del = button(tr("Delete"), "deleteSet", box);
  auto* restore = button(tr("Restore"), "restoreSet", box);
  restore->setToolTip(tr("bring the set chosen in the rig's trash back"));
  undo_btn_ = button(tr("Undo delete"), "undoDelete", box);
  undo_btn_->setVisible(false);
  auto* use_dst = button(tr("→ Destination"), "useDestination", box);
  auto* use_src = button(tr("→ Source"), "useSource", box);
  auto* open_map = button(tr("Open map"), "openMap", box);
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
  connect(undo_btn_, &QPushButton::clicked, this, [this] {
    if (!last_deleted_.isEmpty()) restoreFromTrash(last_deleted_);
  });
  connect(restore, &QPushButton::clicked, this, [this] {
    QTreeWidgetItem* item = selectedItem();
    if (!item || item->parent() != trash_root_) return message(tr("choose a set in the rig's trash to restore"), true);
    restoreFromTrash(item->text(0));
  });
  connect(&rig_, &RigLink::trashListed, this, &MainWindow::onTrashListed);
  connect(&rig_, &RigLink::deleted, this, [this](QString id) {
    last_deleted_ = id;
    undo_btn_->setText(tr("Undo delete of %1").arg(id));
    undo_btn_->setVisible(true);
    message(tr("%1 moved into the rig's trash").arg(id));
  });
  connect(&rig_, &RigLink::restored, this, [this](QString id) {
    if (id == last_deleted_) {
      last_deleted_.clear();
      undo_btn_->setVisible(false);
    }
    message(tr("%1 restored from the rig's trash").arg(id));
  });
  connect(open, &QPushButton::clicked, this, [this] {
    QString dir = QFileDialog::getExistingDirectory(this, tr("Image set folder"));
    if (dir.isEmpty()) return;
    loadSetInBackground(dir, std::nullopt);  // listed in the library; → Destination / → Source use it
  });
  connect(pull, &QPushButton::clicked, this, &MainWindow::pullSelected);
  connect(del, &QPushButton::clicked, this, [this] {
    QTreeWidgetItem* item = selectedItem();
    if (!item) return;
    if (item->parent() == rig_root_) {
      askDelete(item);
    } else if (item->parent() == local_root_) {
      // forgets it here; the folder on disk stays
      library_->forgetSet(item->data(0, Qt::UserRole).toString());
      library_->save();
      delete item;
    }
  });
  connect(open_map, &QPushButton::clicked, this, [this] {
    QTreeWidgetItem* item = selectedItem();
    if (!item || item->parent() != maps_root_) return message(tr("choose a map under \"Maps on this computer\""), true);
    openLibraryMap(item->data(0, Qt::UserRole).toString());
  });
  connect(use_dst, &QPushButton::clicked, this, [this] { useSelected(veneer::io::Role::destination); });
  connect(use_src, &QPushButton::clicked, this, [this] { useSelected(veneer::io::Role::source); });
  connect(sets_tree_, &QTreeWidget::itemDoubleClicked, this, [this](QTreeWidgetItem* item) {
    if (item->parent() == local_root_) {
      useSelected(item->text(1) == "source" ? veneer::io::Role::source : veneer::io::Role::destination);
    } else if (item->parent() == rig_root_) {
      pullSelected();
    } else if (item->parent() == trash_root_) {
      restoreFromTrash(item->text(0));
    } else if (item->parent() == maps_root_) {
      openLibraryMap(item->data(0, Qt::UserRole).toString());
    }
  });
  return box;
}


void MainWindow::onSetsListed(const std::vector<veneer::rig::SetSummary>& sets) {
  qDeleteAll(rig_root_->takeChildren());
  for (const auto& s : sets) {
    auto* item = new QTreeWidgetItem(rig_root_, {qs(s.id), qs(veneer::io::role_name(s.role)), qs(s.object),
                                                 short_date(s.created)});
    QString tip = tr("%1x%2, %3 lamps, %4").arg(s.size.width).arg(s.size.height).arg(s.lights).arg(qs(s.created));
    for (const auto& w : s.warnings) tip += "\n⚠ " + qs(w);
    if (localItem(workdir_ + "/sets/" + qs(s.id), false)) tip += tr("\npulled to this computer");
    item->setToolTip(0, tip);
  }
  rig_root_->setExpanded(true);
  rig_.listTrash();
}

void MainWindow::onTrashListed(const std::vector<veneer::rig::SetSummary>& sets) {
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
void MainWindow::askDelete(QTreeWidgetItem* item) {
  const QString id = item->text(0);
  auto* box = new QMessageBox(
      QMessageBox::Question, tr("Delete a capture"),
      tr("Delete %1 from the rig?\n\n%2 · %3 · captured %4\n\nIt goes into the rig's trash: Undo (or Restore "
         "from the trash) brings it back for a week.")
          .arg(id, item->text(1), item->text(2).isEmpty() ? tr("no object name") : item->text(2), item->text(3)),
      QMessageBox::Yes | QMessageBox::Cancel, this);
  box->setObjectName("confirmDelete");
  box->setDefaultButton(QMessageBox::Cancel);
  box->setAttribute(Qt::WA_DeleteOnClose);
  connect(box, &QMessageBox::finished, this, [this, id](int answer) {
    if (answer == QMessageBox::Yes) rig_.deleteSet(id);
  });
  box->open();
}

void MainWindow::restoreFromTrash(const QString& id) { rig_.restoreSet(id); }

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

// The row of a local set (a folder already listed keeps its row and position).
QTreeWidgetItem* MainWindow::localItem(const QString& folder, bool create) {
  for (int i = 0; i < local_root_->childCount(); ++i)
    if (local_root_->child(i)->data(0, Qt::UserRole).toString() == folder) return local_root_->child(i);
  if (!create) return nullptr;
  auto* item = new QTreeWidgetItem(local_root_);
  item->setText(0, QFileInfo(folder).fileName());
  item->setData(0, Qt::UserRole, folder);
  item->setToolTip(0, folder);
  return item;
}

void MainWindow::addLocalItem(const QString& folder, const veneer::io::ImageSet& set, const cv::Mat& thumbnail) {
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
  library_->addSet(folder, set, small.depth() == CV_8U ? small : io::tonemap_picture(small));
  library_->save();
}

// What the library remembers from earlier runs: rows without reading a set.
void MainWindow::showLibrary() {
  if (!library_->problem().isEmpty()) message(library_->problem(), true);
  for (const auto& s : library_->sets()) {
    QTreeWidgetItem* item = localItem(s.folder, true);
    item->setText(1, s.role);
    item->setText(2, s.object);
    item->setText(3, short_date(s.created.toStdString()));
    if (!QFileInfo::exists(s.folder)) item->setToolTip(0, tr("%1 (the folder is gone)").arg(s.folder));
    if (!s.thumbnail.isEmpty() && QFileInfo::exists(s.thumbnail)) item->setIcon(0, QIcon(s.thumbnail));
  }
  for (const auto& m : library_->maps()) addMapItem(m);
}

void MainWindow::useSelected(veneer::io::Role as) {
  QTreeWidgetItem* item = selectedItem();
  if (!item || item->parent() != local_root_) {
    message(tr("choose a set on this computer (pull rig sets first)"), true);
    return;
  }
  loadSetInBackground(item->data(0, Qt::UserRole).toString(), as);
}

bool MainWindow::loadLocalSet(const QString& folder, veneer::io::Role as) {
  auto read = veneer::io::read_set(folder.toStdString());
  if (!read) {
    message(qs(read.message()), true);
    return false;
  }
  auto loaded = std::make_shared<LoadedSet>();
  loaded->folder = folder;
  loaded->set = std::move(*read);
  loaded->median = veneer::repaint::median_photo(loaded->set.images);
  loaded->median_picture = picture_of(loaded->median);
  addLocalItem(folder, loaded->set);
  setLoaded(loaded, as);
  computeNormals(loaded);
  message(tr("loaded %1 as the %2").arg(folder, qs(veneer::io::role_name(as))));
  return true;
}

void MainWindow::setLoaded(std::shared_ptr<LoadedSet> loaded, veneer::io::Role as) {
  if (as == veneer::io::Role::source) {
    src_ = loaded;
  } else {
    dst_ = loaded;
  }
  ++sets_loaded_;
  result_.reset();
  relighter_.reset();
  live_session_.reset();
  live_refusal_.clear();
  refreshLook();
  updateLampBoxes();
}

void MainWindow::computeNormals(std::shared_ptr<LoadedSet> loaded) {
  QPointer<MainWindow> self(this);
  (void)QtConcurrent::run(job_pool(), [self, loaded] {
    auto seg = veneer::ps::segment(loaded->set);
    if (!seg) return;
    auto ps = veneer::ps::photometric_stereo(loaded->set, seg->mask);
    if (!ps) return;
    auto result = std::make_shared<veneer::ps::PsResult>(std::move(*ps));
    if (!self) return;
    QMetaObject::invokeMethod(self.data(), [self, loaded, result] {
      if (!self) return;
      loaded->normals.emplace(std::move(*result));  // moved: a 10 Mpx result is ~200 MB
      self->refreshLook();
    });
  });
}

}  // namespace veneer::app
