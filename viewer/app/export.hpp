#pragma once
// The exports: the map, the result pictures, the relight sweep video and the
// web page of the look (veneer transfer --web's), each
// a job off the GUI thread told in the status line, cancellable there, and
// written whole or not at all.
#include <atomic>
#include <functional>

#include <QFuture>
#include <QObject>

#include "session.hpp"

class QWidget;

namespace veneer::app {

class ExportActions : public QObject {
  Q_OBJECT
 public:
  // `window` is the parent of the dialogs asking where to write.
  ExportActions(Session& session, QWidget* window);
  ~ExportActions() override;
  // The menu's entries: ask for the place, then write.
  void exportMap();
  void exportResults();
  void exportRelightVideo();
  void exportWebPage();
  // Without a dialog.
  void exportMapTo(const QString& dir);
  void exportResultsTo(const QString& dir);
  void exportRelightVideoTo(const QString& file);
  // The web page of the look (repaint/web_export.hpp) into `dir` (a new or empty folder, or a page written before).
  void exportWebPageTo(const QString& dir);
  bool exporting() const { return job_running_; }
  void cancel() { job_cancel_ = true; }

 private:
  // Runs `job` off the GUI thread as a step of the status line.
  void runJob(const QString& kind, const QString& text, std::function<veneer::Status(const veneer::Progress&)> job,
              const QString& done);
  // Whether there is a result to export; without one, says so.
  bool haveResult();
  // Asks for a folder (dialog titled `title`), then writes into it with `into`.
  void exportIntoFolder(const QString& title, void (ExportActions::*into)(const QString&));

  Session& session_;
  QWidget* window_;
  std::atomic<bool> job_cancel_{false};
  bool job_running_ = false;
  QFuture<void> job_future_;
};

}  // namespace veneer::app
