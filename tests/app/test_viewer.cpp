// app/viewer: the window against a real simulated rig (veneerd --simulate),
// driven through its buttons under Qt's offscreen platform.
#include <filesystem>
#include <random>

#include <memory>

#include <QApplication>
#include <QCheckBox>
#include <QComboBox>
#include <QDoubleSpinBox>
#include <QDate>
#include <QDir>
#include <QSpinBox>
#include <QFile>
#include <QFileInfo>
#include <QLabel>
#include <QMessageBox>
#include <QDateTime>
#include <QLineEdit>
#include <QProcess>
#include <QProgressBar>
#include <QPushButton>
#include <QSemaphore>
#include <QSignalSpy>
#include <QTcpServer>
#include <QTemporaryDir>
#include <QTest>
#include <QThreadPool>
#include <QScrollArea>
#include <QToolButton>
#include <QTreeWidget>
#include <QWheelEvent>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "main_window.hpp"
#include "rig_link.hpp"
#include "scratch_home.hpp"
#include "veneer/proto/tls.hpp"
#include "widgets.hpp"
#include "wait_for.hpp"
#include "veneer/pipeline/transfer.hpp"
#include "veneer/ps/segmentation.hpp"
#include "veneer/sim/simulator.hpp"

namespace fs = std::filesystem;
using veneer::app::MainWindow;

namespace {


int free_port() {
  QTcpServer s;
  s.listen(QHostAddress::LocalHost, 0);
  return s.serverPort();
}

class SimulatedRig {
 public:
  SimulatedRig() {
    store_ = dir_.path() + "/store";
    // A new rig, a new certificate, maybe on a port an earlier rig of this test had: no pin of before holds.
    if (!qEnvironmentVariableIsEmpty("VENEER_KNOWN_RIGS")) QFile::remove(qEnvironmentVariable("VENEER_KNOWN_RIGS"));
    process_.setProcessChannelMode(QProcess::MergedChannels);
    // Port 0: the daemon picks a free port and says which on its first line.
    process_.start(VENEER_BIN_DIR "/veneerd", {"--simulate", "--scenes", "bull,orange", "--size", "256x170",
                                               "--listen", "127.0.0.1:0", "--store", store_});
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
  ~SimulatedRig() {
    process_.kill();
    process_.waitForFinished(5000);
  }
  bool started() const { return started_; }
  QString endpoint() const { return QString("127.0.0.1:%1").arg(port_); }
  QString token_file() const { return store_ + "/token"; }
  QString store() const { return store_; }
  QString log() { return output_ + QString::fromUtf8(process_.readAll()); }

 private:
  QTemporaryDir dir_;
  QString store_, output_;
  QProcess process_;
  int port_ = 0;
  bool started_ = false;
};

template <class T>
T* child(MainWindow& w, const char* name) {
  T* c = w.findChild<T*>(name);
  EXPECT_NE(c, nullptr) << "no widget named " << name;
  return c;
}

void select_item(QTreeWidget* tree, QTreeWidgetItem* item) {
  tree->clearSelection();
  item->setSelected(true);
}

// A small simulated pair written as local sets.
void write_pair(const QString& dir, QString& dst, QString& src) {
  veneer::sim::RenderOptions o;
  o.size = cv::Size(256, 170);
  o.noise_sigma = 0.002;
  auto d = veneer::sim::simulate_set("bull", o, veneer::io::Role::destination);
  auto s = veneer::sim::simulate_set("orange", o, veneer::io::Role::source);
  ASSERT_TRUE(d.ok() && s.ok());
  dst = dir + "/bull";
  src = dir + "/orange";
  ASSERT_TRUE(veneer::io::write_set(*d, dst.toStdString()).ok());
  ASSERT_TRUE(veneer::io::write_set(*s, src.toStdString()).ok());
}

// A window with a small simulated pair loaded from local sets in `dir`
// (nullptr, with a failure recorded, when they do not load).
std::unique_ptr<MainWindow> open_pair(const QTemporaryDir& dir) {
  QString dst, src;
  write_pair(dir.path(), dst, src);
  auto w = std::make_unique<MainWindow>(MainWindow::Options{QString(), QString(), dst, src, dir.path()});
  EXPECT_NE(w->session().dst, nullptr);
  EXPECT_NE(w->session().src, nullptr);
  if (!w->session().dst || !w->session().src) return nullptr;
  return w;
}

// Compute pressed and waited for: success when a result is shown.
::testing::AssertionResult compute_and_wait(MainWindow& w) {
  QTest::mouseClick(child<QPushButton>(w, "compute"), Qt::LeftButton);
  if (!wait_for([&] { return !w.transfer().computing(); }, 60000)) return ::testing::AssertionFailure()
      << "still computing";
  if (!w.session().result) return ::testing::AssertionFailure()
      << "no result: " << w.status().lastMessage().toStdString();
  return ::testing::AssertionSuccess();
}

}  // namespace

TEST(Viewer, CaptureByButtonAndUiPullTransferAndLive) {
  SimulatedRig rig;
  ASSERT_TRUE(rig.started()) << rig.log().toStdString();
  QTemporaryDir work;
  MainWindow w({QString(), QString(), QString(), QString(), work.path()});
  w.show();
  w.capture().setAutoFlow(false);  // every step by hand here; the automatic one is app/workflow.*
  w.rigPanel().connectToRig(rig.endpoint(), rig.token_file());
  ASSERT_TRUE(wait_for([&] { return w.rig().isConnected(); }, 10000)) << w.status().lastMessage().toStdString();
  EXPECT_TRUE(w.status().lastMessage().contains("connected"));
  EXPECT_TRUE(child<QLabel>(w, "rigStatus")->text().contains("simulated"));

  // The rig's button captures the destination, the UI's button the source.
  QTest::mouseClick(child<QPushButton>(w, "pressButton"), Qt::LeftButton);
  auto* tree = child<QTreeWidget>(w, "sets");
  QTreeWidgetItem* on_rig = tree->topLevelItem(0);
  ASSERT_TRUE(wait_for([&] { return on_rig->childCount() >= 1; }, 60000)) << w.status().lastMessage().toStdString();
  EXPECT_TRUE(child<QLabel>(w, "captureStatus")->text().contains("stored"));
  QTest::mouseClick(child<QPushButton>(w, "captureSource"), Qt::LeftButton);
  ASSERT_TRUE(wait_for([&] { return on_rig->childCount() >= 2; }, 60000)) << w.status().lastMessage().toStdString();
  auto* shots = child<QProgressBar>(w, "shotProgress");
  EXPECT_EQ(shots->value(), shots->maximum());

  // Pull both into the work folder.
  QTreeWidgetItem* local = tree->topLevelItem(1);
  QString roles[2];
  for (int i = 0; i < 2; ++i) {
    select_item(tree, on_rig->child(i));
    roles[i] = on_rig->child(i)->text(1);
    QTest::mouseClick(child<QPushButton>(w, "pullSet"), Qt::LeftButton);
    ASSERT_TRUE(wait_for([&] { return local->childCount() >= i + 1; }, 30000))
        << w.status().lastMessage().toStdString();
  }
  EXPECT_TRUE(roles[0] != roles[1]) << "one destination and one source";
  // A user's pull leaves the simulated rig's truth/ on the rig (issue 48).
  int pulled = 0;
  for (const auto& e : std::filesystem::directory_iterator((work.path() + "/sets").toStdString())) {
    if (!std::filesystem::exists(e.path() / "set.json")) continue;
    ++pulled;
    EXPECT_FALSE(std::filesystem::exists(e.path() / "truth")) << e.path();
  }
  EXPECT_EQ(pulled, 2);
  for (int i = 0; i < 2; ++i) {
    select_item(tree, local->child(i));
    const bool is_source = local->child(i)->text(1) == "source";
    QTest::mouseClick(child<QPushButton>(w, is_source ? "useSource" : "useDestination"), Qt::LeftButton);
  }
  // loaded off the GUI thread
  ASSERT_TRUE(wait_for([&] { return w.session().loads_running == 0 && w.session().dst && w.session().src; }, 30000))
      << w.status().lastMessage().toStdString();
  ASSERT_NE(w.session().dst, nullptr)
      << local->child(0)->text(1).toStdString() << " " << local->child(1)->text(1).toStdString();
  ASSERT_NE(w.session().src, nullptr)
      << local->child(0)->text(1).toStdString() << " " << local->child(1)->text(1).toStdString();
  EXPECT_EQ(w.session().dst->set.role, veneer::io::Role::destination);
  EXPECT_EQ(w.session().src->set.role, veneer::io::Role::source);

  // Transfer in the background.
  QTest::mouseClick(child<QPushButton>(w, "compute"), Qt::LeftButton);
  EXPECT_TRUE(w.transfer().computing());
  ASSERT_TRUE(wait_for([&] { return !w.transfer().computing(); }, 120000));
  ASSERT_NE(w.session().result, nullptr) << w.status().lastMessage().toStdString();
  const auto& map = w.session().result->map;
  cv::Mat xy[2];
  cv::split(map.xy, xy);
  const int mapped = cv::countNonZero(xy[0] >= 0);
  EXPECT_GT(mapped, 200);

  // Live frames repainted through the map: under the default look painted
  // shaded at the light estimated in each frame (issue 40), under the copy
  // look the frame's pixels, checked against the map applied by hand.
  w.showTab("Live");
  ASSERT_NE(w.session().live_session, nullptr);
  EXPECT_TRUE(w.session().live_session->has_live_look()) << w.status().lastMessage().toStdString();
  EXPECT_EQ(w.live().look(), veneer::repaint::Look::shaded) << "the live view paints the look by default";
  child<QPushButton>(w, "liveToggle")->setChecked(true);
  ASSERT_TRUE(wait_for([&] { return w.live().framesShown() >= 3 && !w.live().lastRepaintedFrame().empty(); }, 20000))
      << w.status().lastMessage().toStdString();
  EXPECT_EQ(w.live().lastPaintedLook(), veneer::repaint::Look::shaded);
  ASSERT_TRUE(w.live().lightDial().light().has_value()) << w.live().lightDial().text().toStdString();
  const veneer::repaint::LiveLight frame_light = *w.live().lightDial().light();
  EXPECT_TRUE(frame_light.explained) << "residual " << frame_light.residual;
  EXPECT_GT(frame_light.intensity, 0);
  EXPECT_NEAR(cv::norm(frame_light.direction), 1.0, 1e-6);
  EXPECT_GT(frame_light.direction[2], 0) << "the lamp is in front of the object";
  const cv::Mat shaded_frame = w.live().lastFrame().clone(), shaded_shown = w.live().lastRepaintedFrame().clone();
  // then the copy: the selector switches the frames that follow
  child<QComboBox>(w, "liveLook")->setCurrentText("copy");
  const int seen_shaded = w.live().framesShown();
  ASSERT_TRUE(wait_for([&] {
    return w.live().framesShown() >= seen_shaded + 2 && w.live().lastPaintedLook() == veneer::repaint::Look::copy;
  }, 20000)) << w.status().lastMessage().toStdString();
  EXPECT_FALSE(w.live().lightDial().light().has_value()) << "the copy look estimates no light";
  const cv::Mat frame = w.live().lastFrame().clone(), shown = w.live().lastRepaintedFrame().clone();
  ASSERT_EQ(shown.size(), map.xy.size());
  ASSERT_EQ(shaded_shown.size(), map.xy.size());
  // The pictures are blended by default, and so are the live frames: each
  // mapped pixel the weighted sum of the frame (at the source's size) over
  // the blend's terms. The live repaint registers each frame to the stills
  // first (the object here stands still: about the identity, to a fraction
  // of a pixel) and gathers at the nearest pixel, so a pixel may differ a
  // little, on the object's edges more; a wrong lookup differs everywhere.
  const auto plan = w.session().result->blend;
  ASSERT_NE(plan, nullptr) << "blended by default";
  cv::Mat at_source;
  cv::resize(frame, at_source, w.session().result->source_size, 0, 0, cv::INTER_AREA);
  // Mean difference of `shown` from the map applied to `src` by hand.
  auto mean_difference_of = [&](const cv::Mat& shown, const cv::Mat& src, int* checked) {
    double sum = 0;
    for (size_t i = 0; i < plan->pixels.size(); ++i) {
      cv::Vec3f want(0, 0, 0);
      for (int t = plan->first[i]; t < plan->first[i + 1]; ++t) {
        const cv::Vec3b p = src.ptr<cv::Vec3b>(0)[plan->terms[t].source];
        want += plan->terms[t].weight * cv::Vec3f(p[0], p[1], p[2]);
      }
      const cv::Vec3b got = shown.ptr<cv::Vec3b>(0)[plan->pixels[i]];
      for (int c = 0; c < 3; ++c) sum += std::abs(got[c] - want[c]) / 3.0;
      ++*checked;
    }
    return *checked ? sum / *checked : 1e9;
  };
  auto mean_difference = [&](const cv::Mat& src, int* checked) { return mean_difference_of(shown, src, checked); };
  int checked = 0, checked_moved = 0;
  const double right = mean_difference(at_source, &checked);
  // The peer: the same lookup of the frame moved by 3 px, as a wrong registration would give.
  cv::Mat moved;
  cv::warpAffine(at_source, moved, cv::Matx23d(1, 0, 3, 0, 1, 2), at_source.size(), cv::INTER_LINEAR,
                 cv::BORDER_REPLICATE);
  const double wrong = mean_difference(moved, &checked_moved);
  EXPECT_GT(checked, 200);
  EXPECT_EQ(checked, mapped);
  EXPECT_LT(right, 0.5 * wrong) << "mean difference " << right << " levels; a lookup 3 px off: " << wrong;
  // The shaded frame is not its frame's copy: the destination's shading at the frame's light, not the source's.
  cv::Mat shaded_at_source;
  cv::resize(shaded_frame, shaded_at_source, w.session().result->source_size, 0, 0, cv::INTER_AREA);
  int checked_shaded = 0;
  const double shaded_vs_copy = mean_difference_of(shaded_shown, shaded_at_source, &checked_shaded);
  std::printf("live frame vs the copy by hand: copy look %.1f levels, shaded look %.1f (lookup 3 px off %.1f)\n",
              right, shaded_vs_copy, wrong);
  EXPECT_GT(shaded_vs_copy, 2 * right) << "the shaded look paints the copy";
  // (measured: 12 levels against 27; the registration of this 256x170
  // orange under the sweeping hand lamp is off by a few tenths of a pixel,
  // which the dimpled peel shows)
  EXPECT_NE(child<QLabel>(w, "liveStatus")->text().indexOf("tracked"), -1)
      << child<QLabel>(w, "liveStatus")->text().toStdString();
  child<QPushButton>(w, "liveToggle")->setChecked(false);

  // Screenshots of every view, for people to look at.
  w.showTab("Look");
  const QStringList shots_written = w.saveScreenshots(VENEER_SCREENSHOT_DIR);
  EXPECT_EQ(shots_written.size(), 3);
}

namespace {
// The window as the user sees it (1280x720), saved as <screenshots>/<stage>.png.
void save_stage(MainWindow& w, const QString& stage) {
  QDir().mkpath(VENEER_SCREENSHOT_DIR);
  QApplication::processEvents();
  const QString file = QString(VENEER_SCREENSHOT_DIR "/%1.png").arg(stage);
  EXPECT_TRUE(w.grab().save(file)) << file.toStdString();
}
}  // namespace

// Issue 28's one flow: from launch to a live repaint with only connect,
// capture source, capture destination. Everything between -- pulling both
// sets, assigning their roles, computing the map with the default settings,
// starting the live view -- happens by itself, told in one status line.
TEST(workflow, ConnectCaptureSourceCaptureDestinationRepaintsLive) {
  SimulatedRig rig;
  ASSERT_TRUE(rig.started()) << rig.log().toStdString();
  QTemporaryDir work;
  MainWindow w({QString(), QString(), QString(), QString(), work.path()});
  w.resize(1280, 720);
  w.show();
  ASSERT_TRUE(w.capture().autoFlow()) << "the flow is on by default";
  QStringList lines;  // every status line shown, sampled as the test waits
  auto seen = [&] {
    if (lines.isEmpty() || lines.back() != w.status().line()) lines << w.status().line();
  };
  save_stage(w, "workflow-1-launched");

  // connect: the address and token typed, Connect clicked
  child<QLineEdit>(w, "rigAddress")->setText(rig.endpoint());
  child<QLineEdit>(w, "tokenFile")->setText(rig.token_file());
  QTest::mouseClick(child<QPushButton>(w, "connect"), Qt::LeftButton);
  ASSERT_TRUE(wait_for([&] { return w.rig().isConnected(); }, 10000)) << w.status().lastMessage().toStdString();
  save_stage(w, "workflow-2-connected");

  // capture source: from the Capture panel
  QTest::mouseClick(child<QPushButton>(w, "captureSource"), Qt::LeftButton);
  ASSERT_TRUE(wait_for([&] { seen(); return w.session().src != nullptr; }, 60000))
      << w.status().lastMessage().toStdString();
  EXPECT_EQ(w.session().dst, nullptr);
  save_stage(w, "workflow-3-source-captured");

  // capture destination: from the Live tab's own button
  w.showTab("Live");
  QTest::mouseClick(child<QPushButton>(w, "liveCaptureDestination"), Qt::LeftButton);
  ASSERT_TRUE(wait_for([&] { seen(); return w.session().dst != nullptr; }, 60000))
      << w.status().lastMessage().toStdString();
  save_stage(w, "workflow-4-destination-captured");

  // the map, computed by itself with the default method
  ASSERT_TRUE(wait_for([&] { seen(); return w.session().result != nullptr && !w.transfer().computing(); }, 120000))
      << w.status().lastMessage().toStdString();
  EXPECT_EQ(w.session().src->set.role, veneer::io::Role::source);
  EXPECT_EQ(w.session().dst->set.role, veneer::io::Role::destination);
  EXPECT_EQ(w.session().result->match_options.method, veneer::match::Method::combined);
  cv::Mat xy[2];
  cv::split(w.session().result->map.xy, xy);
  EXPECT_GT(cv::countNonZero(xy[0] >= 0), 200) << "mapped pixels";
  save_stage(w, "workflow-5-map-computed");

  // live frames arrive and are repainted through that map
  ASSERT_TRUE(wait_for(
      [&] { seen(); return w.live().framesShown() >= 3 && !w.live().lastRepaintedFrame().empty(); }, 20000))
      << w.status().lastMessage().toStdString();
  EXPECT_EQ(w.live().lastRepaintedFrame().size(), w.session().result->map.xy.size());
  EXPECT_TRUE(child<QPushButton>(w, "liveToggle")->isChecked());
  seen();
  EXPECT_TRUE(w.status().line().contains("live repaint")) << w.status().line().toStdString();
  save_stage(w, "workflow-6-live");

  // the line told each step, and never a finished-looking "0 s left"
  const QString all = lines.join("\n");
  for (const char* step : {"capturing the source", "pulling", "loading", "computing the map", "live repaint"})
    EXPECT_TRUE(all.contains(step)) << step << " not in:\n" << all.toStdString();
  EXPECT_FALSE(all.contains(" 0 s left")) << all.toStdString();
  child<QPushButton>(w, "liveToggle")->setChecked(false);
}

// Deleting a rig capture asks first, naming the set and its date; the set
// goes into the rig's trash and Undo brings it back.
TEST(Viewer, DeletingARigSetAsksAndUndoRestoresIt) {
  SimulatedRig rig;
  ASSERT_TRUE(rig.started()) << rig.log().toStdString();
  QTemporaryDir work;
  MainWindow w({QString(), QString(), QString(), QString(), work.path()});
  w.show();
  w.capture().setAutoFlow(false);
  w.rigPanel().connectToRig(rig.endpoint(), rig.token_file());
  ASSERT_TRUE(wait_for([&] { return w.rig().isConnected(); }, 10000)) << w.status().lastMessage().toStdString();
  QTest::mouseClick(child<QPushButton>(w, "pressButton"), Qt::LeftButton);
  auto* tree = child<QTreeWidget>(w, "sets");
  QTreeWidgetItem *on_rig = tree->topLevelItem(0), *trash = tree->topLevelItem(2);
  ASSERT_TRUE(wait_for([&] { return on_rig->childCount() == 1; }, 60000)) << w.status().lastMessage().toStdString();
  const QString id = on_rig->child(0)->text(0), date = on_rig->child(0)->text(3);
  EXPECT_TRUE(date.startsWith(QDateTime::currentDateTimeUtc().date().toString(Qt::ISODate))) << date.toStdString();
  // a second viewer on the same rig sees the delete and the undo without listing again
  QTemporaryDir other_work;
  MainWindow other({QString(), QString(), QString(), QString(), other_work.path()});
  other.capture().setAutoFlow(false);
  other.rigPanel().connectToRig(rig.endpoint(), rig.token_file());
  ASSERT_TRUE(wait_for([&] { return other.rig().isConnected(); }, 10000)) << other.status().lastMessage().toStdString();
  QTreeWidgetItem* other_rig = child<QTreeWidget>(other, "sets")->topLevelItem(0);
  ASSERT_TRUE(wait_for([&] { return other_rig->childCount() == 1; }, 10000));

  // asked; Cancel keeps it
  auto ask = [&]() -> QMessageBox* {
    select_item(tree, on_rig->child(0));
    QTest::mouseClick(child<QPushButton>(w, "deleteSet"), Qt::LeftButton);
    QMessageBox* box = nullptr;
    wait_for([&] { return (box = w.findChild<QMessageBox*>("confirmDelete")) && box->isVisible(); }, 5000);
    return box;
  };
  QMessageBox* box = ask();
  ASSERT_NE(box, nullptr) << "delete asks";
  EXPECT_TRUE(box->text().contains(id)) << box->text().toStdString();
  EXPECT_TRUE(box->text().contains(date)) << box->text().toStdString();
  QTest::mouseClick(box->button(QMessageBox::Cancel), Qt::LeftButton);
  QTest::qWait(300);
  EXPECT_EQ(on_rig->childCount(), 1) << "Cancel deletes nothing";
  EXPECT_FALSE(child<QPushButton>(w, "undoDelete")->isVisible());

  // Yes: into the trash, listed there
  box = ask();
  ASSERT_NE(box, nullptr);
  QTest::mouseClick(box->button(QMessageBox::Yes), Qt::LeftButton);
  ASSERT_TRUE(wait_for([&] { return on_rig->childCount() == 0 && trash->childCount() == 1; }, 10000))
      << w.status().lastMessage().toStdString();
  EXPECT_EQ(trash->child(0)->text(0), id);
  EXPECT_TRUE(wait_for([&] { return other_rig->childCount() == 0; }, 10000)) << "the other viewer saw the delete";
  auto* undo = child<QPushButton>(w, "undoDelete");
  ASSERT_TRUE(undo->isVisible());

  // Undo: back on the rig, whole (it pulls)
  QTest::mouseClick(undo, Qt::LeftButton);
  ASSERT_TRUE(wait_for([&] { return on_rig->childCount() == 1 && trash->childCount() == 0; }, 10000))
      << w.status().lastMessage().toStdString();
  EXPECT_EQ(on_rig->child(0)->text(0), id);
  EXPECT_FALSE(undo->isVisible());
  ASSERT_TRUE(wait_for([&] { return other_rig->childCount() == 1; }, 10000)) << "the other viewer saw it come back";
  EXPECT_EQ(other_rig->child(0)->text(0), id);
  select_item(tree, on_rig->child(0));
  QTest::mouseClick(child<QPushButton>(w, "pullSet"), Qt::LeftButton);
  ASSERT_TRUE(wait_for([&] { return tree->topLevelItem(1)->childCount() == 1; }, 30000))
      << w.status().lastMessage().toStdString();
}

// The local library -- pulled or opened sets with their roles, dates and
// thumbnails, and the maps computed from them -- is there after a restart.
TEST(Viewer, TheLibrarySurvivesARestart) {
  QTemporaryDir dir;
  {
    auto window = open_pair(dir);
    ASSERT_TRUE(window);
    child<QComboBox>(*window, "method")->setCurrentText("coherent");
    ASSERT_TRUE(compute_and_wait(*window));
    auto* maps = child<QTreeWidget>(*window, "sets")->topLevelItem(3);
    ASSERT_TRUE(wait_for([&] { return maps->childCount() == 1; }, 10000))
        << window->status().lastMessage().toStdString();
  }
  MainWindow w({QString(), QString(), QString(), QString(), dir.path()});
  auto* tree = child<QTreeWidget>(w, "sets");
  QTreeWidgetItem *local = tree->topLevelItem(1), *maps = tree->topLevelItem(3);
  ASSERT_EQ(local->childCount(), 2);
  EXPECT_EQ(local->child(0)->text(0), "bull");
  EXPECT_EQ(local->child(0)->text(1), "destination");
  EXPECT_EQ(local->child(1)->text(1), "source");
  for (int i = 0; i < 2; ++i) {
    EXPECT_FALSE(local->child(i)->text(3).isEmpty()) << "dated";
    EXPECT_FALSE(local->child(i)->icon(0).isNull()) << "a thumbnail";
  }
  ASSERT_EQ(maps->childCount(), 1);
  EXPECT_EQ(maps->child(0)->text(0), "bull ← orange");
  EXPECT_EQ(maps->child(0)->text(2), "coherent");
  EXPECT_TRUE(QFileInfo::exists(maps->child(0)->data(0, Qt::UserRole).toString() + "/map.pfm"));
  // and a library row is used as a set: loaded from its folder
  select_item(tree, local->child(1));
  QTest::mouseClick(child<QPushButton>(w, "useSource"), Qt::LeftButton);
  ASSERT_TRUE(wait_for([&] { return w.session().src != nullptr; }, 20000)) << w.status().lastMessage().toStdString();
}

namespace {
// Destination pixels the map gives a source pixel, within `inside`.
int mapped_in(const veneer::match::Map& map, const cv::Rect& inside) {
  cv::Mat xy[2];
  cv::split(map.xy, xy);
  return cv::countNonZero(xy[0](inside) >= 0);
}
}  // namespace

// A map kept in the library is shown again after a restart without matching:
// its sets load in their roles with the options it was computed with, and the
// result is painted through the stored map. The stored map is altered on disk
// first, so a map matched again would differ from it. A set that is gone is
// named in one message.
TEST(Viewer, ALibraryMapReopensAfterARestartWithoutMatchingAgain) {
  QTemporaryDir dir;
  QString map_folder, dst, src;
  {
    auto window = open_pair(dir);
    ASSERT_TRUE(window);
    dst = window->session().dst->folder;
    src = window->session().src->folder;
    child<QComboBox>(*window, "method")->setCurrentText("coherent");
    child<QSpinBox>(*window, "blend")->setValue(3);
    ASSERT_TRUE(compute_and_wait(*window));
    auto* maps = child<QTreeWidget>(*window, "sets")->topLevelItem(3);
    ASSERT_TRUE(wait_for([&] { return maps->childCount() == 1; }, 10000))
        << window->status().lastMessage().toStdString();
    map_folder = maps->child(0)->data(0, Qt::UserRole).toString();
  }
  // the stored map, altered: its top half unmapped
  const std::string pfm = (map_folder + "/map.pfm").toStdString();
  auto stored = veneer::match::read_map(pfm);
  ASSERT_TRUE(stored) << stored.message();
  const cv::Rect top(0, 0, stored->xy.cols, stored->xy.rows / 2);
  const int mapped_before = mapped_in(*stored, top);
  ASSERT_GT(mapped_before, 100) << "the bull reaches into the top half";
  stored->xy(top).setTo(cv::Scalar::all(-1));
  ASSERT_TRUE(veneer::match::write_map(pfm, *stored).ok());

  {
    MainWindow w({QString(), QString(), QString(), QString(), dir.path()});
    w.show();
    auto* tree = child<QTreeWidget>(w, "sets");
    QTreeWidgetItem* maps = tree->topLevelItem(3);
    ASSERT_EQ(maps->childCount(), 1);
    EXPECT_EQ(child<QComboBox>(w, "method")->currentText(), "combined") << "the default before reopening";
    select_item(tree, maps->child(0));
    QTest::mouseClick(child<QPushButton>(w, "openMap"), Qt::LeftButton);
    ASSERT_TRUE(wait_for([&] { return w.session().result != nullptr && !w.transfer().computing(); }, 60000))
        << w.status().lastMessage().toStdString();
    ASSERT_TRUE(w.session().dst && w.session().src);
    EXPECT_EQ(w.session().dst->folder, dst);
    EXPECT_EQ(w.session().src->folder, src);
    EXPECT_TRUE(w.session().result->map_given) << "repainted through the stored map";
    EXPECT_EQ(w.session().result->match_seconds, 0.0);
    EXPECT_EQ(mapped_in(w.session().result->map, top), 0) << "the stored (altered) map, not one matched again";
    EXPECT_EQ(cv::norm(w.session().result->map.xy, stored->xy, cv::NORM_INF), 0.0);
    EXPECT_EQ(w.session().result->match_options.method, veneer::match::Method::coherent);
    EXPECT_EQ(child<QComboBox>(w, "method")->currentText(), "coherent") << "the options it was computed with";
    EXPECT_EQ(child<QSpinBox>(w, "blend")->value(), 3);
    EXPECT_TRUE(w.status().lastMessage().contains("reopened")) << w.status().lastMessage().toStdString();
    w.resize(1280, 720);
    save_stage(w, "library-map-reopened");
    QTest::qWait(300);
    EXPECT_EQ(maps->childCount(), 1) << "a reopened map is not stored twice";
  }

  // the source set gone: one message naming it, nothing loaded
  ASSERT_TRUE(QDir(src).removeRecursively());
  MainWindow w({QString(), QString(), QString(), QString(), dir.path()});
  auto* maps = child<QTreeWidget>(w, "sets")->topLevelItem(3);
  ASSERT_EQ(maps->childCount(), 1);
  EXPECT_FALSE(w.mapLibrary().open(maps->child(0)->data(0, Qt::UserRole).toString()));
  EXPECT_TRUE(w.status().lastMessage().contains("source set") && w.status().lastMessage().contains(src) &&
              w.status().lastMessage().contains("gone"))
      << w.status().lastMessage().toStdString();
  QTest::qWait(200);
  EXPECT_EQ(w.session().dst, nullptr);
  EXPECT_EQ(w.session().result, nullptr);
}

namespace {
int lamp_boxes(MainWindow& w) {
  int n = 0;
  for (auto* b : w.findChildren<QCheckBox*>())
    if (b->objectName().startsWith("lamp")) ++n;
  return n;
}
bool wheel(QWidget* target) {
  QWheelEvent e(QPointF(5, 5), target->mapToGlobal(QPointF(5, 5)), QPoint(), QPoint(0, 120), Qt::NoButton,
                Qt::NoModifier, Qt::NoScrollPhase, false);
  QApplication::sendEvent(target, &e);
  return e.isAccepted();
}
}  // namespace

// Expert parameters sit in a closed "Advanced" fold with presets; the wheel
// changes only a field with focus; the lamp boxes follow the set's manifest.
TEST(Viewer, AdvancedFoldPresetsWheelFocusAndLampsFromTheManifest) {
  QTemporaryDir dir;
  auto window = open_pair(dir);
  ASSERT_TRUE(window);
  MainWindow& w = *window;
  w.resize(1280, 720);
  w.show();
  ASSERT_TRUE(QTest::qWaitForWindowExposed(&w));
  auto* advanced = child<QWidget>(w, "advanced");
  EXPECT_FALSE(advanced->isVisible()) << "closed at first";
  EXPECT_EQ(child<QComboBox>(w, "method")->currentText(), "combined") << "the CLI's default";
  auto* side = w.findChild<QScrollArea*>();
  side->ensureWidgetVisible(child<QWidget>(w, "transferStatus"));
  save_stage(w, "advanced-closed");
  QTest::mouseClick(child<QToolButton>(w, "advancedToggle"), Qt::LeftButton);
  EXPECT_TRUE(advanced->isVisible());
  QApplication::processEvents();
  side->ensureWidgetVisible(child<QWidget>(w, "preset"), 50, 10);
  save_stage(w, "advanced-open");

  auto* preset = child<QComboBox>(w, "preset");
  preset->setCurrentIndex(1);
  EXPECT_EQ(child<QComboBox>(w, "method")->currentText(), "coherent");
  preset->setCurrentIndex(2);
  EXPECT_EQ(child<QComboBox>(w, "method")->currentText(), "linear");
  EXPECT_EQ(child<QComboBox>(w, "patch")->currentText(), "3");
  EXPECT_FALSE(child<QCheckBox>(w, "fast")->isChecked());
  child<QComboBox>(w, "patch")->setCurrentText("5");
  EXPECT_EQ(preset->currentText(), "custom") << "a setting changed by hand";

  // the wheel passes over a field without focus, and changes it with focus
  auto* candidates = child<QSpinBox>(w, "candidates");
  const int before = candidates->value();
  EXPECT_FALSE(wheel(candidates));
  EXPECT_EQ(candidates->value(), before);
  w.activateWindow();
  candidates->setFocus();
  if (candidates->hasFocus()) {
    wheel(candidates);
    EXPECT_NE(candidates->value(), before);
  }

  // one lamp box per light of the set's manifest
  EXPECT_EQ(lamp_boxes(w), static_cast<int>(w.session().dst->set.lights.size()));
  veneer::io::ImageSet three = w.session().dst->set;
  three.images.resize(3);
  three.lights.resize(3);
  const QString folder = dir.path() + "/bull3";
  ASSERT_TRUE(veneer::io::write_set(three, folder.toStdString()).ok());
  ASSERT_TRUE(w.flow().loadLocalSet(folder, veneer::io::Role::destination)) << w.status().lastMessage().toStdString();
  EXPECT_EQ(lamp_boxes(w), 3);
}

// Every view mode shows a picture; the histogram carries the manifest's
// exposure; a snapshot writes the view shown as a PNG (and refuses another name).
TEST(Viewer, ViewModesHistogramExposureAndSnapshot) {
  QTemporaryDir dir;
  auto window = open_pair(dir);
  ASSERT_TRUE(window);
  MainWindow& w = *window;
  w.resize(1280, 720);
  w.show();
  child<QComboBox>(w, "method")->setCurrentText("coherent");
  ASSERT_TRUE(compute_and_wait(w));
  ASSERT_TRUE(wait_for([&] { return w.session().dst->normals && w.session().src->normals; }, 30000));
  // the simulator records 1/30 s at exposure 1, f/8, ISO 100
  EXPECT_TRUE(w.look().exposureText().contains("1/30 s")) << w.look().exposureText().toStdString();
  EXPECT_TRUE(w.look().exposureText().contains("f/8")) << w.look().exposureText().toStdString();
  EXPECT_TRUE(w.look().exposureText().contains("ISO 100")) << w.look().exposureText().toStdString();
  EXPECT_FALSE(child<QLabel>(w, "histogram")->pixmap().isNull());
  auto* look = child<QComboBox>(w, "lookWhat");
  for (int i = 0; i < look->count(); ++i) {
    const QString mode = look->itemText(i);
    ASSERT_TRUE(w.showLook(mode));
    QString slug = mode;
    slug.replace(' ', '-');
    save_stage(w, "view-" + slug);
  }
  ASSERT_TRUE(w.showLook("specular enhancement"));
  const QString file = dir.path() + "/snap.png";
  EXPECT_EQ(w.snapshotTo(file), file) << w.status().lastMessage().toStdString();
  QImage shot(file);
  ASSERT_FALSE(shot.isNull());
  EXPECT_GT(shot.width(), 600);
  EXPECT_TRUE(w.snapshotTo(dir.path() + "/snap.jpg").isEmpty());
  EXPECT_TRUE(w.status().lastMessage().contains("snap.jpg")) << w.status().lastMessage().toStdString();
  EXPECT_FALSE(QFileInfo::exists(dir.path() + "/snap.jpg"));
}

// Segmentation by hand: a rectangle on the destination and a brush on the
// source each change the map -- nothing is mapped outside the rectangle and
// nothing is taken from the brushed-out disc -- and show as outlines.
TEST(Viewer, HandRectangleAndBrushMasksChangeTheMap) {
  QTemporaryDir dir;
  auto window = open_pair(dir);
  ASSERT_TRUE(window);
  MainWindow& w = *window;
  child<QComboBox>(w, "method")->setCurrentText("coherent");
  ASSERT_TRUE(compute_and_wait(w));
  auto mapped = [&](const cv::Rect& inside) { return mapped_in(w.session().result->map, inside); };
  const cv::Size size = w.session().result->map.xy.size();
  const cv::Rect left(0, 0, size.width / 2, size.height), right(size.width / 2, 0, size.width - size.width / 2, size.height);
  const int left_before = mapped(left), right_before = mapped(right);
  ASSERT_GT(left_before, 100);
  ASSERT_GT(right_before, 100);

  // the rectangle: the right half of the destination only
  const auto* first = w.session().result.get();
  w.segmentation().setHandRect(veneer::io::Role::destination, QRect(right.x, right.y, right.width, right.height));
  ASSERT_TRUE(wait_for(
      [&] { return !w.transfer().computing() && w.session().result && w.session().result.get() != first; }, 60000))
      << w.status().lastMessage().toStdString();
  ASSERT_TRUE(wait_for([&] { return !w.transfer().computing(); }, 60000));
  EXPECT_EQ(mapped(left), 0) << "outside the rectangle nothing is the object";
  EXPECT_GT(mapped(right), right_before / 2);

  // the brush: a disc at the source's object centre taken out
  cv::Mat sm = w.session().src->hand_mask.empty() ? w.session().src->normals->mask : w.session().src->hand_mask;
  const cv::Moments m = cv::moments(sm, true);
  const QPoint centre(static_cast<int>(m.m10 / m.m00), static_cast<int>(m.m01 / m.m00));
  auto from_disc = [&] {
    int n = 0;
    const cv::Mat& xy = w.session().result->map.xy;
    for (int y = 0; y < xy.rows; ++y)
      for (int x = 0; x < xy.cols; ++x) {
        const cv::Vec2f v = xy.at<cv::Vec2f>(y, x);
        if (v[0] >= 0 && std::hypot(v[0] - centre.x(), v[1] - centre.y()) < 7) ++n;
      }
    return n;
  };
  ASSERT_GT(from_disc(), 0) << "the map takes from the centre before";
  const auto* second = w.session().result.get();
  w.segmentation().brushHandMask(veneer::io::Role::source, centre, false, 10);
  ASSERT_TRUE(wait_for(
      [&] { return !w.transfer().computing() && w.session().result && w.session().result.get() != second; }, 60000))
      << w.status().lastMessage().toStdString();
  ASSERT_TRUE(wait_for([&] { return !w.transfer().computing(); }, 60000));
  EXPECT_EQ(from_disc(), 0) << "nothing comes from the brushed-out disc";
  EXPECT_FALSE(w.session().src->hand_mask.empty());
  // and a brush adds back
  w.segmentation().brushHandMask(veneer::io::Role::source, centre, true, 10);
  EXPECT_EQ(w.session().src->hand_mask.at<uchar>(centre.y(), centre.x()), 255);
  ASSERT_TRUE(wait_for([&] { return !w.transfer().computing(); }, 60000));
  // exported for the CLI, as drawn
  const QStringList files = w.segmentation().exportMasksTo(dir.path());
  ASSERT_EQ(files.size(), 2);
  cv::Mat back = cv::imread(files[0].toStdString(), cv::IMREAD_GRAYSCALE);
  EXPECT_EQ(cv::norm(back, w.session().dst->hand_mask, cv::NORM_INF), 0.0);
}

// The CLI reuses a mask drawn by hand: `veneer transfer --dst-mask` maps
// nothing outside it; a mask of another size is refused naming the file.
TEST(Viewer, CliTransferTakesMaskFiles) {
  QTemporaryDir dir;
  QString dst, src;
  write_pair(dir.path(), dst, src);
  auto d = veneer::io::read_set(dst.toStdString());
  ASSERT_TRUE(d);
  auto seg = veneer::ps::segment(*d);
  ASSERT_TRUE(seg);
  cv::Mat mask = seg->mask.clone();
  mask(cv::Rect(0, 0, mask.cols / 2, mask.rows)).setTo(0);  // the right half of the object only
  const QString mask_file = dir.path() + "/dst-mask.png";
  ASSERT_TRUE(cv::imwrite(mask_file.toStdString(), mask));
  auto run = [&](const QStringList& extra, QString& out) {
    QProcess p;
    p.setProcessChannelMode(QProcess::MergedChannels);
    p.start(VENEER_BIN_DIR "/veneer", QStringList{"transfer", "--dst", dst, "--src", src, "--method", "coherent"} + extra);
    p.waitForFinished(120000);
    out = QString::fromUtf8(p.readAll());
    return p.exitCode();
  };
  QString out;
  ASSERT_EQ(run({"--out", dir.path() + "/plain"}, out), 0) << out.toStdString();
  ASSERT_EQ(run({"--out", dir.path() + "/masked", "--dst-mask", mask_file}, out), 0) << out.toStdString();
  auto plain = veneer::match::read_map((dir.path() + "/plain/map.pfm").toStdString());
  auto masked = veneer::match::read_map((dir.path() + "/masked/map.pfm").toStdString());
  ASSERT_TRUE(plain && masked);
  const cv::Rect left(0, 0, mask.cols / 2, mask.rows), right(mask.cols / 2, 0, mask.cols - mask.cols / 2, mask.rows);
  EXPECT_GT(mapped_in(*plain, left), 100);
  EXPECT_EQ(mapped_in(*masked, left), 0);
  EXPECT_GT(mapped_in(*masked, right), 100);
  // a mask of another size
  cv::Mat small(10, 10, CV_8UC1, cv::Scalar(255));
  ASSERT_TRUE(cv::imwrite((dir.path() + "/small.png").toStdString(), small));
  EXPECT_EQ(run({"--out", dir.path() + "/bad", "--src-mask", dir.path() + "/small.png"}, out), 2) << out.toStdString();
  EXPECT_TRUE(out.contains("--src-mask") && out.contains("small.png") && out.contains("10x10")) << out.toStdString();
  EXPECT_FALSE(QFileInfo::exists(dir.path() + "/bad/map.pfm"));
}

TEST(Viewer, CancelledComputationLeavesUiUsable) {
  QTemporaryDir dir;
  auto window = open_pair(dir);
  ASSERT_TRUE(window);
  MainWindow& w = *window;
  // The faithful exhaustive search with 7x7 patches is slow enough to cancel.
  child<QComboBox>(w, "method")->setCurrentText("linear");
  child<QComboBox>(w, "patch")->setCurrentText("7");
  child<QCheckBox>(w, "fast")->setChecked(false);
  QTest::mouseClick(child<QPushButton>(w, "compute"), Qt::LeftButton);
  ASSERT_TRUE(w.transfer().computing());
  QTest::mouseClick(child<QPushButton>(w, "cancelTransfer"), Qt::LeftButton);
  ASSERT_TRUE(wait_for([&] { return !w.transfer().computing(); }, 60000));
  EXPECT_EQ(w.session().result, nullptr);
  EXPECT_TRUE(child<QLabel>(w, "transferStatus")->text().contains("cancel"));
  EXPECT_TRUE(child<QPushButton>(w, "compute")->isEnabled());
  // Still usable: a fast transfer now completes.
  child<QComboBox>(w, "method")->setCurrentText("coherent");
  child<QComboBox>(w, "patch")->setCurrentText("1");
  child<QCheckBox>(w, "fast")->setChecked(true);
  ASSERT_TRUE(compute_and_wait(w));
  ASSERT_TRUE(w.session().result->quality.has_value());
  EXPECT_GT(w.session().result->quality->coverage, 0.9);
}

// Exports cancelled leave nothing behind: not the results folder, not its
// temporary sibling, not the video or its temporary, not the web page or its. The export is held in
// the job pool's queue behind a gate until the cancel is in, so the cancel
// always comes before the first file (core/Transfer.WritingStopsBetweenFiles
// WhenCancelled shows the stop between files); uncancelled, the same exports
// are written whole.
TEST(Viewer, CancelledExportsLeaveNoHalfWrittenFile) {
  QTemporaryDir dir;
  auto window = open_pair(dir);
  ASSERT_TRUE(window);
  MainWindow& w = *window;
  child<QComboBox>(w, "method")->setCurrentText("coherent");
  ASSERT_TRUE(compute_and_wait(w));
  QThreadPool* pool = veneer::app::job_pool();
  pool->waitForDone();  // the normals' background solve
  const int threads = pool->maxThreadCount();
  const QString results = dir.path() + "/results", video = dir.path() + "/sweep.avi";
  auto held_then_cancelled = [&](const std::function<void()>& start) {
    pool->setMaxThreadCount(1);
    QSemaphore gate;
    pool->start([&gate] { gate.acquire(); });
    start();
    EXPECT_TRUE(w.exports().exporting());
    w.cancelStep();
    gate.release();
    EXPECT_TRUE(wait_for([&] { return !w.exports().exporting(); }, 30000));
    pool->setMaxThreadCount(threads);
  };
  held_then_cancelled([&] { w.exports().exportResultsTo(results); });
  EXPECT_TRUE(w.status().lastMessage().contains("cancelled")) << w.status().lastMessage().toStdString();
  EXPECT_TRUE(QDir(results).isEmpty()) << "nothing moved into the folder";
  EXPECT_FALSE(QFileInfo::exists(results + ".part")) << "the temporary sibling removed";
  held_then_cancelled([&] { w.exports().exportRelightVideoTo(video); });
  EXPECT_TRUE(w.status().lastMessage().contains("cancelled")) << w.status().lastMessage().toStdString();
  EXPECT_EQ(QDir(dir.path()).entryList({"*.avi", ".*.avi"}, QDir::Files | QDir::Hidden), QStringList())
      << "no video, no temporary";

  w.exports().exportResultsTo(results);
  ASSERT_TRUE(wait_for([&] { return !w.exports().exporting(); }, 30000));
  EXPECT_TRUE(w.status().lastMessage().contains("results written")) << w.status().lastMessage().toStdString();
  EXPECT_TRUE(QFileInfo::exists(results + "/metrics.json"));
  EXPECT_TRUE(QFileInfo::exists(results + "/result_median.png"));
  EXPECT_FALSE(QFileInfo::exists(results + ".part"));
  w.exports().exportRelightVideoTo(video);
  ASSERT_TRUE(wait_for([&] { return !w.exports().exporting(); }, 60000));
  EXPECT_EQ(QDir(dir.path()).entryList({"*.avi", ".*.avi"}, QDir::Files | QDir::Hidden), QStringList{"sweep.avi"});
  EXPECT_GT(QFileInfo(video).size(), 1000);

  // the web page of the look (issue 50): cancelled, no folder and no temporary; else the page whole
  const QString web = dir.path() + "/web";
  held_then_cancelled([&] { w.exports().exportWebPageTo(web); });
  EXPECT_TRUE(w.status().lastMessage().contains("cancelled")) << w.status().lastMessage().toStdString();
  EXPECT_FALSE(QFileInfo::exists(web));
  EXPECT_EQ(QDir(dir.path()).entryList({".web.*"}, QDir::Dirs | QDir::Hidden), QStringList()) << "no temporary";
  w.exports().exportWebPageTo(web);
  ASSERT_TRUE(wait_for([&] { return !w.exports().exporting(); }, 60000));
  EXPECT_TRUE(w.status().lastMessage().contains("web page written")) << w.status().lastMessage().toStdString();
  for (const char* f : {"index.html", "look.js", "info.json", "still.jpg", "plane_0.jpg"})
    EXPECT_TRUE(QFileInfo::exists(web + "/" + f)) << f;
  EXPECT_EQ(QDir(dir.path()).entryList({".web.*"}, QDir::Dirs | QDir::Hidden), QStringList()) << "no temporary";
}

// A set loaded in the background comes with the picture the views show and
// its histogram made off the GUI thread: the view shows the loader's image
// itself (the same pixels, not a conversion made on the GUI thread), and the
// histogram is the median picture's.
TEST(Viewer, ALoadedSetsPictureIsMadeByTheLoader) {
  QTemporaryDir dir;
  QString dst, src;
  write_pair(dir.path(), dst, src);
  MainWindow w({QString(), QString(), QString(), QString(), dir.path()});
  w.show();
  w.capture().setAutoFlow(false);
  w.flow().loadSetInBackground(dst, veneer::io::Role::destination);
  ASSERT_TRUE(wait_for([&] { return w.session().dst != nullptr && w.session().loads_running == 0; }, 20000))
      << w.status().lastMessage().toStdString();
  const veneer::app::LoadedSet* d = w.session().dst.get();
  ASSERT_FALSE(d->median_image.isNull());
  EXPECT_EQ(d->median_image.size(), QSize(d->set.size.width, d->set.size.height));
  int showing = 0;
  for (auto* view : w.findChildren<veneer::app::ImageView*>())
    showing += view->image().cacheKey() == d->median_image.cacheKey();
  EXPECT_EQ(showing, 1) << "the destination view shows the loader's image";
  ASSERT_FALSE(d->histogram.empty());
  EXPECT_EQ(cv::sum(d->histogram)[0], double(d->set.size.area())) << "every pixel counted once";
  // the picture is the median tonemapped: a pixel checked through the QImage
  const cv::Vec3b bgr = d->median_picture.at<cv::Vec3b>(85, 128);
  EXPECT_EQ(d->median_image.pixel(128, 85), qRgb(bgr[2], bgr[1], bgr[0]));
}

// Issue 43: the first use asks to compare the fingerprint (a "no" refuses the
// rig, a "yes" pins it in the known-rigs file); a changed certificate is
// refused with both fingerprints named, without asking.
TEST(Viewer, TheRigIsPinnedAtFirstUseAndAChangedCertificateRefused) {
  QTemporaryDir dir;
  SimulatedRig rig;
  ASSERT_TRUE(rig.started()) << rig.log().toStdString();
  auto fp = veneer::tls::fingerprint_of_cert_file((rig.store() + ".tls/cert.pem").toStdString());
  ASSERT_TRUE(fp) << fp.message();
  MainWindow w({QString(), QString(), QString(), QString(), dir.path()});
  const QString known = dir.path() + "/known_rigs";
  w.rig().setKnownRigsFile(known);
  w.rig().setAutoReconnect(false);
  QStringList asked;
  bool answer = false;
  w.rig().setPinAsker([&](const QString& rig_name, const QString& seen) {
    asked << rig_name + " " + seen;
    return answer;
  });
  w.rigPanel().connectToRig(rig.endpoint(), rig.token_file());
  ASSERT_TRUE(wait_for([&] { return w.status().lastMessage().contains("cannot connect"); }, 10000))
      << w.status().lastMessage().toStdString();
  EXPECT_TRUE(w.status().lastMessage().contains("not accepted")) << w.status().lastMessage().toStdString();
  ASSERT_EQ(asked.size(), 1);
  EXPECT_EQ(asked[0], rig.endpoint() + " " + QString::fromStdString(*fp));
  EXPECT_FALSE(QFile::exists(known));

  answer = true;
  w.rigPanel().connectToRig(rig.endpoint(), rig.token_file());
  ASSERT_TRUE(wait_for([&] { return w.rig().isConnected(); }, 10000)) << w.status().lastMessage().toStdString();
  EXPECT_EQ(asked.size(), 2);
  EXPECT_EQ(w.rig().fingerprint().toStdString(), *fp);
  auto pinned = veneer::tls::known_fingerprint(known.toStdString(), rig.endpoint().toStdString());
  ASSERT_TRUE(pinned) << pinned.message();
  EXPECT_EQ(*pinned, *fp);

  // Known now: connecting again asks nothing.
  w.rig().disconnectFromRig();
  w.rigPanel().connectToRig(rig.endpoint(), rig.token_file());
  ASSERT_TRUE(wait_for([&] { return w.rig().isConnected(); }, 10000)) << w.status().lastMessage().toStdString();
  EXPECT_EQ(asked.size(), 2);

  // Another certificate than the pinned one (as a rig impersonated on the LAN would show).
  w.rig().disconnectFromRig();
  const std::string other = "AA:BB:CC:DD:EE:FF:00:11:22:33:44:55:66:77:88:99:AA:BB:CC:DD:EE:FF:00:11:22:33:44:55:66:77:88:99";
  ASSERT_TRUE(veneer::tls::remember_fingerprint(known.toStdString(), rig.endpoint().toStdString(), other).ok());
  w.rigPanel().connectToRig(rig.endpoint(), rig.token_file());
  ASSERT_TRUE(wait_for([&] { return w.status().lastMessage().contains("cannot connect"); }, 10000))
      << w.status().lastMessage().toStdString();
  const std::string msg = w.status().lastMessage().toStdString();
  EXPECT_NE(msg.find("not the pinned one"), std::string::npos) << msg;
  EXPECT_NE(msg.find(other), std::string::npos) << msg;
  EXPECT_NE(msg.find(*fp), std::string::npos) << msg;
  EXPECT_EQ(asked.size(), 2);
  EXPECT_FALSE(w.rig().isConnected());
}

TEST(Viewer, BadInputGivesClearMessages) {
  QTemporaryDir dir;
  MainWindow w({QString(), QString(), QString(), QString(), dir.path()});
  // A rig that is not there.
  QFile token(dir.path() + "/token");
  ASSERT_TRUE(token.open(QIODevice::WriteOnly));
  token.write("0123456789abcdef0123456789abcdef\n");
  token.close();
  w.rig().setAutoReconnect(false);
  w.rigPanel().connectToRig(QString("127.0.0.1:%1").arg(free_port()), token.fileName());
  ASSERT_TRUE(wait_for([&] { return w.status().lastMessage().contains("cannot connect"); }, 10000))
      << w.status().lastMessage().toStdString();
  EXPECT_FALSE(w.rig().isConnected());

  // A wrong token.
  SimulatedRig rig;
  ASSERT_TRUE(rig.started());
  w.rigPanel().connectToRig(rig.endpoint(), token.fileName());
  ASSERT_TRUE(wait_for([&] { return w.status().lastMessage().contains("cannot connect"); }, 10000))
      << w.status().lastMessage().toStdString();
  EXPECT_TRUE(w.status().lastMessage().contains("token", Qt::CaseInsensitive))
      << w.status().lastMessage().toStdString();
  EXPECT_FALSE(w.rig().isConnected());

  // A missing token file.
  w.rigPanel().connectToRig(rig.endpoint(), dir.path() + "/no-such-token");
  EXPECT_TRUE(w.status().lastMessage().contains("no-such-token")) << w.status().lastMessage().toStdString();

  // A folder that is not a set.
  QDir(dir.path()).mkpath("not-a-set");
  EXPECT_FALSE(w.flow().loadLocalSet(dir.path() + "/not-a-set", veneer::io::Role::destination));
  EXPECT_TRUE(w.status().lastMessage().contains("not-a-set")) << w.status().lastMessage().toStdString();
  EXPECT_EQ(w.session().dst, nullptr);

  // Transfer without sets.
  w.transfer().startTransfer();
  EXPECT_FALSE(w.transfer().computing());
  EXPECT_TRUE(w.status().lastMessage().contains("load a destination"));
}


// After a first Compute, changing a matching option recomputes the map alone
// (normals and masks kept), as a slider is dragged: several changes while one
// runs end in one run with the latest value.
TEST(Viewer, MatchingOptionChangesRecomputeTheMap) {
  QTemporaryDir dir;
  auto window = open_pair(dir);
  ASSERT_TRUE(window);
  MainWindow& w = *window;
  child<QComboBox>(w, "method")->setCurrentText("coherent");
  EXPECT_FALSE(w.transfer().computing());  // nothing shown yet: no recomputation
  ASSERT_TRUE(compute_and_wait(w));
  const cv::Mat first = w.session().result->map.xy.clone();
  EXPECT_EQ(w.transfer().mapOnlyRuns(), 0);

  auto* thr = child<QDoubleSpinBox>(w, "coherentThreshold");
  for (double t : {0.15, 0.2, 0.3}) thr->setValue(t);  // dragged
  ASSERT_TRUE(wait_for(
      [&] { return !w.transfer().computing() && w.session().result && w.transfer().mapOnlyRuns() >= 1; }, 60000));
  ASSERT_TRUE(wait_for([&] { return !w.transfer().computing(); }, 60000));
  EXPECT_LE(w.transfer().mapOnlyRuns(), 3);
  ASSERT_NE(w.session().result, nullptr) << w.status().lastMessage().toStdString();
  // the map shown is the one for the last value
  EXPECT_NE(w.session().result->metrics_json.find("\"coherent_threshold\": 0.3"), std::string::npos);
  cv::Mat diff;
  cv::absdiff(first, w.session().result->map.xy, diff);
  EXPECT_GT(cv::countNonZero(diff.reshape(1) > 0.5), 0) << "a larger threshold makes other chunks";
  EXPECT_TRUE(child<QLabel>(w, "transferStatus")->text().contains("map"));

  // the blend radius and its guide change how the source's photos are
  // pasted (the copy look's: the live view's frames), not the map: repainted
  // from the map shown. Here only that the paste changes and the map stays;
  // what the blended pixels must be is checked against an oracle independent
  // of the plan in Viewer.LookSelectorAndTheBlendAgainstAnIndependentOracle.
  const auto pasted = [](const veneer::pipeline::TransferResult& r) {
    return r.blend ? *veneer::repaint::repaint_planned(*r.blend, r.source_median)
                   : veneer::repaint::repaint(r.map, r.source_median);
  };
  const int map_runs = w.transfer().mapOnlyRuns();
  const auto* guided = w.session().result.get();
  const cv::Mat kept = guided->map.xy.clone(), guided_picture = pasted(*guided);
  EXPECT_EQ(child<QSpinBox>(w, "blend")->value(), veneer::pipeline::TransferOptions{}.blend);
  child<QDoubleSpinBox>(w, "blendGuide")->setValue(0);
  ASSERT_TRUE(wait_for([&] { return !w.transfer().computing() && w.session().result && w.session().result.get() != guided; }, 60000));
  const auto* plain_blend = w.session().result.get();
  const cv::Mat plain_picture = pasted(*plain_blend);
  EXPECT_GT(cv::norm(plain_picture, guided_picture, cv::NORM_INF), 0.0);
  child<QSpinBox>(w, "blend")->setValue(0);
  ASSERT_TRUE(wait_for([&] { return !w.transfer().computing() && w.session().result && w.session().result.get() != plain_blend; }, 60000));
  EXPECT_EQ(w.transfer().repaintOnlyRuns(), 2);
  EXPECT_EQ(w.transfer().mapOnlyRuns(), map_runs);
  EXPECT_TRUE(w.session().result.get()->map_given);
  EXPECT_EQ(cv::norm(w.session().result.get()->map.xy, kept, cv::NORM_INF), 0.0);
  EXPECT_GT(cv::norm(pasted(*w.session().result.get()), plain_picture, cv::NORM_INF), 0.0);
  EXPECT_TRUE(child<QLabel>(w, "transferStatus")->text().contains("map kept"));

  // a segmentation change prepares the objects again (not a map-only run) and matches
  const int before = w.transfer().mapOnlyRuns();
  const auto* shown = w.session().result.get();
  child<QComboBox>(w, "segMethod")->setCurrentText("otsu");
  ASSERT_TRUE(wait_for(
      [&] { return !w.transfer().computing() && w.session().result && w.session().result.get() != shown; }, 60000));
  ASSERT_TRUE(wait_for([&] { return !w.transfer().computing(); }, 60000));
  EXPECT_EQ(w.transfer().mapOnlyRuns(), before);

  // switched off: a change does nothing until Compute
  const int runs = w.transfer().mapOnlyRuns();
  child<QCheckBox>(w, "liveUpdate")->setChecked(false);
  thr->setValue(0.05);
  EXPECT_FALSE(w.transfer().computing());
  EXPECT_EQ(w.transfer().mapOnlyRuns(), runs);
}

namespace {

// The oracle of the copy look's blend, worked out here pixel by pixel from
// what fast::blend_plan's header promises (no plan, no engine call): each
// mapped pixel p averages, with Gaussian weights exp(-|d|^2 / (2 s^2)),
// s = max(1, radius / 2), the source pixels its mapped neighbours p + d
// within the radius propose for it -- their match moved back by d (the
// match's integer part) -- leaving out proposals off the source's object;
// with none left, its own match. Unmapped pixels keep `backdrop`. Plain
// blend only (no normal guide): the caller sets blend_guide to 0.
cv::Mat blended_by_hand(const veneer::match::Map& map, const cv::Mat& photo, const cv::Mat& source_mask, int radius,
                        const cv::Mat& backdrop) {
  cv::Mat out = backdrop.clone();
  const int w = map.xy.cols, h = map.xy.rows;
  const double s = std::max(1.0, radius / 2.0);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const cv::Vec2f own = map.xy.at<cv::Vec2f>(y, x);
      if (own[0] < 0) continue;
      cv::Vec3d sum(0, 0, 0);
      double total = 0;
      for (int dy = -radius; dy <= radius; ++dy)
        for (int dx = -radius; dx <= radius; ++dx) {
          const int nx = x + dx, ny = y + dy;
          if (nx < 0 || ny < 0 || nx >= w || ny >= h) continue;
          const cv::Vec2f m = map.xy.at<cv::Vec2f>(ny, nx);
          if (m[0] < 0) continue;
          const int qx = static_cast<int>(m[0]) - dx, qy = static_cast<int>(m[1]) - dy;
          if (qx < 0 || qy < 0 || qx >= photo.cols || qy >= photo.rows || !source_mask.at<uchar>(qy, qx)) continue;
          const double weight = std::exp(-(dx * dx + dy * dy) / (2 * s * s));
          sum += weight * cv::Vec3d(photo.at<cv::Vec3f>(qy, qx));
          total += weight;
        }
      if (total > 0) {
        out.at<cv::Vec3f>(y, x) = cv::Vec3f(sum / total);
      } else {
        const int qx = static_cast<int>(std::lround(own[0])), qy = static_cast<int>(std::lround(own[1]));
        out.at<cv::Vec3f>(y, x) = photo.at<cv::Vec3f>(qy, qx);
      }
    }
  return out;
}

// The largest difference of the still shown (the median repainted) from the
// oracle's, over the whole picture, and how many mapped pixels the blend
// changed from the plain lookup (so the oracle is not checked on a map without seams).
struct BlendCheck {
  double worst = 1e9;
  int blended = 0;
};
BlendCheck check_blend(MainWindow& w, int radius) {
  const auto& r = *w.session().result;
  const auto pair = w.transfer().prepared();
  EXPECT_NE(pair, nullptr);
  if (!pair) return {};
  EXPECT_EQ(r.look, nullptr) << "the copy look";
  const cv::Mat want = blended_by_hand(r.map, pair->source_median, pair->src.view.mask, radius,
                                       pair->destination_median);
  const cv::Mat plain = blended_by_hand(r.map, pair->source_median, pair->src.view.mask, 0, pair->destination_median);
  BlendCheck c;
  c.worst = cv::norm(r.repainted_median, want, cv::NORM_INF);
  cv::Mat changed;
  cv::absdiff(want, plain, changed);
  c.blended = cv::countNonZero(changed.reshape(1) > 1e-4);
  return c;
}

// A simulated rig's destination (bull) and source (orange) captured and
// computed by the one flow, as in workflow.*; false (with a failure) when not.
::testing::AssertionResult capture_pair_by_flow(MainWindow& w, SimulatedRig& rig) {
  w.rig().setPullTruth(true);  // expect_one_answer reads the sets' truth
  w.rigPanel().connectToRig(rig.endpoint(), rig.token_file());
  if (!wait_for([&] { return w.rig().isConnected(); }, 10000))
    return ::testing::AssertionFailure() << "not connected: " << w.status().lastMessage().toStdString();
  QTest::mouseClick(child<QPushButton>(w, "captureSource"), Qt::LeftButton);
  if (!wait_for([&] { return w.session().src != nullptr; }, 60000))
    return ::testing::AssertionFailure() << "no source: " << w.status().lastMessage().toStdString();
  QTest::mouseClick(child<QPushButton>(w, "liveCaptureDestination"), Qt::LeftButton);
  if (!wait_for([&] { return w.session().dst != nullptr && w.session().result != nullptr && !w.transfer().computing(); },
                120000))
    return ::testing::AssertionFailure() << "no map: " << w.status().lastMessage().toStdString();
  return ::testing::AssertionSuccess();
}

// `veneer transfer` run on the viewer's sets into `out` (extra flags after);
// its exit code. With the result cache, as the viewer prepares: a set
// prepared from the cache's files differs from one decoded afresh by up to
// ~25 16-bit steps in the still (measured 3.9e-4), which is the cache's, not
// a difference between the programs.
int run_cli_transfer(MainWindow& w, const QString& out, const QStringList& extra, QString* log) {
  QProcess p;
  p.setProcessChannelMode(QProcess::MergedChannels);
  p.start(VENEER_BIN_DIR "/veneer", QStringList{"transfer", "--dst", w.session().dst->folder, "--src",
                                                w.session().src->folder, "--out", out} + extra);
  p.waitForFinished(180000);
  *log = QString::fromUtf8(p.readAll());
  return p.exitStatus() == QProcess::NormalExit ? p.exitCode() : -1;
}

// The viewer's map and still against the folder `veneer transfer` wrote:
// the same pixels mapped to the same source pixels, the same median picture
// (to a quarter of an 8-bit step, see below).
void expect_same_as_cli(MainWindow& w, const QString& folder) {
  const auto& r = *w.session().result;
  auto map = veneer::match::read_map((folder + "/map.pfm").toStdString());
  ASSERT_TRUE(map) << map.message();
  ASSERT_EQ(map->xy.size(), r.map.xy.size());
  cv::Mat viewer_xy[2], cli_xy[2];
  cv::split(r.map.xy, viewer_xy);
  cv::split(map->xy, cli_xy);
  const cv::Mat viewer_mapped = viewer_xy[0] >= 0, cli_mapped = cli_xy[0] >= 0;
  EXPECT_EQ(cv::countNonZero(viewer_mapped != cli_mapped), 0) << "the same pixels mapped";
  EXPECT_LE(cv::norm(r.map.xy, map->xy, cv::NORM_INF, viewer_mapped), 1e-3) << "to the same source pixels";
  auto median = veneer::io::read_linear_image((folder + "/result_median.png").toStdString());
  ASSERT_TRUE(median) << median.message();
  cv::Mat shown = cv::min(cv::max(r.repainted_median, 0.0), 1.0);
  // measured up to 5.2e-4 (0.13 of an 8-bit step) in the shaded look, 2.8e-5
  // to 2.4e-4 in the copy look, with the same map: not yet explained (threads'
  // summing order? the CLI paints with keep_pictures off), left open
  EXPECT_LE(cv::norm(shown, *median, cv::NORM_INF), 1e-3) << "the same still";
  EXPECT_LE(cv::norm(shown, *median, cv::NORM_L1) / shown.total() / 3, 2e-5) << "the same still, on average";
}

}  // namespace

namespace {
// The viewer's transfer shown in `w` against `veneer transfer` on the same
// sets, in the shaded look (the default) and then the copy look (the Look
// tab's selector against --look copy): the same mask (the Look tab's too),
// map and still. With `plinth_grey`, the plinth -- what the segmentation sees
// lit that the set's truth (the bull alone) leaves out -- is mapped by
// neither and the still leaves it as the destination's own photo.
void expect_one_answer(MainWindow& w, const QString& work, bool plinth_grey) {
  const auto pair = w.transfer().prepared();
  ASSERT_NE(pair, nullptr);
  const veneer::io::ImageSet& dst = pair->destination;
  ASSERT_TRUE(dst.truth.present() && !dst.truth.mask.empty()) << "simulated sets carry their truth";
  EXPECT_EQ(w.session().result->match_options, veneer::pipeline::default_match_options());
  auto lit = veneer::ps::segment(dst);
  ASSERT_TRUE(lit) << lit.message();
  cv::Mat bull;
  cv::dilate(dst.truth.mask > 127, bull, cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(7, 7)));
  const cv::Mat plinth = lit->mask & ~bull;
  ASSERT_GT(cv::countNonZero(plinth), 300) << "the bull stands on a plinth the segmentation sees";
  auto mapped_on_plinth = [&](const veneer::match::Map& map) {
    cv::Mat xy[2];
    cv::split(map.xy, xy);
    return cv::countNonZero((xy[0] >= 0) & plinth);
  };
  for (const char* look : {"shaded", "copy"}) {
    SCOPED_TRACE(look);
    if (std::string(look) == "copy") {
      const auto* before = w.session().result.get();
      child<QComboBox>(w, "look")->setCurrentText("copy");
      ASSERT_TRUE(wait_for(
          [&] { return !w.transfer().computing() && w.session().result && w.session().result.get() != before; }, 60000))
          << w.status().lastMessage().toStdString();
      ASSERT_TRUE(wait_for([&] { return !w.transfer().computing(); }, 60000));
      EXPECT_EQ(w.session().result->look, nullptr) << "the pixel copy";
      EXPECT_EQ(w.session().result->match_options, veneer::pipeline::default_match_options(veneer::repaint::Look::copy));
    } else {
      EXPECT_NE(w.session().result->look, nullptr) << "the shaded look by default";
    }
    const QString out = work + "/cli-" + look;
    QString log;
    ASSERT_EQ(run_cli_transfer(w, out, {"--look", look}, &log), 0) << log.toStdString();
    expect_same_as_cli(w, out);
    const auto shown_pair = w.transfer().prepared();
    ASSERT_NE(shown_pair, nullptr);
    ASSERT_TRUE(wait_for([&] { return w.session().dst->normals.has_value(); }, 30000));
    EXPECT_EQ(cv::countNonZero(w.session().dst->normals->mask != shown_pair->dst.view.mask), 0)
        << "the Look tab's mask is the one the map was made on";
    auto cli_map = veneer::match::read_map((out + "/map.pfm").toStdString());
    ASSERT_TRUE(cli_map);
    const int viewer_on_plinth = mapped_on_plinth(w.session().result->map), cli_on_plinth = mapped_on_plinth(*cli_map);
    EXPECT_EQ(viewer_on_plinth, cli_on_plinth) << "the plinth alike in both";
    if (plinth_grey) {
      EXPECT_EQ(cv::countNonZero(shown_pair->dst.view.mask & plinth), 0) << "the base left out of the object";
      EXPECT_EQ(cli_on_plinth, 0) << "veneer transfer leaves the plinth out";
      EXPECT_EQ(viewer_on_plinth, 0) << "the viewer leaves the plinth out";
      EXPECT_LE(cv::norm(w.session().result->repainted_median, shown_pair->destination_median, cv::NORM_INF, plinth),
                1e-6)
          << "grey: the destination's own photo";
    } else {
      std::printf("plinth pixels mapped (%s): viewer %d, veneer transfer %d of %d\n", look, viewer_on_plinth,
                  cli_on_plinth, cv::countNonZero(plinth));
    }
  }
}
}  // namespace

// Issue 40: the viewer and `veneer transfer` give one answer on the
// simulated rig's 256x170 bull (destination) and orange (source), captured
// and computed by the viewer's one flow: the viewer prepares its pairs as the
// CLI does (pipeline::default_prepare_options, prepare_pair from the sets'
// folders; it used to read them with LibRaw's DCB and prepare them from
// memory). On these camera-like sets (DNG + JPEG) the base removal keeps the
// plinth in both (their photometric stereo is 8.3 deg off the truth, 45 deg
// at the 95th percentile, against 3.6 / 6.1 on `veneer simulate`'s sets, and
// the plinth's top is not flat within ps::SupportOptions' 3 deg): that is
// the engine's, issue 40 keeps it open; here both must agree on it.
TEST(Viewer, TheViewerAndVeneerTransferGiveOneAnswer) {
  SimulatedRig rig;
  ASSERT_TRUE(rig.started()) << rig.log().toStdString();
  QTemporaryDir work;
  MainWindow w({QString(), QString(), QString(), QString(), work.path()});
  w.resize(1280, 720);
  w.show();
  ASSERT_TRUE(capture_pair_by_flow(w, rig));
  child<QPushButton>(w, "liveToggle")->setChecked(false);
  expect_one_answer(w, work.path(), false);
}

// The same on simulated sets written as files (linear PNG, as `veneer
// simulate` writes them): there the base removal takes the plinth out, and
// both leave it grey.
TEST(Viewer, ThePlinthIsGreyInTheViewerAsInVeneerTransfer) {
  QTemporaryDir dir;
  auto window = open_pair(dir);
  ASSERT_TRUE(window);
  MainWindow& w = *window;
  w.resize(1280, 720);
  w.show();
  ASSERT_TRUE(compute_and_wait(w));
  expect_one_answer(w, dir.path(), true);
  w.showTab("Look");
  save_stage(w, "look-plinth-grey");
}

// The Look tab's selector paints the stills in the shaded look or the pixel
// copy; the blend radius is the copy look's: under the shaded look it leaves
// the stills as they are (to the bit), under the copy look each still pixel is
// the blend worked out by hand from the source's photos and the map
// (blended_by_hand: an oracle independent of the engine's plan).
TEST(Viewer, LookSelectorAndTheBlendAgainstAnIndependentOracle) {
  QTemporaryDir dir;
  auto window = open_pair(dir);
  ASSERT_TRUE(window);
  MainWindow& w = *window;
  w.resize(1280, 720);
  w.show();
  child<QComboBox>(w, "method")->setCurrentText("coherent");  // chunks, so seams to blend
  child<QDoubleSpinBox>(w, "blendGuide")->setValue(0);       // the plain blend the oracle works out
  EXPECT_EQ(child<QComboBox>(w, "look")->currentText(), "shaded") << "the default look";
  ASSERT_TRUE(compute_and_wait(w));
  ASSERT_NE(w.session().result->look, nullptr);
  const cv::Mat shaded = w.session().result->repainted_median.clone();
  std::vector<cv::Mat> shaded_lamps;
  for (const cv::Mat& m : w.session().result->repainted) shaded_lamps.push_back(m.clone());
  const cv::Mat map_shown = w.session().result->map.xy.clone();

  // shaded: the blend radius changes nothing in the stills
  auto recomputed = [&](const veneer::pipeline::TransferResult* before) {
    return wait_for([&] { return !w.transfer().computing() && w.session().result && w.session().result.get() != before; },
                    60000) &&
           wait_for([&] { return !w.transfer().computing(); }, 60000);
  };
  const int repaints = w.transfer().repaintOnlyRuns();
  const auto* before = w.session().result.get();
  child<QSpinBox>(w, "blend")->setValue(5);
  ASSERT_TRUE(recomputed(before));
  EXPECT_EQ(w.transfer().repaintOnlyRuns(), repaints + 1) << "the map kept";
  EXPECT_EQ(cv::norm(w.session().result->map.xy, map_shown, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(w.session().result->repainted_median, shaded, cv::NORM_INF), 0.0)
      << "the shaded look does not blend";
  ASSERT_EQ(w.session().result->repainted.size(), shaded_lamps.size());
  for (size_t i = 0; i < shaded_lamps.size(); ++i)
    EXPECT_EQ(cv::norm(w.session().result->repainted[i], shaded_lamps[i], cv::NORM_INF), 0.0) << "lamp " << i;

  // copy: the same map (custom matching is kept), the stills blended as the oracle says
  before = w.session().result.get();
  child<QComboBox>(w, "look")->setCurrentText("copy");
  ASSERT_TRUE(recomputed(before));
  EXPECT_EQ(cv::norm(w.session().result->map.xy, map_shown, cv::NORM_INF), 0.0) << "a custom matching is kept";
  EXPECT_GT(cv::norm(w.session().result->repainted_median, shaded, cv::NORM_INF), 0.01) << "another look";
  BlendCheck c = check_blend(w, 5);
  EXPECT_LE(c.worst, 1e-5);
  EXPECT_GT(c.blended, 100) << "seams blended";
  for (int radius : {2, 0}) {
    SCOPED_TRACE(radius);
    before = w.session().result.get();
    child<QSpinBox>(w, "blend")->setValue(radius);
    ASSERT_TRUE(recomputed(before));
    c = check_blend(w, radius);
    EXPECT_LE(c.worst, 1e-5);
  }
  save_stage(w, "look-copy");
  // back to shaded: the stills are the shaded ones again
  before = w.session().result.get();
  child<QComboBox>(w, "look")->setCurrentText("shaded");
  ASSERT_TRUE(recomputed(before));
  EXPECT_EQ(cv::norm(w.session().result->repainted_median, shaded, cv::NORM_INF), 0.0);
  save_stage(w, "look-shaded");
}

// The Live tab has its own look selector (shaded by default) and a light
// overlay: the light a frame's estimate gives (a stand-in LiveLight here,
// until repaint::LiveSession estimates one), its intensity and residual, and
// what the view did when one lamp did not explain the frame.
TEST(Viewer, LiveLookSelectorAndLightOverlay) {
  QTemporaryDir dir;
  auto window = open_pair(dir);
  ASSERT_TRUE(window);
  MainWindow& w = *window;
  w.resize(1280, 720);
  w.show();
  w.showTab("Live");
  auto* look = child<QComboBox>(w, "liveLook");
  EXPECT_EQ(look->currentText(), "shaded") << "the live view paints the look by default";
  EXPECT_EQ(w.live().look(), veneer::repaint::Look::shaded);
  look->setCurrentText("copy");
  EXPECT_EQ(w.live().look(), veneer::repaint::Look::copy);
  w.live().setLook(veneer::repaint::Look::shaded);
  EXPECT_EQ(look->currentText(), "shaded");

  EXPECT_TRUE(w.live().lightDial().text().contains("no light estimate")) << w.live().lightDial().text().toStdString();
  veneer::repaint::LiveLight light;  // the stand-in: a lamp up and to the left, explained
  light.direction = cv::normalize(cv::Vec3d(-0.5, 0.5, 0.7));
  light.intensity = 0.82;
  light.residual = 0.07;
  w.live().showLight(light, veneer::repaint::Look::shaded);
  const QString said = w.live().lightDial().text();
  EXPECT_TRUE(said.contains("0.82") && said.contains("0.07")) << said.toStdString();
  EXPECT_FALSE(said.contains("not one lamp"));
  save_stage(w, "live-light-explained");
  light.explained = false;
  light.residual = 0.61;
  light.fallback = "held the last good light";
  w.live().showLight(light, veneer::repaint::Look::shaded);
  EXPECT_TRUE(w.live().lightDial().text().contains("held the last good light"))
      << w.live().lightDial().text().toStdString();
  save_stage(w, "live-light-not-explained");
}

int main(int argc, char** argv) {
  if (qEnvironmentVariableIsEmpty("QT_QPA_PLATFORM")) qputenv("QT_QPA_PLATFORM", "offscreen");
  QTemporaryDir xdg;
  veneer::test::use_scratch_xdg_folders(xdg);
  QApplication app(argc, argv);
  QApplication::setOrganizationName("veneer-tests");
  QApplication::setApplicationName("veneer-viewer");
  // The rigs these tests start are pinned in a file of their own (never the
  // user's), their first use answered yes (the pin test installs its own asker).
  QTemporaryDir known;
  qputenv("VENEER_KNOWN_RIGS", (known.path() + "/known_rigs").toUtf8());
  veneer::app::RigLink::setDefaultPinAsker([](const QString&, const QString&) { return true; });
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
