#include "map_library.hpp"

#include <QDateTime>
#include <QDir>
#include <QFileInfo>
#include <QPointer>
#include <QSaveFile>
#include <QtConcurrent/QtConcurrentRun>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "segmentation.hpp"
#include "sets_panel.hpp"
#include "transfer_panel.hpp"
#include "widgets.hpp"

namespace veneer::app {

MapLibrary::MapLibrary(Session& session, SetsPanel& sets, TransferPanel& transfer, SegmentationTool& segmentation,
                       QObject* parent)
    : QObject(parent), session_(session), sets_(sets), transfer_(transfer), segmentation_(segmentation) {}

// The map shown goes into the library with the options and hand masks it was
// made with (written off the GUI thread, each file through a temporary).
void MapLibrary::saveShown() {
  if (!session_.result || !session_.dst || !session_.src) return;
  LibraryMap m;
  m.destination = session_.dst->folder;
  m.source = session_.src->folder;
  m.destination_id = qs(session_.dst->set.id);
  m.source_id = qs(session_.src->set.id);
  m.method = qs(veneer::match::method_name(session_.shown.options.match.method));
  m.computed = QDateTime::currentDateTimeUtc().toString(Qt::ISODate);
  m.folder = session_.library.mapsFolder() + "/" + QFileInfo(m.destination).fileName() + "--" +
             QFileInfo(m.source).fileName();
  auto result = session_.result;
  const RunSettings settings = session_.shown;
  QPointer<MapLibrary> self(this);
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
      if (!error.isEmpty())
        return self->session_.message(tr("the map could not be kept in the library: %1").arg(error), true);
      self->session_.library.addMap(m);
      self->session_.library.save();
      self->sets_.addMapItem(m);
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

bool MapLibrary::open(const QString& map_folder) {
  const LibraryMap* found = session_.library.findMap(map_folder);
  if (!found) {
    session_.message(tr("%1 is not a map of the library").arg(map_folder), true);
    return false;
  }
  const LibraryMap m = *found;
  const QString name = QFileInfo(m.destination).fileName() + " ← " + QFileInfo(m.source).fileName();
  for (auto [folder, role] : {std::pair{m.destination, tr("destination")}, std::pair{m.source, tr("source")}}) {
    if (!QFileInfo::exists(folder + "/set.json")) {
      session_.message(tr("cannot reopen the map %1: its %2 set %3 is gone from this computer (pull or open it "
                          "again, then compute)")
                           .arg(name, role, folder),
                       true);
      return false;
    }
  }
  if (!QFileInfo::exists(m.folder + "/map.pfm")) {
    session_.message(tr("cannot reopen the map %1: %2 is gone").arg(name, m.folder + "/map.pfm"), true);
    return false;
  }
  if (transfer_.computing()) transfer_.cancelTransfer();
  session_.status.step().start("load", tr("reopening the map %1").arg(name));
  session_.status.showStep();
  ++session_.loads_running;
  QPointer<MapLibrary> self(this);
  auto cancel = session_.load_cancel;
  (void)QtConcurrent::run(job_pool(), [self, m, name, cancel] {
    ReadMap r = read_library_map(m);
    QMetaObject::invokeMethod(self.data(), [self, m, name, cancel, r] {
      if (!self) return;
      --self->session_.loads_running;
      if (cancel->load()) {
        self->session_.status.step().finish();
        self->session_.status.showStep();
        return self->session_.message(tr("reopening %1 cancelled").arg(name));
      }
      if (!r.map) {
        self->session_.status.step().finish();
        self->session_.status.showStep();
        return self->session_.message(tr("cannot reopen the map %1: %2").arg(name, r.error), true);
      }
      self->reopen_ = Reopen{m, r.map, r.options, r.dst_hand, r.src_hand, false, false};
      self->session_.status.step().finish();
      emit self->loadRequested(m.destination, veneer::io::Role::destination);
      emit self->loadRequested(m.source, veneer::io::Role::source);
    });
  });
  return true;
}

// Called as each set finishes loading: once both of a reopened map's sets
// are there, its options and hand masks are put back and the transfer
// repaints through the stored map.
bool MapLibrary::reopenWhenLoaded(const QString& folder, veneer::io::Role role) {
  if (!reopen_) return false;
  if (role == veneer::io::Role::destination && folder == reopen_->entry.destination) reopen_->dst_loaded = true;
  if (role == veneer::io::Role::source && folder == reopen_->entry.source) reopen_->src_loaded = true;
  if (!reopen_->dst_loaded || !reopen_->src_loaded) return true;  // the other set is still loading
  const auto& dst = session_.dst;
  const auto& src = session_.src;
  if (!dst || !src || dst->folder != reopen_->entry.destination || src->folder != reopen_->entry.source) {
    reopen_.reset();  // another set was chosen meanwhile
    return false;
  }
  Reopen r = std::move(*reopen_);
  reopen_.reset();
  const QString name = QFileInfo(r.entry.destination).fileName() + " ← " + QFileInfo(r.entry.source).fileName();
  for (auto [s, id, role] : {std::tuple{session_.dst.get(), r.entry.destination_id, tr("destination")},
                             std::tuple{session_.src.get(), r.entry.source_id, tr("source")}}) {
    if (!id.isEmpty() && qs(s->set.id) != id) {
      session_.message(tr("cannot reopen the map %1: the %2 set in %3 is now %4, not %5 that the map was computed "
                          "from (compute again)")
                           .arg(name, role, s->folder, qs(s->set.id), id),
                       true);
      return true;
    }
  }
  if (r.map->xy.size() != session_.dst->set.size) {
    session_.message(tr("cannot reopen the map %1: it is %2x%3 and the destination %4x%5 (compute again)")
                         .arg(name)
                         .arg(r.map->xy.cols)
                         .arg(r.map->xy.rows)
                         .arg(session_.dst->set.size.width)
                         .arg(session_.dst->set.size.height),
                     true);
    return true;
  }
  transfer_.showOptions(r.options);
  for (auto [role, mask] :
       {std::pair{veneer::io::Role::destination, r.dst_hand}, std::pair{veneer::io::Role::source, r.src_hand}})
    segmentation_.restoreHandMask(role, mask);
  transfer_.repaintThrough(r.map, r.entry.folder);
  // the transfer cancelled when the reopening began may not have ended yet: then after it
  transfer_.runOrRerun();
  return true;
}

bool MapLibrary::reopenFailed(const QString& folder, const QString& error) {
  if (!reopen_ || (folder != reopen_->entry.destination && folder != reopen_->entry.source)) return false;
  reopen_.reset();
  session_.message(tr("cannot reopen the map: %1").arg(error), true);
  return true;
}

}  // namespace veneer::app
