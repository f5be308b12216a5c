// app/Viewer.CalibratesLampsFromAChromeSphereSet: the viewer's calibration
// step on the real chrome sphere writes the lights file the CLI reads and
// shows the picture of the circle and the highlights it found.
#include <cmath>
#include <filesystem>

#include <QDialog>
#include <QFileInfo>
#include <QLabel>
#include <QTemporaryDir>

#include <gtest/gtest.h>

#include "main_window.hpp"
#include "veneer/ps/calibration.hpp"

using veneer::app::MainWindow;

TEST(Viewer, CalibratesLampsFromAChromeSphereSet) {
  const std::filesystem::path chrome = std::filesystem::path(VENEER_SHARED_DATA) / "real" / "chrome";
  if (!std::filesystem::exists(chrome / "filenames.txt")) GTEST_SKIP() << "no " << chrome;
  QTemporaryDir dir;
  MainWindow w({QString(), QString(), QString(), QString(), dir.path()});
  const QString file = dir.path() + "/lights.json";
  ASSERT_TRUE(w.calibration().calibrateLamps(QString::fromStdString(chrome.string()), file))
      << w.status().lastMessage().toStdString();
  EXPECT_TRUE(w.status().lastMessage().contains("12 lamps calibrated")) << w.status().lastMessage().toStdString();
  auto cal = veneer::ps::read_light_calibration(file.toStdString());
  ASSERT_TRUE(cal.ok()) << cal.message();
  EXPECT_EQ(cal->directions.size(), 12u);
  // The picture shown is the set's size, with the fitted circle drawn in green.
  auto* label = w.findChild<QLabel*>("calibrationPicture");
  ASSERT_NE(label, nullptr);
  const QImage shown = label->pixmap().toImage();
  ASSERT_EQ(shown.size(), QSize(512, 340));
  const QPoint on_circle(static_cast<int>(std::lround(cal->center.x + cal->radius)),
                         static_cast<int>(std::lround(cal->center.y)));
  const QColor c = shown.pixelColor(on_circle);
  EXPECT_GT(c.green(), 100) << "the circle passes through the sphere's right edge";
  EXPECT_LT(c.red(), c.green());
  EXPECT_TRUE(w.findChild<QDialog*>("calibrationDialog")->isVisible());

  // Not a sphere set: one clear message, no file.
  const QString bad = dir.path() + "/none.json";
  EXPECT_FALSE(w.calibration().calibrateLamps(dir.path() + "/missing", bad));
  EXPECT_TRUE(w.status().lastMessage().startsWith("calibration")) << w.status().lastMessage().toStdString();
  EXPECT_FALSE(QFileInfo::exists(bad));
}
