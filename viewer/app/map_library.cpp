// The maps of the local library: kept when computed, shown again after a
// restart through the stored map (repainted, not matched again).
#include <QCheckBox>
#include <QDateTime>
#include <QDir>
#include <QFileInfo>
#include <QPointer>
#include <QSaveFile>
#include <QTreeWidget>
#include <QtConcurrent/QtConcurrentRun>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "main_window.hpp"
#include "qt_convert.hpp"
#include "widgets.hpp"

namespace veneer::app {

void MainWindow::addMapItem(const LibraryMap& m) {
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

// The map shown goes into the library with the options and hand masks it was
// made with (written off the GUI thread, each file through a temporary).
void MainWindow::saveMapToLibrary() {
  if (!result_ || !dst_ || !src_) return;
  LibraryMap m;
  m.destination = dst_->folder;
  m.source = src_->folder;
  m.destination_id = qs(dst_->set.id);
  m.source_id = qs(src_->set.id);
  m.method = qs(veneer::match::method_name(shown_.options.match.method));
  m.computed = QDateTime::currentDateTimeUtc().toString(Qt::ISODate);
  m.folder = library_->mapsFolder() + "/" + QFileInfo(m.destination).fileName() + "--" + QFileInfo(m.source).fileName();
  auto result = result_;
  const RunSettings settings = shown_;
  QPointer<MainWindow> self(this);
  (void)QtConcurrent::run(job_pool(), [self, result, settings, m] {
    QDir().mkpath(m.folder);
    QString error;
    if (auto s = veneer::match::write_map((m.folder + "/map.pfm").toStdString(), result->map); !s)
      error = qs(s.message());
    cv::Mat picture = veneer::repaint::map_picture(result->map, result->source_size), small;
    const double k = 96.0 / std::max(1, picture.cols);
    cv::resize(picture, small, cv::Size(), k, k, cv::INTER_AREA);
    if (error.isEmpty() && !cv::imwrite((m.folder + "/map.png").toStdString(), small)) error = tr("map.png not written");
    if (error.isEmpty()) {
      QSaveFile f(m.folder + "/options.json");
      const std::string text = veneer::pipeline::transfer_options_json(settings.options);
      if (!f.open(QIODevice::WriteOnly) || f.write(text.data(), static_cast<qint64>(text.size())) < 0 || !f.commit())
        error = tr("%1: %2").arg(f.fileName(), f.errorString());
    }
    for (auto [mask, name] : {std::pair{settings.dst_hand, "dst-mask.png"}, std::pair{settings.src_hand, "src-mask.png"}}) {
      const QString file = m.folder + "/" + name;
      if (mask.empty()) {
        QFile::remove(file);  // an earlier map of this pair drawn by hand
      } else if (error.isEmpty() && !cv::imwrite(file.toStdString(), mask)) {
        error = tr("%1 not written").arg(file);
      }
    }
    QMetaObject::invokeMethod(self.data(), [self, m, error] {
      if (!self) return;
      if (!error.isEmpty()) return self->message(tr("the map could not be kept in the library: %1").arg(error), true);
      self->library_->addMap(m);
      self->library_->save();
      self->addMapItem(m);
    });
  });
}

namespace {
// What reopening a library map reads off the GUI thread.
struct ReadMap {
  std::shared_ptr<const veneer::match::Map> map;
  veneer::pipeline::TransferOptions options;
  cv::Mat dst_hand, src_hand;
  QString error;
};

ReadMap read_library_map(const LibraryMap& m) {
  ReadMap r;
  auto map = veneer::match::read_map((m.folder + "/map.pfm").toStdString());
  if (!map) {
    r.error = qs(map.message());
    return r;
  }
  r.map = std::make_shared<const veneer::match::Map>(std::move(*map));
  const QString options = m.folder + "/options.json";
  if (QFileInfo::exists(options)) {
    auto o = veneer::pipeline::read_transfer_options(options.toStdString());
    if (!o) {
      r.error = qs(o.message());
      return r;
    }
    r.options = *o;
  } else if (auto method = veneer::match::parse_method(m.method.toStdString())) {
    r.options.match.method = *method;  // kept before options.json was: its method, the rest default
  }
  for (auto [mask, name] : {std::pair{&r.dst_hand, "/dst-mask.png"}, std::pair{&r.src_hand, "/src-mask.png"}}) {
    const QString file = m.folder + name;
    if (!QFileInfo::exists(file)) continue;
    *mask = cv::imread(file.toStdString(), cv::IMREAD_GRAYSCALE);
    if (mask->empty()) {
      r.error = QObject::tr("%1 is not a readable PNG").arg(file);
      return r;
    }
  }
  return r;
}
}  // namespace

bool MainWindow::openLibraryMap(const QString& map_folder) {
  const LibraryMap* found = library_->findMap(map_folder);
  if (!found) {
    message(tr("%1 is not a map of the library").arg(map_folder), true);
    return false;
  }
  const LibraryMap m = *found;
  const QString name = QFileInfo(m.destination).fileName() + " ← " + QFileInfo(m.source).fileName();
  for (auto [folder, role] : {std::pair{m.destination, tr("destination")}, std::pair{m.source, tr("source")}}) {
    if (!QFileInfo::exists(folder + "/set.json")) {
      message(tr("cannot reopen the map %1: its %2 set %3 is gone from this computer (pull or open it again, "
                 "then compute)")
                  .arg(name, role, folder),
              true);
      return false;
    }
  }
  if (!QFileInfo::exists(m.folder + "/map.pfm")) {
    message(tr("cannot reopen the map %1: %2 is gone").arg(name, m.folder + "/map.pfm"), true);
    return false;
  }
  if (computing_) cancelTransfer();
  step_.start("load", tr("reopening the map %1").arg(name));
  showStep();
  ++loads_running_;
  QPointer<MainWindow> self(this);
  auto cancel = load_cancel_;
  (void)QtConcurrent::run(job_pool(), [self, m, name, cancel] {
    ReadMap r = read_library_map(m);
    QMetaObject::invokeMethod(self.data(), [self, m, name, cancel, r] {
      if (!self) return;
      --self->loads_running_;
      if (cancel->load()) {
        self->step_.finish();
        self->showStep();
        return self->message(tr("reopening %1 cancelled").arg(name));
      }
      if (!r.map) {
        self->step_.finish();
        self->showStep();
        return self->message(tr("cannot reopen the map %1: %2").arg(name, r.error), true);
      }
      self->reopen_ = Reopen{m, r.map, r.options, r.dst_hand, r.src_hand, false, false};
      self->step_.finish();
      self->loadSetInBackground(m.destination, veneer::io::Role::destination);
      self->loadSetInBackground(m.source, veneer::io::Role::source);
    });
  });
  return true;
}

// Called as each set finishes loading: once both of a reopened map's sets
// are there, its options and hand masks are put back and the transfer
// repaints through the stored map.
bool MainWindow::reopenWhenLoaded(const QString& folder, veneer::io::Role role) {
  if (!reopen_) return false;
  if (role == veneer::io::Role::destination && folder == reopen_->entry.destination) reopen_->dst_loaded = true;
  if (role == veneer::io::Role::source && folder == reopen_->entry.source) reopen_->src_loaded = true;
  if (!reopen_->dst_loaded || !reopen_->src_loaded) return true;  // the other set is still loading
  if (!dst_ || !src_ || dst_->folder != reopen_->entry.destination || src_->folder != reopen_->entry.source) {
    reopen_.reset();  // another set was chosen meanwhile
    return false;
  }
  Reopen r = std::move(*reopen_);
  reopen_.reset();
  const QString name = QFileInfo(r.entry.destination).fileName() + " ← " + QFileInfo(r.entry.source).fileName();
  for (auto [s, id, role] : {std::tuple{dst_.get(), r.entry.destination_id, tr("destination")},
                             std::tuple{src_.get(), r.entry.source_id, tr("source")}}) {
    if (!id.isEmpty() && qs(s->set.id) != id) {
      message(tr("cannot reopen the map %1: the %2 set in %3 is now %4, not %5 that the map was computed from "
                 "(compute again)")
                  .arg(name, role, s->folder, qs(s->set.id), id),
              true);
      return true;
    }
  }
  if (r.map->xy.size() != dst_->set.size) {
    message(tr("cannot reopen the map %1: it is %2x%3 and the destination %4x%5 (compute again)")
                .arg(name)
                .arg(r.map->xy.cols)
                .arg(r.map->xy.rows)
                .arg(dst_->set.size.width)
                .arg(dst_->set.size.height),
            true);
    return true;
  }
  const auto& o = r.options;
  Preset p{tr("as reopened"),
           qs(veneer::match::method_name(o.match.method)),
           qs(veneer::match::feature_name(o.match.feature)),
           o.match.patch,
           o.match.candidates,
           o.match.threshold,
           o.match.iterations,
           o.match.coherent_threshold,
           o.match.coherent_smooth,
           o.match.coherent_guide,
           o.match.uniformity,
           o.blend,
           o.blend_guide,
           o.match.fast};
  applyPreset(p);
  truth_normals_->setChecked(o.truth_normals);
  for (auto [role, mask] : {std::pair{veneer::io::Role::destination, r.dst_hand}, std::pair{veneer::io::Role::source, r.src_hand}}) {
    auto s = setFor(role);
    if (mask.empty() || mask.size() != s->set.size) continue;
    s->hand_mask = mask;
    handMaskChanged(role);
  }
  given_map_ = r.map;
  reopened_folder_ = r.entry.folder;
  if (computing_) {
    rerun_ = true;  // the transfer cancelled when the reopening began has not ended yet: after it
    return true;
  }
  startTransfer();
  return true;
}

}  // namespace veneer::app
