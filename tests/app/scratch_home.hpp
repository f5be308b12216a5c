// The viewer's tests and benchmark keep settings, the library and every cache
// (Qt's, fontconfig's, GStreamer's, the rigs') in a folder of their run, never
// the user's (issue 49: the rig panel wrote a test rig's address into
// ~/.config/veneer/veneer-viewer.conf). Before the QApplication is made; the
// programs they start (veneerd, veneer) inherit it.
#pragma once

#include <QByteArray>
#include <QTemporaryDir>

namespace veneer::test {

inline void use_scratch_xdg_folders(const QTemporaryDir& dir) {
  for (const char* name : {"config", "cache", "data", "state"})
    qputenv(("XDG_" + QByteArray(name).toUpper() + "_HOME").constData(), (dir.path() + "/" + name).toUtf8());
}

}  // namespace veneer::test
