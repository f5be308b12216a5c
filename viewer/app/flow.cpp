#include "flow.hpp"

#include <QFileInfo>
#include <QPointer>
#include <QtConcurrent/QtConcurrentRun>

#include <opencv2/imgproc.hpp>

#include "capture_panel.hpp"
#include "live_first.hpp"
#include "live_tab.hpp"
#include "map_library.hpp"
#include "sets_panel.hpp"
#include "transfer_panel.hpp"
#include "veneer/io/image_io.hpp"
#include "veneer/io/reduced.hpp"
#include "veneer/pipeline/prepare.hpp"
#include "veneer/ps/segmentation.hpp"
#include "widgets.hpp"

namespace veneer::app {

FlowController::FlowController(Session& session, CapturePanel& capture, SetsPanel& sets, TransferPanel& transfer,
                               LiveTab& live, LiveFirstJob& live_first, MapLibrary& library, QObject* parent)
    : QObject(parent),
      session_(session),
      capture_(capture),
      sets_(sets),
      transfer_(transfer),
      live_(live),
      live_first_(live_first),
      library_(library) {
  connect(&capture_, &CapturePanel::setStored, this, &FlowController::setStored);
  connect(&session_.rig, &RigLink::pulled, this, &FlowController::pulled);
  connect(&session_.rig, &RigLink::previewPulled, this, &FlowController::previewPulled);
  connect(&transfer_, &TransferPanel::transferEnded, this, &FlowController::computeWaitingNormals);
  connect(&sets_, &SetsPanel::loadRequested, this, &FlowController::loadSetInBackground);
  connect(&library_, &MapLibrary::loadRequested, this,
          [this](const QString& folder, veneer::io::Role role) { loadSetInBackground(folder, role); });
}

bool FlowController::autoFlow() const { return capture_.autoFlow(); }

// A set was stored on the rig, by whatever pressed the trigger: pull it.
void FlowController::setStored(const QString& id, veneer::io::Role role) {
  if (!autoFlow()) return;
  auto_pulls_[id] = role;
  session_.status.step().start("pull", role == veneer::io::Role::unknown ? tr("pulling %1").arg(id)
                                                     : tr("pulling %1 (%2)").arg(id, qs(veneer::io::role_name(role))));
  session_.status.showStep();
  sets_.pullStarted();
  // live first: the rig's preview set first, read at the live width while the full files come (issue 48)
  const QString folder = session_.workdir + "/sets/" + id;
  full_folders_.erase(folder);
  session_.rig.pull(id, folder, preview_first_ && live_width_ > 0 ? live_width_ : 0);
}

// The preview of a set the flow pulls is in place: loaded as its role at the
// live width, so the live-size map need not wait for the full files.
void FlowController::previewPulled(const QString& id, const QString& folder) {
  auto it = auto_pulls_.find(id);
  if (it == auto_pulls_.end() || live_width_ <= 0 || !autoFlow()) return;
  previews_loaded_.insert(id);
  session_.status.step().finish();
  loadSetInBackground(folder, it->second);
}

void FlowController::pulled(const QString& id, const QString& folder) {
  full_folders_.insert(folder);
  auto it = auto_pulls_.find(id);
  std::optional<veneer::io::Role> role;
  if (it != auto_pulls_.end()) {
    role = it->second;
    auto_pulls_.erase(it);
    if (previews_loaded_.erase(id) > 0) {
      // its preview is loaded (or loading) as the role: the full files are for the full resolution
      for (const auto& l : {session_.dst, session_.src})
        if (l && l->folder == folder) l->preview = false;
      live_first_.maybeStart();
      return;
    }
    session_.status.step().finish();
  }
  loadSetInBackground(folder, role);
}

namespace {
// What loading a set makes off the GUI thread.
struct ReadSet {
  std::shared_ptr<LoadedSet> loaded;
  cv::Mat thumbnail;
  QString error;
};

cv::Mat thumbnail_of(const veneer::io::ImageSet& set) {
  if (set.images.empty()) return {};
  cv::Mat small;
  cv::resize(set.images.front(), small,
             cv::Size(96, std::max(1, 96 * set.size.height / std::max(1, set.size.width))), 0, 0, cv::INTER_AREA);
  return small;
}
}  // namespace

namespace {
// A set read as the transfer reads it (veneer transfer's and the
// pipeline's reading: RAW where present, the same demosaic), so the photos
// the views show and the live repaint uses are the pixels the map was made of.
veneer::Expected<veneer::io::ImageSet> read_as_transfer(const std::string& folder) {
  return veneer::io::read_set(folder, veneer::pipeline::default_prepare_options().read);
}

// A set at the live view's width; `smaller` says whether that is smaller than the set.
// A set no wider is read whole, as before (the map is then the full-resolution one).
veneer::Expected<veneer::io::ImageSet> read_live_size(const std::string& folder, int width, bool* smaller) {
  veneer::io::ReadOptions manifest;
  manifest.load_photos = false;
  manifest.load_truth = false;
  auto whole = veneer::io::read_set(folder, manifest);
  // a preview set (the rig's, while its full files come) is always a live-size set: of a larger one
  const bool preview = whole && whole->preview_of.has_value();
  if (!whole || (whole->size.width <= width && !preview)) return read_as_transfer(folder);
  veneer::io::ReducedOptions o;
  o.width = width;
  auto set = veneer::io::read_set_reduced(folder, o);
  *smaller = set && (set->size.width < whole->size.width || set->preview_of.has_value());
  return set;
}
}  // namespace

void FlowController::loadSetInBackground(const QString& folder, std::optional<veneer::io::Role> as) {
  ++session_.loads_running;
  const QString name = QFileInfo(folder).fileName();
  if (as) {
    session_.status.step().start("load", *as == veneer::io::Role::unknown
                            ? tr("loading %1").arg(name)
                            : tr("loading %1 as the %2").arg(name, qs(veneer::io::role_name(*as))));
    session_.status.showStep();
  }
  const bool full = as.has_value();
  // live first: the flow's sets at the live view's width (live_first.cpp)
  const int live_width = full && autoFlow() ? live_width_ : 0;
  QPointer<FlowController> self(this);
  auto cancel = session_.load_cancel;
  (void)QtConcurrent::run(job_pool(), [self, folder, as, full, cancel, live_width] {
    ReadSet r;
    bool live_size = false;
    auto read = live_width > 0 ? read_live_size(folder.toStdString(), live_width, &live_size)
                               : read_as_transfer(folder.toStdString());
    if (!read) {
      r.error = qs(read.message());
    } else {
      r.loaded = std::make_shared<LoadedSet>();
      r.loaded->folder = folder;
      r.loaded->set = std::move(*read);
      r.loaded->live_size = live_size;
      r.loaded->live_width = live_size ? live_width : 0;
      r.thumbnail = thumbnail_of(r.loaded->set);
      if (full) {
        r.loaded->median = veneer::repaint::median_photo(r.loaded->set.images);
        r.loaded->median_picture = io::tonemap_picture(r.loaded->median);
        r.loaded->median_image = to_qimage(r.loaded->median_picture);  // what the views show, made here
        r.loaded->histogram = luminance_histogram(r.loaded->median_picture);
      }
    }
    QMetaObject::invokeMethod(self.data(), [self, r, as, folder, cancel] {
      if (!self) return;
      --self->session_.loads_running;
      if (as) self->session_.status.step().finish();
      if (cancel->load()) {
        self->session_.message(tr("loading %1 cancelled").arg(folder));
        self->session_.status.showStep();
        return;
      }
      if (!r.loaded) {
        if (!self->library_.reopenFailed(folder, r.error)) self->session_.message(r.error, true);
        self->session_.status.showStep();
        return;
      }
      self->sets_.addLocalItem(folder, r.loaded->set, r.thumbnail);
      if (!as) {
        self->session_.status.showStep();
        return;
      }
      // unknown: the role the set's manifest gives it
      const veneer::io::Role role = *as != veneer::io::Role::unknown ? *as : r.loaded->set.role;
      if (role == veneer::io::Role::unknown) {
        self->session_.message(tr("%1 has no role in its manifest: choose → Destination or → Source").arg(folder),
                               true);
        self->session_.status.showStep();
        return;
      }
      // read from the rig's preview while its full files are still coming
      r.loaded->preview = r.loaded->set.preview_of.has_value() && !self->full_folders_.count(folder);
      self->session_.setLoaded(r.loaded, role);
      // live first: a live-size set's Look-tab normals wait while its map is made, which is what the
      // first live frame waits for (they compete for the same cores)
      self->normals_waiting_.push_back(r.loaded);
      self->session_.message(tr("loaded %1 as the %2").arg(folder, qs(veneer::io::role_name(role))));
      self->session_.status.showStep();
      if (!self->library_.reopenWhenLoaded(folder, role)) self->maybeCompute();
      if (!r.loaded->live_size || !self->transfer_.computing()) self->computeWaitingNormals();
    });
  });
}

bool FlowController::loadLocalSet(const QString& folder, veneer::io::Role as) {
  auto read = read_as_transfer(folder.toStdString());
  if (!read) {
    session_.message(qs(read.message()), true);
    return false;
  }
  auto loaded = std::make_shared<LoadedSet>();
  loaded->folder = folder;
  loaded->set = std::move(*read);
  loaded->median = veneer::repaint::median_photo(loaded->set.images);
  loaded->median_picture = picture_of(loaded->median);
  sets_.addLocalItem(folder, loaded->set);
  session_.setLoaded(loaded, as);
  computeNormals(loaded);
  session_.message(tr("loaded %1 as the %2").arg(folder, qs(veneer::io::role_name(as))));
  return true;
}

// The Look tab's normals, albedo, mask and confidence: the set prepared as
// the transfer prepares it (pipeline::prepare_set, through the result cache,
// which the transfer then hits), so the mask shown is the one the map is made
// on (the base the object stands on left out). A live-size set: the same
// steps on the set as read (what pipeline::prepare_live_pair does per set).
void FlowController::computeNormals(std::shared_ptr<LoadedSet> loaded) {
  QPointer<Session> session(&session_);
  (void)QtConcurrent::run(job_pool(), [session, loaded] {
    auto result = std::make_shared<veneer::ps::PsResult>();
    if (!loaded->live_size) {
      auto prepared = veneer::pipeline::prepare_set(loaded->folder.toStdString(), 1.0, false,
                                                    veneer::pipeline::default_prepare_options());
      (void)veneer::pipeline::finish_cache_writes();
      if (!prepared) return;
      result->normals = prepared->object.view.normals;
      result->mask = prepared->object.view.mask;
      result->albedo = prepared->albedo;
      result->residual = prepared->residual;
    } else {
      auto seg = veneer::ps::segment(loaded->set);
      if (!seg) return;
      auto ps = veneer::ps::photometric_stereo(loaded->set, seg->mask);
      if (!ps) return;
      if (loaded->set.mask.empty()) veneer::ps::drop_supports(*ps);  // as match::prepare_object
      *result = std::move(*ps);
    }
    if (!session) return;
    QMetaObject::invokeMethod(session.data(), [session, loaded, result] {
      if (!session) return;
      loaded->normals.emplace(std::move(*result));  // moved: a 10 Mpx result is ~200 MB
      session->normalsReady();
    });
  });
}

// The Look tab's normals of the sets loaded that wait for them (those still loaded).
void FlowController::computeWaitingNormals() {
  auto waiting = std::move(normals_waiting_);
  normals_waiting_.clear();
  for (auto& loaded : waiting)
    if (!loaded->normals && (loaded == session_.dst || loaded == session_.src)) computeNormals(loaded);
}

// Both sets there: the map, with the settings shown (the defaults unless the
// user changed them).
void FlowController::maybeCompute() {
  if (!autoFlow() || !session_.dst || !session_.src) return;
  // a set changed under the running transfer: once more with both
  if (!transfer_.computing() && session_.result) return;
  transfer_.runOrRerun();
  // live first: the live view starts while the live-size map is made, so its first repainted frame
  // follows the map at once (not the rig's start of the stream)
  if ((session_.dst->live_size || session_.src->live_size) && session_.rig.isConnected() && !live_.isLive()) {
    emit tabWanted("Live");
    live_.startLive();
  }
}

// A map is shown and a rig is there: the live repaint starts by itself; on a
// live-size map, the full resolution follows behind it.
void FlowController::resultShown() {
  if (!autoFlow()) return;
  if (session_.result && session_.rig.isConnected() && !live_.isLive()) {
    emit tabWanted("Live");
    live_.startLive();
  }
  live_first_.maybeStart();
}

}  // namespace veneer::app
