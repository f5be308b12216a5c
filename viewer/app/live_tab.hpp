#pragma once
// The Live tab: the rig's live view beside the destination repainted live
// (each frame decoded, registered and repainted on the tab's own thread), the
// lamps of the rig as check boxes, and the simulated rig's hand-held lamp.
#include <atomic>
#include <functional>
#include <optional>
#include <semaphore>
#include <thread>
#include <vector>

#include <QElapsedTimer>
#include <QWidget>

#include "image_view.hpp"
#include "light_dial.hpp"
#include "session.hpp"
#include "sphere_pad.hpp"

class QCheckBox;
class QComboBox;
class QDoubleSpinBox;
class QHBoxLayout;
class QLabel;
class QPushButton;

namespace veneer::app {

// The live session for a transfer's result, as `veneer repaint --video` makes
// it: the source's stills `source_photos` (the set loaded; `still_mask` the
// object there, resized to them when needed), the result's map, blend and
// source size, `backdrop` where nothing is mapped, and the live look of the
// map (pipeline::live_look, from the result's still look when it has one), so
// frames are painted shaded unless the Live tab's selector says copy. When the
// live look cannot be made the session paints the copy only and `*note` (when
// given) says why. Heavy (the live look): run off the GUI thread.
std::shared_ptr<veneer::repaint::LiveSession> make_live_session(
    const veneer::pipeline::PreparedPair& pair, const veneer::pipeline::TransferOptions& options,
    const veneer::pipeline::TransferResult& result, const std::vector<cv::Mat>& source_photos,
    const cv::Mat& still_mask, const cv::Mat& backdrop, QString* note = nullptr, const veneer::Progress& progress = {});

class LiveTab : public QWidget {
  Q_OBJECT
 public:
  explicit LiveTab(Session& session, QWidget* parent = nullptr);
  ~LiveTab() override;
  bool isLive() const;
  void startLive();  // as the Start button does
  // One box per lamp: the lamps of the set loaded (its manifest's light
  // list), else the rig's lamp count; none before either is known.
  void updateLampBoxes();
  cv::Mat lastFrame() const { return live_frame_; }
  cv::Mat lastRepaintedFrame() const { return live_repainted_; }
  int framesShown() const { return live_frames_; }
  double fps() const { return live_fps_; }
  // Paints of the live views that scaled nothing on the GUI thread (the
  // frames came already at the views' sizes): ImageView::fittedPaints.
  int fittedPaints() const;
  // How the live frames are painted (the tab's selector; shaded by default):
  // each frame's session is told (repaint::LiveSession::set_look) before it
  // paints the frame.
  veneer::repaint::Look look() const { return look_; }
  void setLook(veneer::repaint::Look look);
  // The light overlay shows `light` (the frame's estimate; none = no
  // estimate) for a frame painted `painted`.
  void showLight(const std::optional<veneer::repaint::LiveLight>& light, veneer::repaint::Look painted);
  const LightDial& lightDial() const { return *light_dial_; }
  veneer::repaint::Look lastPaintedLook() const { return last_painted_; }  // what the last frame shown shows

 signals:
  void captureRequested(veneer::io::Role role);

 private:
  // What the live view's thread makes of one frame, for the GUI to show.
  struct LiveOut {
    uint64_t seq = 0;
    cv::Mat frame, repainted;  // empty frame: not a JPEG
    QImage shown_image, repainted_image;
    QImage shown_fitted, repainted_fitted;  // the same at the views' painted sizes (ImageView::fitSize)
    QString state, refusal;
    veneer::repaint::Look painted = veneer::repaint::Look::copy;  // what `repainted` shows
    std::optional<veneer::repaint::LiveLight> light;              // the frame's light (shaded look)
  };
  void onLiveFrame(const veneer::rig::LiveFrame& frame);
  void showLiveFrame(const LiveOut& out, const veneer::repaint::LiveSession* session);

  Session& session_;
  // The live frames' own thread (not a pool: the GUI thread hands it a frame
  // by a semaphore's release, which never waits on a lock the thread holds).
  // `live_task_` is written by the GUI thread only while no frame is out
  // (!live_busy_), and taken by the thread before it runs it.
  std::thread live_thread_;
  std::binary_semaphore live_go_{0};
  std::function<void()> live_task_;
  std::atomic<bool> live_quit_{false};
  bool live_busy_ = false;  // a frame is being processed there
  std::optional<veneer::rig::LiveFrame> live_next_;  // the newest frame that came meanwhile
  int live_frames_ = 0;
  double live_fps_ = 0;
  QElapsedTimer live_clock_;
  cv::Mat live_frame_, live_repainted_;
  veneer::repaint::Look look_ = veneer::repaint::Look::shaded;  // the live look by default
  veneer::repaint::Look last_painted_ = veneer::repaint::Look::copy;
  QComboBox* look_box_ = nullptr;
  LightDial* light_dial_ = nullptr;
  QPushButton* live_btn_ = nullptr;
  QDoubleSpinBox* fps_ = nullptr;
  QHBoxLayout* lamp_row_ = nullptr;
  std::vector<QCheckBox*> lamp_boxes_;
  QLabel* live_label_ = nullptr;
  ImageView *live_src_view_ = nullptr, *live_dst_view_ = nullptr;
  SpherePad* hand_pad_ = nullptr;
};

}  // namespace veneer::app
