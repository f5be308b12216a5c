// veneer-viewer — the desktop program.
#include <QApplication>
#include <QCommandLineParser>

#include "main_window.hpp"
#include "veneer/util/cpu_check.hpp"
#include "veneer/util/large_buffers.hpp"

int main(int argc, char** argv) {
  QApplication app(argc, argv);
  QApplication::setApplicationName("veneer-viewer");
  QApplication::setOrganizationName("veneer");
  QApplication::setApplicationVersion(VENEER_VERSION);
  QCommandLineParser parser;
  parser.setApplicationDescription("Veneer: transfer the look of one object onto another, live.");
  parser.addHelpOption();
  parser.addVersionOption();
  QCommandLineOption rig("rig", "rig to connect to at start (host:port)", "host:port");
  QCommandLineOption token("token-file", "the rig's access token file", "file");
  QCommandLineOption fingerprint("fingerprint", "the rig's certificate fingerprint (`veneerd --fingerprint`)", "hex");
  QCommandLineOption dst("dst", "destination image set to load", "folder");
  QCommandLineOption src("src", "source image set to load", "folder");
  QCommandLineOption workdir("workdir", "where pulled sets are kept", "folder");
  QCommandLineOption compute("compute", "compute the transfer once both sets are loaded");
  parser.addOptions({rig, token, fingerprint, dst, src, workdir, compute});
  parser.process(app);
  veneer::app::MainWindow::Options o;
  o.rig = parser.value(rig);
  o.token_file = parser.value(token);
  o.destination = parser.value(dst);
  o.source = parser.value(src);
  o.workdir = parser.value(workdir);
  // With the rig's fingerprint given, the window connects with it (else with the pinned one, or asks).
  const bool pinned_here = parser.isSet(fingerprint) && !o.rig.isEmpty();
  if (pinned_here) o.rig.clear();
  veneer::app::MainWindow window(o);
  window.show();
  if (pinned_here) window.rigPanel().connectToRig(parser.value(rig), o.token_file, parser.value(fingerprint));
  if (parser.isSet(compute)) window.transfer().startTransfer();
  return app.exec();
}
