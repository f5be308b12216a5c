#pragma once
// The viewer's link to a rig: wraps the Qt-free veneer::rig::Client, runs its
// blocking requests on worker threads and hands every answer, event and live
// frame to the GUI thread as a signal. Reconnects by itself after a drop.
#include <atomic>
#include <functional>
#include <memory>
#include <mutex>

#include <QObject>
#include <QString>
#include <QTimer>

#include "qt_convert.hpp"
#include "veneer/rig/client.hpp"

namespace veneer::app {

class RigLink : public QObject {
  Q_OBJECT
 public:
  explicit RigLink(QObject* parent = nullptr);
  ~RigLink() override;

  bool isConnected() const;
  QString endpoint() const { return endpoint_; }
  const veneer::rig::RigStatus& lastStatus() const { return status_; }

  // Connects (in the background); `token` is the rig's access token.
  void connectTo(const QString& endpoint, const QString& token);
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
  void pull(const QString& id, const QString& folder);
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
  QString endpoint_, token_;
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
};

}  // namespace veneer::app
