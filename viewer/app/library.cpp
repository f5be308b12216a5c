#include "library.hpp"

#include <QCryptographicHash>
#include <QDir>
#include <QFile>
#include <QFileInfo>
#include <QJsonArray>
#include <QJsonDocument>
#include <QJsonObject>
#include <QSaveFile>

#include <opencv2/imgcodecs.hpp>

#include "qt_convert.hpp"

namespace veneer::app {

Library::Library(const QString& workdir) : workdir_(workdir) {
  writer_.setMaxThreadCount(1);
  QFile f(workdir_ + "/library.json");
  if (!f.exists()) return;
  if (!f.open(QIODevice::ReadOnly)) {
    problem_ = QObject::tr("cannot read %1: %2").arg(f.fileName(), f.errorString());
    return;
  }
  QJsonParseError error;
  const QJsonDocument doc = QJsonDocument::fromJson(f.readAll(), &error);
  f.close();
  if (doc.isNull() || !doc.isObject()) {
    problem_ = QObject::tr("%1 is damaged (%2); kept as library.json.bad, the library starts empty")
                   .arg(f.fileName(), error.errorString());
    QFile::remove(f.fileName() + ".bad");
    QFile::rename(f.fileName(), f.fileName() + ".bad");
    return;
  }
  for (const auto& v : doc.object().value("sets").toArray()) {
    const QJsonObject o = v.toObject();
    LibrarySet s{o.value("folder").toString(), o.value("role").toString(), o.value("object").toString(),
                 o.value("created").toString(), o.value("thumbnail").toString()};
    if (!s.folder.isEmpty()) sets_.push_back(s);
  }
  for (const auto& v : doc.object().value("maps").toArray()) {
    const QJsonObject o = v.toObject();
    LibraryMap m{o.value("folder").toString(),         o.value("destination").toString(),
                 o.value("source").toString(),         o.value("destination_id").toString(),
                 o.value("source_id").toString(),      o.value("method").toString(),
                 o.value("computed").toString()};
    if (!m.folder.isEmpty()) maps_.push_back(m);
  }
}

void Library::addSet(const QString& folder, const veneer::io::ImageSet& set, const cv::Mat& thumbnail) {
  LibrarySet s{folder, qs(veneer::io::role_name(set.role)), qs(set.object), qs(set.created), {}};
  if (!thumbnail.empty()) {
    QDir().mkpath(workdir_ + "/thumbnails");
    const QString name = QCryptographicHash::hash(folder.toUtf8(), QCryptographicHash::Sha1).toHex().left(16);
    s.thumbnail = workdir_ + "/thumbnails/" + name + ".png";
    const QString file = s.thumbnail;
    const cv::Mat picture = thumbnail.clone();
    writer_.start([this, file, picture] {
      if (!cv::imwrite(file.toStdString(), picture)) problemLater(QObject::tr("cannot write the thumbnail %1").arg(file));
    });
  }
  for (auto& e : sets_)
    if (e.folder == folder) {
      e = s;
      return;
    }
  sets_.push_back(s);
}

void Library::forgetSet(const QString& folder) {
  std::erase_if(sets_, [&](const LibrarySet& s) { return s.folder == folder; });
}

void Library::addMap(const LibraryMap& map) {
  std::erase_if(maps_, [&](const LibraryMap& m) { return m.folder == map.folder; });
  maps_.push_back(map);
}

const LibraryMap* Library::findMap(const QString& folder) const {
  for (const auto& m : maps_)
    if (m.folder == folder) return &m;
  return nullptr;
}

Library::~Library() { writer_.waitForDone(); }

void Library::flush() { writer_.waitForDone(); }

void Library::setProblemHandler(QObject* context, std::function<void(const QString&)> on_problem) {
  context_ = context;
  on_problem_ = std::move(on_problem);
}

// (on the writer's thread)
void Library::problemLater(const QString& problem) {
  QPointer<QObject> context = context_;
  auto handler = on_problem_;
  if (!context || !handler) return;
  QMetaObject::invokeMethod(context.data(), [context, handler, problem] {
    if (context) handler(problem);
  });
}

void Library::save() {
  QJsonArray sets, maps;
  for (const auto& s : sets_)
    sets.append(QJsonObject{{"folder", s.folder}, {"role", s.role}, {"object", s.object}, {"created", s.created},
                            {"thumbnail", s.thumbnail}});
  for (const auto& m : maps_)
    maps.append(QJsonObject{{"folder", m.folder}, {"destination", m.destination}, {"source", m.source},
                            {"destination_id", m.destination_id}, {"source_id", m.source_id},
                            {"method", m.method}, {"computed", m.computed}});
  const QByteArray text =
      QJsonDocument(QJsonObject{{"format", "veneer-library/1"}, {"sets", sets}, {"maps", maps}}).toJson();
  const QString workdir = workdir_;
  writer_.start([this, workdir, text] {
    QDir().mkpath(workdir);
    QSaveFile f(workdir + "/library.json");
    if (!f.open(QIODevice::WriteOnly) || f.write(text) != text.size() || !f.commit())
      problemLater(QObject::tr("cannot write %1: %2").arg(f.fileName(), f.errorString()));
  });
}

}  // namespace veneer::app
