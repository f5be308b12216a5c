#pragma once
// The viewer's link to a rig: wraps the Qt-free veneer::rig::Client, runs its
// blocking requests on worker threads and hands every answer, event and live
// frame to the GUI thread as a signal. Reconnects by itself after a drop.
// The connection is TLS 1.3 with the rig's certificate pinned (known-rigs
// file): at a rig's first use the pin asker (a dialog, RigPanel's) shows the
// fingerprint to compare; a changed certificate is refused, never asked about.
#include <atomic>
#include <functional>
#include <memory>
#include <mutex>

#include <QObject>
#include <QString>
#include <QTimer>

#include "qt_convert.hpp"
#include "veneer/rig/client.hpp"

class QThreadPool;

namespace veneer::app {

// The pool the rig's calls run on (not Qt's global pool: see rig_link.cpp).
QThreadPool* rig_pool();

class RigLink : public QObject {
  Q_OBJECT
 public:
  explicit RigLink(QObject* parent = nullptr);
  ~RigLink() override;

  bool isConnected() const;
  QString endpoint() const { return endpoint_; }
  const veneer::rig::RigStatus& lastStatus() const { return status_; }

  // Connects (in the background); `token` is the rig's access token;
  // `fingerprint` (optional) the rig's certificate's, as `veneerd --fingerprint` prints it.
  void connectTo(const QString& endpoint, const QString& token, const QString& fingerprint = {});

  // Asked on the GUI thread at a rig's first use (no fingerprint given or
  // pinned): show `fingerprint` to compare; true pins it, false refuses the rig.
  using PinAsker = std::function<bool(const QString& rig, const QString& fingerprint)>;
  void setPinAsker(PinAsker ask) { pin_asker_ = std::move(ask); }
  // The asker of every link that has none of its own (tests answer here; the
  // windows' RigPanel installs its dialog only when this is unset).
  static void setDefaultPinAsker(PinAsker ask);
  static bool hasDefaultPinAsker();
  // The known-rigs file (default: veneer::tls::default_known_rigs_file()).
  void setKnownRigsFile(const QString& file) { known_rigs_ = file; }
  QString knownRigsFile() const;
  // The connected rig's certificate fingerprint ("" in plain TCP or unconnected).
  QString fingerprint() const;
  void disconnectFromRig();
  void setAutoReconnect(bool on) { auto_reconnect_ = on; }

  // Requests (each answers with a signal; failures with failed(what, message)).
  void refreshStatus();
  void listSets();
  void capture(const veneer::rig::CaptureOptions& options);
  void cancelCapture();
  void pressButton(bool long_press);
  void setLamps(const std::vector<bool>& on, int brightness);
  void startLive(double fps);
  void stopLive();
  void moveHandLamp(const cv::Vec3d& position);
  void deleteSet(const QString& id);  // into the rig's trash
  void listTrash();
  void restoreSet(const QString& id);
  // With preview_width > 0, the rig's preview set (about 1/4 size, a JPEG
  // per lamp) is put in `folder` first and previewPulled says so when it is
  // at least that wide; the full files then replace it in one step and
  // pulled follows (rig::Client::pull_set's live first). A rig without
  // previews, or a narrower preview: pulled only.
  void pull(const QString& id, const QString& folder, int preview_width = 0);
  // Whether pulls bring the simulated rig's truth/ too (for the tests that
  // measure against it; a user's sets have none). Default off.
  void setPullTruth(bool on) { pull_truth_ = on; }
  void cancelPulls();  // the pulls running stop (their temporary folders go)
  bool pulling() const { return pulls_running_ > 0; }

 signals:
  void connectedChanged(bool connected, QString message);
  void statusUpdated(veneer::rig::RigStatus status);
  void setsListed(std::vector<veneer::rig::SetSummary> sets);
  void trashListed(std::vector<veneer::rig::SetSummary> sets);
  void deleted(QString id);
  void restored(QString id);
  void rigEvent(veneer::rig::Event event);
  void liveFrame(veneer::rig::LiveFrame frame);
  void pullProgress(QString id, double fraction);
  void previewPulled(QString id, QString folder);
  void pulled(QString id, QString folder);
  void failed(QString what, QString message);
  void info(QString message);

 private:
  using ClientPtr = std::shared_ptr<veneer::rig::Client>;
  // Runs `job` on a worker with the current client; reports failure as failed(what).
  void run(const QString& what, std::function<veneer::Status(veneer::rig::Client&)> job,
           std::function<void()> on_ok = {});
  // Runs `call` (the client's answer or an error) on a worker; on success
  // `deliver(*this, answer)` runs on the GUI thread, while this link lives.
  template <class Call, class Deliver>
  void fetch(const QString& what, Call call, Deliver deliver);
  // Deleting a set or restoring one: `move` on the rig, then `moved(id)` and the list read again.
  using SetMove = veneer::Status (veneer::rig::Client::*)(const std::string&);
  void moveSet(const QString& what, const QString& id, SetMove move, void (RigLink::*moved)(QString));
  ClientPtr client() const;
  // Takes the client out of the link, its callbacks (which point at this link) cleared.
  ClientPtr takeClient();
  void tryConnect();
  void onDropped(const QString& why);

  mutable std::mutex mutex_;
  ClientPtr client_;
  bool askPin(const QString& rig, const QString& fingerprint);
  QString endpoint_, token_, fingerprint_, known_rigs_;
  PinAsker pin_asker_;
  bool wanted_ = false, auto_reconnect_ = true, connecting_ = false;
  int generation_ = 0;
  QTimer reconnect_timer_;
  veneer::rig::RigStatus status_;
  struct LiveSlot {  // the newest live frame not yet shown
    std::mutex mutex;
    veneer::rig::LiveFrame frame;
    bool posted = false;
    long dropped = 0;
  };
  std::shared_ptr<LiveSlot> live_slot_ = std::make_shared<LiveSlot>();
  std::shared_ptr<std::atomic<bool>> pull_cancel_ = std::make_shared<std::atomic<bool>>(false);
  int pulls_running_ = 0;
  bool pull_truth_ = false;
};

}  // namespace veneer::app
