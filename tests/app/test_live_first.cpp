// Live first in the viewer's automatic flow: with a live width below the
// rig's still size, the pulled sets are read small (reduced decodes), the map
// is made at that size and the live repaint starts on it; the
// full-resolution map follows in the background and is swapped in, the live
// repaint going on through it; and that map is the one `veneer transfer`
// makes from the same folders.
#include <sys/wait.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>

#include <QFile>
#include <QLabel>
#include <QLineEdit>
#include <QProcess>
#include <QPushButton>
#include <QTemporaryDir>
#include <QTest>
#include <QTimer>

#include <gtest/gtest.h>

#include "main_window.hpp"
#include "veneer/pipeline/transfer.hpp"
#include "wait_for.hpp"

using veneer::app::MainWindow;

namespace {

class Rig {
 public:
  explicit Rig(const QString& size) {
    store_ = dir_.path() + "/store";
    // A new rig, a new certificate, maybe on a port an earlier rig of this test had: no pin of before holds.
    if (!qEnvironmentVariableIsEmpty("VENEER_KNOWN_RIGS")) QFile::remove(qEnvironmentVariable("VENEER_KNOWN_RIGS"));
    process_.setProcessChannelMode(QProcess::MergedChannels);
    process_.start(VENEER_BIN_DIR "/veneerd", {"--simulate", "--scenes", "bull,orange", "--size", size, "--listen",
                                               "127.0.0.1:0", "--store", store_});
    started_ = process_.waitForStarted(5000) && wait_for(
                                                    [&] {
                                                      output_ += QString::fromUtf8(process_.readAll());
                                                      const int at = output_.indexOf("veneerd: listening on 127.0.0.1:");
                                                      if (at < 0) return false;
                                                      port_ = output_.mid(at + 32).section(',', 0, 0).toInt();
                                                      return port_ > 0;
                                                    },
                                                    20000);
  }
  ~Rig() {
    process_.kill();
    process_.waitForFinished(5000);
  }
  bool started() const { return started_; }
  QString endpoint() const { return QString("127.0.0.1:%1").arg(port_); }
  QString token_file() const { return store_ + "/token"; }
  QString log() { return output_ + QString::fromUtf8(process_.readAll()); }

 private:
  QTemporaryDir dir_;
  QString store_, output_;
  QProcess process_;
  int port_ = 0;
  bool started_ = false;
};

double now_ms() {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

TEST(LiveFirst, GoesLiveOnTheLiveSizeMapThenSwapsInTheFullResolution) {
  Rig rig("512x340");
  ASSERT_TRUE(rig.started()) << rig.log().toStdString();
  QTemporaryDir work;
  MainWindow w({QString(), QString(), QString(), QString(), work.path()});
  w.flow().setLiveWidth(256);
  w.resize(1280, 720);
  w.show();
  ASSERT_TRUE(w.capture().autoFlow());
  w.findChild<QLineEdit*>("rigAddress")->setText(rig.endpoint());
  w.findChild<QLineEdit*>("tokenFile")->setText(rig.token_file());
  QTest::mouseClick(w.findChild<QPushButton*>("connect"), Qt::LeftButton);
  ASSERT_TRUE(wait_for([&] { return w.rig().isConnected(); }, 10000)) << w.status().lastMessage().toStdString();
  QTest::mouseClick(w.findChild<QPushButton*>("captureSource"), Qt::LeftButton);
  ASSERT_TRUE(wait_for([&] { return w.session().src != nullptr; }, 60000)) << w.status().lastMessage().toStdString();
  w.showTab("Live");
  QTest::mouseClick(w.findChild<QPushButton*>("liveCaptureDestination"), Qt::LeftButton);

  // live on the live-size map first
  ASSERT_TRUE(wait_for([&] { return w.session().result != nullptr && !w.transfer().computing(); }, 120000))
      << w.status().lastMessage().toStdString();
  EXPECT_TRUE(w.session().dst->live_size);
  EXPECT_TRUE(w.session().src->live_size);
  EXPECT_EQ(w.session().dst->set.size, cv::Size(256, 170));
  EXPECT_EQ(w.session().result->map.xy.size(), cv::Size(256, 170));
  EXPECT_EQ(w.liveFirst().swaps(), 0);
  // the repaint runs on it (or, on a slow machine, the full resolution was already swapped in)
  ASSERT_TRUE(wait_for([&] { return w.live().framesShown() >= 2 && !w.live().lastRepaintedFrame().empty(); }, 30000))
      << w.status().lastMessage().toStdString();
  if (w.liveFirst().swaps() == 0) {
    EXPECT_EQ(w.live().lastRepaintedFrame().size(), cv::Size(256, 170));
    EXPECT_TRUE(w.liveFirst().running());
    EXPECT_TRUE(w.liveFirst().line().startsWith("full resolution")) << w.liveFirst().line().toStdString();
  }

  // the full resolution follows and is swapped in; the GUI keeps its beat
  double last = now_ms(), worst = 0;
  int ticks = 0;
  QTimer beat;
  QObject::connect(&beat, &QTimer::timeout, [&] {
    const double t = now_ms();
    worst = std::max(worst, t - last);
    last = t;
    ++ticks;
  });
  beat.start(10);
  ASSERT_TRUE(wait_for([&] { return w.liveFirst().swaps() == 1; }, 240000))
      << w.status().lastMessage().toStdString() << " / " << w.liveFirst().line().toStdString();
  beat.stop();
  if (ticks > 0)  // a number, not asserted (bench_app measures it)
    std::printf("longest GUI stall while the full resolution was made and swapped in: %.0f ms\n", worst);
  EXPECT_FALSE(w.session().dst->live_size);
  EXPECT_EQ(w.session().result->map.xy.size(), cv::Size(512, 340));
  EXPECT_TRUE(w.liveFirst().line().contains("in use")) << w.liveFirst().line().toStdString();
  const int frames = w.live().framesShown();
  ASSERT_TRUE(wait_for([&] { return w.live().framesShown() >= frames + 2; }, 30000));
  EXPECT_EQ(w.live().lastRepaintedFrame().size(), cv::Size(512, 340));
  // the live views were painted from frames already at their sizes: nothing scaled on the GUI thread
  EXPECT_TRUE(wait_for([&] { return w.live().fittedPaints() > 0; }, 10000));
  // the full-resolution session paints the live look too (issue 40)
  ASSERT_NE(w.session().live_session, nullptr);
  EXPECT_TRUE(w.session().live_session->has_live_look());
  EXPECT_EQ(w.live().lastPaintedLook(), veneer::repaint::Look::shaded);
  w.findChild<QPushButton*>("liveToggle")->setChecked(false);

  // the same map as `veneer transfer` makes from the folders
  const QString out = work.path() + "/cli";
  const std::string cmd = std::string(VENEER_BIN_DIR "/veneer transfer --dst '") +
                          w.session().dst->folder.toStdString() + "' --src '" + w.session().src->folder.toStdString() +
                          "' --out '" + out.toStdString() + "' >/dev/null";
  const int status = std::system(cmd.c_str());
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << cmd;
  auto cli = veneer::match::read_map((out + "/map.pfm").toStdString());
  ASSERT_TRUE(cli) << cli.message();
  ASSERT_EQ(cli->xy.size(), w.session().result->map.xy.size());
  cv::Mat diff;
  cv::absdiff(cli->xy, w.session().result->map.xy, diff);
  const double same = 1.0 - static_cast<double>(cv::countNonZero(diff.reshape(1) > 0.01)) / (diff.total() * 2);
  EXPECT_GT(same, 0.99) << "share of map coordinates equal to the CLI's";
}

// Issue 42: on a rig whose stills are wider than the live width, the live
// view (1024 px, the simulated camera's) is smaller than the live-size stills
// (1280 px) and than the full-resolution ones (1536 px). It repaints through
// the live-size map while the full-resolution job has not begun (held), and
// through the full-resolution map after the swap; it was refused before
// ("cannot be related to the stills ... ECC 0.82"), and no frame was ever
// repainted.
TEST(LiveFirst, RepaintsThroughTheLiveSizeMapBeforeTheFullResolutionExists) {
  Rig rig("1536x1024");
  ASSERT_TRUE(rig.started()) << rig.log().toStdString();
  QTemporaryDir work;
  MainWindow w({QString(), QString(), QString(), QString(), work.path()});
  ASSERT_EQ(w.flow().liveWidth(), 1280);  // the default live width
  w.liveFirst().setHeld(true);            // the full resolution waits until released below
  w.resize(1280, 720);
  w.show();
  w.findChild<QLineEdit*>("rigAddress")->setText(rig.endpoint());
  w.findChild<QLineEdit*>("tokenFile")->setText(rig.token_file());
  QTest::mouseClick(w.findChild<QPushButton*>("connect"), Qt::LeftButton);
  ASSERT_TRUE(wait_for([&] { return w.rig().isConnected(); }, 10000)) << w.status().lastMessage().toStdString();
  QTest::mouseClick(w.findChild<QPushButton*>("captureSource"), Qt::LeftButton);
  ASSERT_TRUE(wait_for([&] { return w.session().src != nullptr; }, 60000)) << w.status().lastMessage().toStdString();
  w.showTab("Live");
  QTest::mouseClick(w.findChild<QPushButton*>("liveCaptureDestination"), Qt::LeftButton);
  ASSERT_TRUE(wait_for([&] { return w.session().result != nullptr && !w.transfer().computing(); }, 120000))
      << w.status().lastMessage().toStdString();
  ASSERT_TRUE(w.session().dst->live_size);
  const cv::Size live_map = w.session().result->map.xy.size();
  EXPECT_EQ(live_map, cv::Size(1280, 853));
  // repainted frames through the live-size map, the full resolution not begun
  ASSERT_TRUE(wait_for([&] { return w.live().framesShown() >= 3 && !w.live().lastRepaintedFrame().empty(); }, 30000))
      << w.status().lastMessage().toStdString() << " / refusal: " << w.session().live_refusal.toStdString();
  EXPECT_TRUE(w.session().live_refusal.isEmpty()) << w.session().live_refusal.toStdString();
  EXPECT_LT(w.live().lastFrame().cols, live_map.width);  // the live view is smaller than the stills
  EXPECT_EQ(w.live().lastRepaintedFrame().size(), live_map);
  EXPECT_EQ(w.liveFirst().swaps(), 0);
  EXPECT_TRUE(w.liveFirst().running());
  ASSERT_NE(w.session().live_session, nullptr);
  ASSERT_TRUE(w.session().live_session->geometry());
  EXPECT_NEAR(w.session().live_session->geometry()->scale, 1024.0 / 1280, 0.01)
      << w.session().live_session->geometry()->describe();

  // released: the full resolution is swapped in and the live view repaints through it
  w.liveFirst().setHeld(false);
  ASSERT_TRUE(wait_for([&] { return w.liveFirst().swaps() == 1; }, 240000))
      << w.status().lastMessage().toStdString() << " / " << w.liveFirst().line().toStdString();
  const int frames = w.live().framesShown();
  ASSERT_TRUE(wait_for([&] { return w.live().framesShown() >= frames + 3; }, 30000));
  EXPECT_TRUE(w.session().live_refusal.isEmpty()) << w.session().live_refusal.toStdString();
  EXPECT_EQ(w.live().lastRepaintedFrame().size(), cv::Size(1536, 1024));
  ASSERT_TRUE(w.session().live_session->geometry());
  EXPECT_NEAR(w.session().live_session->geometry()->scale, 1024.0 / 1536, 0.01)
      << w.session().live_session->geometry()->describe();
  w.findChild<QPushButton*>("liveToggle")->setChecked(false);
}

}  // namespace
