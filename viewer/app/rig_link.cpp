#include "rig_link.hpp"
#include "veneer/io/imageset.hpp"

#include <QPointer>
#include <QThreadPool>

#include "veneer/proto/tls.hpp"
#include <QtConcurrent/QtConcurrentRun>

namespace veneer::app {

// The rig's calls (connect, pull, capture, ...) wait on the network for
// seconds: on a pool of their own, not Qt's global one, which the raster
// engine's painting fills and scales on (the GUI thread waits for those).
QThreadPool* rig_pool() {
  static QThreadPool pool;
  static const bool sized = [] {
    pool.setMaxThreadCount(8);  // a pull, a capture and status calls side by side
    return true;
  }();
  (void)sized;
  return &pool;
}

namespace {
RigLink::PinAsker& default_pin_asker() {
  static RigLink::PinAsker ask;
  return ask;
}
}  // namespace

void RigLink::setDefaultPinAsker(PinAsker ask) { default_pin_asker() = std::move(ask); }
bool RigLink::hasDefaultPinAsker() { return static_cast<bool>(default_pin_asker()); }

QString RigLink::knownRigsFile() const {
  return known_rigs_.isEmpty() ? qs(veneer::tls::default_known_rigs_file().string()) : known_rigs_;
}

QString RigLink::fingerprint() const {
  auto c = client();
  return c ? qs(c->fingerprint()) : QString();
}

bool RigLink::askPin(const QString& rig, const QString& fingerprint) {
  if (pin_asker_) return pin_asker_(rig, fingerprint);
  if (default_pin_asker()) return default_pin_asker()(rig, fingerprint);
  return false;
}

RigLink::RigLink(QObject* parent) : QObject(parent) {
  qRegisterMetaType<veneer::rig::Event>();
  qRegisterMetaType<veneer::rig::RigStatus>();
  qRegisterMetaType<veneer::rig::LiveFrame>();
  qRegisterMetaType<std::vector<veneer::rig::SetSummary>>();
  reconnect_timer_.setInterval(2000);
  reconnect_timer_.setSingleShot(true);
  connect(&reconnect_timer_, &QTimer::timeout, this, &RigLink::tryConnect);
}

RigLink::~RigLink() {
  wanted_ = false;
  if (auto c = takeClient()) c->close();
}

RigLink::ClientPtr RigLink::takeClient() {
  ClientPtr c;
  {
    std::lock_guard lock(mutex_);
    c.swap(client_);
  }
  if (c) {
    c->on_event = nullptr;
    c->on_live_frame = nullptr;
    c->on_disconnect = nullptr;
  }
  return c;
}

bool RigLink::isConnected() const {
  auto c = client();
  return c && c->connected();
}

RigLink::ClientPtr RigLink::client() const {
  std::lock_guard lock(mutex_);
  return client_;
}

void RigLink::connectTo(const QString& endpoint, const QString& token, const QString& fingerprint) {
  disconnectFromRig();
  endpoint_ = endpoint;
  token_ = token;
  fingerprint_ = fingerprint;
  wanted_ = true;
  tryConnect();
}

void RigLink::disconnectFromRig() {
  wanted_ = false;
  reconnect_timer_.stop();
  ++generation_;
  if (auto c = takeClient()) {
    (void)QtConcurrent::run(rig_pool(), [c] { c->close(); });
    emit connectedChanged(false, tr("disconnected from %1").arg(endpoint_));
  }
}

void RigLink::tryConnect() {
  if (!wanted_ || connecting_) return;
  connecting_ = true;
  const int gen = generation_;
  const std::string endpoint = endpoint_.toStdString(), token = token_.toStdString();
  veneer::rig::ConnectOptions options;
  options.client_name = "veneer-viewer";
  options.connect_timeout_s = 3.0;
  options.request_timeout_s = 30.0;
  options.fingerprint = fingerprint_.toStdString();
  options.known_rigs = knownRigsFile().toStdString();
  options.trust_loopback = false;  // a person looks at this rig: pinned wherever it is
  QPointer<RigLink> self(this);
  // First use: the question goes to the GUI thread, the connecting worker waits for the answer.
  options.confirm_first_use = [self](const std::string& rig, const std::string& seen) {
    bool yes = false;
    if (!self) return false;
    QMetaObject::invokeMethod(
        self.data(), [&yes, self, rig, seen] { yes = self && self->askPin(qs(rig), qs(seen)); },
        Qt::BlockingQueuedConnection);
    return yes;
  };
  (void)QtConcurrent::run(rig_pool(), [self, gen, endpoint, token, options] {
    auto ep = veneer::rig::Endpoint::parse(endpoint);
    veneer::Expected<std::unique_ptr<veneer::rig::Client>> result =
        ep ? veneer::rig::Client::connect(*ep, token, options)
           : veneer::Expected<std::unique_ptr<veneer::rig::Client>>(ep.error());
    std::shared_ptr<veneer::rig::Client> client;
    QString message;
    if (result) {
      client = std::shared_ptr<veneer::rig::Client>(std::move(*result));
    } else {
      message = qs(result.message());
    }
    QMetaObject::invokeMethod(
        self.data(),
        [self, gen, client, message] {
          if (!self) return;
          self->connecting_ = false;
          if (gen != self->generation_ || !self->wanted_) {
            if (client) (void)QtConcurrent::run(rig_pool(), [client] { client->close(); });
            return;
          }
          if (!client) {
            emit self->connectedChanged(false, tr("cannot connect to %1: %2").arg(self->endpoint_, message));
            // A wrong token or a bad address will not fix itself; a rig that is
            // down or a network drop might.
            const bool permanent = message.contains("token", Qt::CaseInsensitive) ||
                                   message.contains("address", Qt::CaseInsensitive) ||
                                   message.contains("fingerprint", Qt::CaseInsensitive);
            if (self->auto_reconnect_ && !permanent) self->reconnect_timer_.start();
            return;
          }
          QPointer<RigLink> weak(self);
          client->on_event = [weak](const veneer::rig::Event& e) {
            if (weak) emit weak->rigEvent(e);
          };
          // The latest frame wins: while the GUI thread has one waiting, a
          // newer one replaces it instead of queueing behind it, so a busy
          // GUI never works through a backlog of stale frames.
          auto slot = self->live_slot_;
          client->on_live_frame = [weak, slot](const veneer::rig::LiveFrame& f) {
            {
              std::lock_guard lock(slot->mutex);
              slot->frame = f;
              if (slot->posted) {
                ++slot->dropped;
                return;
              }
              slot->posted = true;
            }
            QMetaObject::invokeMethod(weak.data(), [weak, slot] {
              veneer::rig::LiveFrame latest;
              {
                std::lock_guard lock(slot->mutex);
                latest = std::move(slot->frame);
                slot->posted = false;
              }
              if (weak) emit weak->liveFrame(latest);
            });
          };
          client->on_disconnect = [weak](const std::string& why) {
            QString w = qs(why);
            if (weak) QMetaObject::invokeMethod(weak.data(), [weak, w] { if (weak) weak->onDropped(w); });
          };
          {
            std::lock_guard lock(self->mutex_);
            self->client_ = client;
          }
          self->status_ = client->hello_status();
          emit self->connectedChanged(true, tr("connected to %1").arg(self->endpoint_));
          emit self->statusUpdated(self->status_);
          self->listSets();
        },
        Qt::QueuedConnection);
  });
}

void RigLink::onDropped(const QString& why) {
  {
    std::lock_guard lock(mutex_);
    client_.reset();
  }
  if (!wanted_) return;
  emit connectedChanged(false, tr("lost the rig at %1 (%2) — reconnecting…").arg(endpoint_, why));
  if (auto_reconnect_) reconnect_timer_.start();
}

void RigLink::run(const QString& what, std::function<veneer::Status(veneer::rig::Client&)> job,
                  std::function<void()> on_ok) {
  auto c = client();
  if (!c) {
    emit failed(what, tr("not connected to a rig"));
    return;
  }
  QPointer<RigLink> self(this);
  (void)QtConcurrent::run(rig_pool(), [self, c, what, job, on_ok] {
    veneer::Status s = job(*c);
    QString msg = s ? QString() : qs(s.message());
    QMetaObject::invokeMethod(
        self.data(),
        [self, what, msg, ok = s.ok(), on_ok] {
          if (!self) return;
          if (!ok) {
            emit self->failed(what, msg);
          } else if (on_ok) {
            on_ok();
          }
        },
        Qt::QueuedConnection);
  });
}

template <class Call, class Deliver>
void RigLink::fetch(const QString& what, Call call, Deliver deliver) {
  QPointer<RigLink> self(this);
  run(what, [self, call, deliver](veneer::rig::Client& c) -> veneer::Status {
    auto got = call(c);
    if (!got) return got.error();
    QMetaObject::invokeMethod(self.data(), [self, deliver, v = *got] {
      if (self) deliver(*self, v);
    });
    return {};
  });
}

void RigLink::refreshStatus() {
  fetch(tr("status"), [](veneer::rig::Client& c) { return c.status(); },
        [](RigLink& link, const veneer::rig::RigStatus& st) {
          link.status_ = st;
          emit link.statusUpdated(st);
        });
}

void RigLink::listSets() {
  fetch(tr("list sets"), [](veneer::rig::Client& c) { return c.list_sets(); },
        [](RigLink& link, const std::vector<veneer::rig::SetSummary>& v) { emit link.setsListed(v); });
}

void RigLink::capture(const veneer::rig::CaptureOptions& options) {
  run(tr("capture"), [options](veneer::rig::Client& c) -> veneer::Status {
    auto id = c.capture(options);
    return id ? veneer::Status() : veneer::Status(id.error());
  });
}

void RigLink::cancelCapture() {
  run(tr("cancel capture"), [](veneer::rig::Client& c) { return c.cancel_capture(); });
}

void RigLink::pressButton(bool long_press) {
  run(tr("press button"), [long_press](veneer::rig::Client& c) { return c.press_button(long_press); });
}

void RigLink::setLamps(const std::vector<bool>& on, int brightness) {
  run(tr("lamps"), [on, brightness](veneer::rig::Client& c) { return c.set_lamps(on, brightness); });
}

void RigLink::startLive(double fps) {
  run(tr("live view"), [fps](veneer::rig::Client& c) { return c.start_live_view(fps); });
}

void RigLink::stopLive() {
  run(tr("stop live view"), [](veneer::rig::Client& c) { return c.stop_live_view(); });
}

void RigLink::moveHandLamp(const cv::Vec3d& position) {
  run(tr("hand lamp"), [position](veneer::rig::Client& c) { return c.move_hand_lamp(position); });
}

void RigLink::moveSet(const QString& what, const QString& id, SetMove move, void (RigLink::*moved)(QString)) {
  const std::string sid = id.toStdString();
  run(what, [sid, move](veneer::rig::Client& c) { return (c.*move)(sid); },
      [this, id, moved] {
        emit (this->*moved)(id);
        listSets();
      });
}

void RigLink::deleteSet(const QString& id) {
  moveSet(tr("delete %1").arg(id), id, &veneer::rig::Client::delete_set, &RigLink::deleted);
}

void RigLink::listTrash() {
  fetch(tr("list the rig's trash"), [](veneer::rig::Client& c) { return c.list_trash(); },
        [](RigLink& link, const std::vector<veneer::rig::SetSummary>& v) { emit link.trashListed(v); });
}

void RigLink::restoreSet(const QString& id) {
  moveSet(tr("restore %1").arg(id), id, &veneer::rig::Client::restore_set, &RigLink::restored);
}

void RigLink::cancelPulls() {
  pull_cancel_->store(true);
  pull_cancel_ = std::make_shared<std::atomic<bool>>(false);  // the next pull is not cancelled
}

void RigLink::pull(const QString& id, const QString& folder, int preview_width) {
  QPointer<RigLink> self(this);
  const std::string sid = id.toStdString(), dir = folder.toStdString();
  auto cancel = pull_cancel_;
  const bool truth = pull_truth_;
  ++pulls_running_;
  run(
      tr("pull %1").arg(id),
      [self, id, sid, dir, cancel, truth, preview_width](veneer::rig::Client& c) {
        struct Done {  // counted down however the pull ends
          QPointer<RigLink> self;
          ~Done() {
            QMetaObject::invokeMethod(self.data(), [s = self] {
              if (s) --s->pulls_running_;
            });
          }
        } done{self};
        veneer::Progress progress;
        progress.cancel = cancel.get();
        progress.on_progress = [self, id](double f, const std::string&) {
          QMetaObject::invokeMethod(self.data(), [self, id, f] {
            if (self) emit self->pullProgress(id, f);
          });
        };
        veneer::rig::PullOptions o;
        o.include_truth = truth;
        o.overwrite = true;
        o.live_first = preview_width > 0;
        o.on_preview = [self, id, preview_width](const std::filesystem::path& f) {
          veneer::io::ReadOptions manifest;
          manifest.load_photos = false;
          manifest.load_truth = false;
          auto preview = veneer::io::read_set(f, manifest);
          if (!preview || preview->size.width < preview_width) return;  // too small to stand in: the full files
          const QString folder = QString::fromStdString(f.string());
          QMetaObject::invokeMethod(self.data(), [self, id, folder] {
            if (self) emit self->previewPulled(id, folder);
          });
        };
        return c.pull_set(sid, dir, o, progress);
      },
      [this, id, folder] { emit pulled(id, folder); });
}

}  // namespace veneer::app
