// The Sets panel: sets on the rig, in its trash and on this computer; pull, delete, use.
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

}  // namespace veneer::app
